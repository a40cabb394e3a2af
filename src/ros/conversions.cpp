// Message <-> core conversions (see include/fisheye_mapping/ros/conversions.h).
#include "fisheye_mapping/ros/conversions.h"

#include <algorithm>

#include <cv_bridge/cv_bridge.h>
#include <pcl_conversions/pcl_conversions.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2_eigen/tf2_eigen.h>

#include "fisheye_mapping/core/common/safe_open.h"

namespace fisheye_mapping {

namespace enc = sensor_msgs::image_encodings;

const std::vector<std::string> kCameraImageEncodings = {
    enc::MONO8,       enc::MONO16,      enc::BGR8,        enc::RGB8,        enc::BGRA8,  enc::RGBA8,
    enc::BGR16,       enc::RGB16,       enc::BGRA16,      enc::RGBA16,      enc::BAYER_RGGB8,
    enc::BAYER_BGGR8, enc::BAYER_GBRG8, enc::BAYER_GRBG8, enc::YUV422};

const char* const kMeshMarkerNamespace = "tsdf_mesh";

namespace {

bool isCameraEncoding(const std::string& e) {
  return std::find(kCameraImageEncodings.begin(), kCameraImageEncodings.end(), e) != kCameraImageEncodings.end();
}

std::string acceptedList(ImageTarget target) {
  std::string s;
  for (const auto& e : kCameraImageEncodings) s += (s.empty() ? "" : ", ") + e;
  if (target == ImageTarget::kSweep) s += ", 32FC1 (intensity in [0, 1])";
  return s;
}

std::string describe(const sensor_msgs::Image& msg, const std::string& source) {
  return (source.empty() ? std::string() : source + ": ") + "image " + std::to_string(msg.width) + "x" +
         std::to_string(msg.height) + " '" + msg.encoding + "'";
}

[[noreturn]] void reject(const sensor_msgs::Image& msg, const std::string& source, const std::string& why) {
  throw ImageConversionError(describe(msg, source) + " rejected: " + why);
}

// Pixels present, step and data size consistent with the (known) encoding.
void checkLayout(const sensor_msgs::Image& msg, const std::string& source) {
  if (msg.width == 0 || msg.height == 0 || msg.data.empty()) reject(msg, source, "no pixels");
  const std::size_t bpp = std::size_t(enc::numChannels(msg.encoding)) * std::size_t(enc::bitDepth(msg.encoding)) / 8;
  if (std::size_t(msg.step) < std::size_t(msg.width) * bpp) {
    reject(msg, source, "step " + std::to_string(msg.step) + " < width x " + std::to_string(bpp) +
                            " bytes per pixel = " + std::to_string(std::size_t(msg.width) * bpp));
  }
  const std::size_t want = std::size_t(msg.step) * msg.height;
  if (msg.data.size() != want) {
    reject(msg, source, "data holds " + std::to_string(msg.data.size()) + " bytes, step x height = " +
                            std::to_string(want));
  }
}

// The cv_bridge encoding `msg` becomes for `target` ("" = as it is).
std::string targetEncoding(const std::string& e, ImageTarget target) {
  switch (target) {
    case ImageTarget::kGrey8:
      return e == enc::MONO8 ? "" : enc::MONO8;
    case ImageTarget::kBgr8:
      return e == enc::BGR8 ? "" : enc::BGR8;
    case ImageTarget::kDetector:
      if (e == enc::MONO8 || e == enc::BGR8) return "";
      return e == enc::MONO16 ? enc::MONO8 : enc::BGR8;
    case ImageTarget::kSweep:
      if (e == enc::MONO8 || e == enc::MONO16 || e == enc::TYPE_32FC1 || e == enc::BGR8) return "";
      return enc::BGR8;
  }
  return "";
}

cv::Mat convert(const sensor_msgs::Image& msg, const boost::shared_ptr<void const>& tracked, ImageTarget target,
                const std::string& source, bool share) {
  checkImage(msg, target, source);
  const std::string want = targetEncoding(msg.encoding, target);
  try {
    if (share) return cv_bridge::toCvShare(msg, tracked, want)->image;
    return cv_bridge::toCvCopy(msg, want)->image;
  } catch (const cv_bridge::Exception& e) {
    reject(msg, source, std::string("cannot convert to ") + (want.empty() ? msg.encoding : want) + ": " + e.what());
  } catch (const cv::Exception& e) {
    reject(msg, source, std::string("cannot convert to ") + (want.empty() ? msg.encoding : want) + ": " + e.what());
  }
}

}  // namespace

bool acceptsImageEncoding(const std::string& encoding, ImageTarget target) {
  return isCameraEncoding(encoding) || (target == ImageTarget::kSweep && encoding == enc::TYPE_32FC1);
}

void checkImage(const sensor_msgs::Image& msg, ImageTarget target, const std::string& source) {
  if (!acceptsImageEncoding(msg.encoding, target)) {
    reject(msg, source, "unsupported encoding (accepted: " + acceptedList(target) + ")");
  }
  checkLayout(msg, source);
}

cv::Mat toCvImage(const sensor_msgs::Image& msg, ImageTarget target, const std::string& source) {
  return convert(msg, nullptr, target, source, false);
}

cv::Mat toCvImageShare(const sensor_msgs::ImageConstPtr& msg, ImageTarget target, const std::string& source) {
  if (!msg) throw ImageConversionError((source.empty() ? std::string() : source + ": ") + "no image (null message)");
  return convert(*msg, msg, target, source, true);
}

void checkDepthImage(const sensor_msgs::Image& msg, const std::string& source) {
  if (msg.encoding != enc::TYPE_32FC1) {
    reject(msg, source, "depth must be 32FC1 (metres of range along the ray, NaN invalid)");
  }
  checkLayout(msg, source);
}

cv::Mat toDepth(const sensor_msgs::Image& msg, const std::string& source) {
  checkDepthImage(msg, source);
  return cv_bridge::toCvCopy(msg)->image;
}

cv::Mat toDepthShare(const sensor_msgs::ImageConstPtr& msg, const std::string& source) {
  if (!msg) throw ImageConversionError((source.empty() ? std::string() : source + ": ") + "no depth (null message)");
  checkDepthImage(*msg, source);
  return cv_bridge::toCvShare(msg)->image;
}

sensor_msgs::ImagePtr toImageMsg(const std_msgs::Header& header, const cv::Mat& image) {
  std::string e;
  switch (image.type()) {
    case CV_8UC1: e = enc::MONO8; break;
    case CV_8UC3: e = enc::BGR8; break;
    case CV_8UC4: e = enc::BGRA8; break;
    case CV_16UC1: e = enc::MONO16; break;
    case CV_32FC1: e = enc::TYPE_32FC1; break;
    default:
      throw ImageConversionError("cv::Mat of type " + std::to_string(image.type()) +
                                 " has no image encoding (CV_8UC1, CV_8UC3, CV_8UC4, CV_16UC1 or CV_32FC1)");
  }
  if (image.empty()) throw ImageConversionError("empty cv::Mat (" + e + ") cannot be published");
  return cv_bridge::CvImage(header, e, image).toImageMsg();
}

sensor_msgs::ImagePtr toDepthMsg(const std_msgs::Header& header, const cv::Mat& depth) {
  if (depth.type() != CV_32FC1) {
    throw ImageConversionError("depth must be CV_32FC1 (got cv::Mat type " + std::to_string(depth.type()) + ")");
  }
  return toImageMsg(header, depth);
}

// ---------------------------------------------------------------------------

Detection2DArray toDetectionArrayMsg(const std_msgs::Header& header, int image_width, int image_height,
                                     const std::vector<Detection>& detections) {
  Detection2DArray out;
  out.header = header;
  out.image_width = std::uint32_t(std::max(0, image_width));
  out.image_height = std::uint32_t(std::max(0, image_height));
  out.detections.reserve(detections.size());
  for (const auto& d : detections) {
    Detection2D m;
    m.x_min = d.x_min;
    m.y_min = d.y_min;
    m.x_max = d.x_max;
    m.y_max = d.y_max;
    m.class_id = d.class_id;
    m.class_name = d.class_name;
    m.score = d.score;
    out.detections.push_back(std::move(m));
  }
  return out;
}

Detection2DArray toDetectionArrayMsg(const StampedDetections& d) {
  return toDetectionArrayMsg(d.header, d.image_width, d.image_height, d.detections);
}

Detection toDetection(const Detection2D& m) {
  Detection d;
  d.x_min = m.x_min;
  d.y_min = m.y_min;
  d.x_max = m.x_max;
  d.y_max = m.y_max;
  d.class_id = m.class_id;
  d.class_name = m.class_name;
  d.score = m.score;
  return d;
}

StampedDetections fromDetectionArrayMsg(const Detection2DArray& msg) {
  StampedDetections out;
  out.header = msg.header;
  out.image_width = int(msg.image_width);
  out.image_height = int(msg.image_height);
  out.detections.reserve(msg.detections.size());
  for (const auto& m : msg.detections) out.detections.push_back(toDetection(m));
  return out;
}

// ---------------------------------------------------------------------------

visualization_msgs::Marker meshBlockMarker(const BlockOutput* block, int id, const std::string& frame,
                                           const ros::Time& stamp, MeshColoring coloring) {
  visualization_msgs::Marker m;
  m.header.frame_id = frame;
  m.header.stamp = stamp;
  m.ns = kMeshMarkerNamespace;
  m.id = id;
  m.pose.orientation.w = 1.0;
  m.scale.x = m.scale.y = m.scale.z = 1.0;
  if (!block || block->triangles.empty()) {
    m.action = visualization_msgs::Marker::DELETE;
    return m;
  }
  m.type = visualization_msgs::Marker::TRIANGLE_LIST;
  m.action = visualization_msgs::Marker::ADD;
  m.color.a = 1.0;
  const auto& tri = block->triangles;
  const bool has_grey = block->triangle_grey.size() == tri.size();
  m.points.reserve(tri.size());
  m.colors.reserve(tri.size());
  for (size_t i = 0; i < tri.size(); ++i) {
    const Eigen::Vector3f& v = tri[i];
    geometry_msgs::Point p;
    p.x = v.x(), p.y = v.y(), p.z = v.z();
    m.points.push_back(p);
    Eigen::Vector3f n = Eigen::Vector3f::UnitZ();
    if (coloring == MeshColoring::kNormal) {
      const size_t f = i - i % 3;
      if (f + 2 < tri.size()) n = (tri[f + 1] - tri[f]).cross(tri[f + 2] - tri[f]).normalized();
    }
    const auto rgb = vertexColor(coloring, v, n, has_grey ? block->triangle_grey[i] : 0, kMarkerHeightMin,
                                 kMarkerHeightMax);
    std_msgs::ColorRGBA c;
    c.r = rgb[0] / 255.0f, c.g = rgb[1] / 255.0f, c.b = rgb[2] / 255.0f, c.a = 1.0f;
    m.colors.push_back(c);
  }
  return m;
}

visualization_msgs::Marker deleteAllMarker(const std::string& frame) {
  visualization_msgs::Marker del;
  del.header.frame_id = frame;
  del.action = visualization_msgs::Marker::DELETEALL;
  return del;
}

visualization_msgs::MarkerArray meshToMarkerArray(
    const std::unordered_map<BlockIndex, BlockOutput, BlockIndexHash>& blocks, const std::string& frame,
    const ros::Time& stamp, const std::function<int(const BlockIndex&)>& marker_id) {
  visualization_msgs::MarkerArray markers;
  markers.markers.push_back(deleteAllMarker(frame));
  for (const auto& kv : blocks) {
    if (kv.second.triangles.empty()) continue;
    markers.markers.push_back(meshBlockMarker(&kv.second, marker_id(kv.first), frame, stamp));
  }
  return markers;
}

sensor_msgs::PointCloud2 toCloudMsg(const pcl::PointCloud<pcl::PointXYZI>& cloud, const std::string& frame,
                                    const ros::Time& stamp) {
  sensor_msgs::PointCloud2 msg;
  pcl::toROSMsg(cloud, msg);
  msg.header.frame_id = frame;
  msg.header.stamp = stamp;
  return msg;
}

// ---------------------------------------------------------------------------

geometry_msgs::TransformStamped toTransformMsg(const Eigen::Isometry3d& T, const std::string& parent,
                                               const std::string& child, const ros::Time& stamp) {
  geometry_msgs::TransformStamped t = tf2::eigenToTransform(T);
  t.header.frame_id = parent;
  t.header.stamp = stamp;
  t.child_frame_id = child;
  return t;
}

Eigen::Isometry3d toIsometry(const geometry_msgs::TransformStamped& t) { return tf2::transformToEigen(t); }

}  // namespace fisheye_mapping

// ---------------------------------------------------------------------------
// Compressed images

#include <opencv2/imgcodecs.hpp>

namespace fisheye_mapping {

cv::Mat toGrey(const sensor_msgs::CompressedImage& msg, const std::string& source) {
  const std::string what = (source.empty() ? std::string() : source + ": ") + "compressed image (format '" +
                           msg.format + "')";
  // compressedDepth prefixes the PNG with a header of its own: not an image.
  if (msg.format.find("compressedDepth") != std::string::npos)
    throw ImageConversionError(what + " rejected: compressedDepth is a depth format, not a camera image");
  if (msg.data.empty()) throw ImageConversionError(what + " rejected: no data");
  // Undecodable, or a JPEG cut short (which libjpeg decodes with a warning).
  cv::Mat grey;
  const std::string why = decodeImage(msg.data.data(), msg.data.size(), cv::IMREAD_GRAYSCALE, &grey);
  if (!why.empty()) throw ImageConversionError(what + " rejected: " + why);
  return grey;
}

}  // namespace fisheye_mapping
