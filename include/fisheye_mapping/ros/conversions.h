// Every ROS message <-> core type conversion of the package, in one place
// (library fisheye_mapping_ros; the nodelets and the ROS tools call these and
// keep no private copies).
//
// Camera images: ONE encoding policy (kCameraImageEncodings)
// -----------------------------------------------------------
// Accepted everywhere a camera image is read (frame sync, plane sweep,
// detector, refine_rig, plane_sweep_depth):
//   mono8, mono16                              grey
//   bgr8, rgb8, bgra8, rgba8                   8-bit colour (alpha dropped)
//   bgr16, rgb16, bgra16, rgba16               16-bit colour
//   bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8, yuv422   raw camera formats
// plus, for the plane sweep only (ImageTarget::kSweep), 32FC1 = grey
// intensity in [0, 1] (the core sweep takes floats; a detector has no use for
// them, so kGrey8 / kBgr8 / kDetector reject 32FC1).
// The conversions are cv_bridge's (colour -> grey with OpenCV's weights
// 0.299 R + 0.587 G + 0.114 B in OpenCV's fixed point; 16 -> 8 bits: value x
// 255 / 65535, rounded; bayer demosaiced by OpenCV; yuv422 is UYVY).
// Anything else, and any malformed message (no pixels, data size != step x
// height, step < width x bytes per pixel), throws
// ImageConversionError whose message names the source (topic or camera), the
// encoding and the size, e.g.
//   "/cam1/image_raw: image 640x480 '16SC1' rejected: unsupported encoding (accepted: mono8, ...)".
//
// Depth images: 32FC1 only (metres, NaN invalid), with the same checks.
//
// Everything here throws ImageConversionError (a std::invalid_argument) for
// bad images; the other functions do not throw for valid inputs.
#ifndef FISHEYE_MAPPING_ROS_CONVERSIONS_H_
#define FISHEYE_MAPPING_ROS_CONVERSIONS_H_

#include <functional>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Geometry>
#include <geometry_msgs/TransformStamped.h>
#include <opencv2/core.hpp>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <ros/time.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/Header.h>
#include <visualization_msgs/MarkerArray.h>

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"

namespace fisheye_mapping {

// ---------------------------------------------------------------------------
// Images

/// A sensor_msgs/Image that cannot be converted; what() names the source, the
/// encoding, the size and the reason.
class ImageConversionError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

/// The camera-image encodings of the policy above (without the sweep's 32FC1).
extern const std::vector<std::string> kCameraImageEncodings;

/// What a camera image becomes for the core.
enum class ImageTarget {
  kGrey8,     ///< CV_8UC1 (colour -> grey, 16 bits -> 8 bits)
  kBgr8,      ///< CV_8UC3, BGR order (grey replicated)
  kDetector,  ///< 8 bits, no colour invented: mono8/mono16 -> CV_8UC1, anything with colour -> CV_8UC3 BGR
  kSweep,     ///< the plane sweep's input: mono8 CV_8UC1, mono16 CV_16UC1 and 32FC1 (intensity in
              ///< [0, 1]) CV_32FC1 kept as they are, anything with colour -> CV_8UC3 BGR
};

/// True when `encoding` is accepted for `target`.
bool acceptsImageEncoding(const std::string& encoding, ImageTarget target);

/// Throws ImageConversionError unless `msg` is a well-formed image in an
/// encoding accepted for `target`. `source` (topic or camera) goes into the
/// message.
void checkImage(const sensor_msgs::Image& msg, ImageTarget target, const std::string& source = "");

/// checkImage for a camera image of the rig: kCameraImageEncodings (no 32FC1).
inline void checkCameraImage(const sensor_msgs::Image& msg, const std::string& source = "") {
  checkImage(msg, ImageTarget::kBgr8, source);
}

/// The image as `target` (a deep copy: owns its pixels).
cv::Mat toCvImage(const sensor_msgs::Image& msg, ImageTarget target, const std::string& source = "");
/// The same, but sharing the message's pixels where no conversion is needed
/// (keep `msg` alive while the Mat is used).
cv::Mat toCvImageShare(const sensor_msgs::ImageConstPtr& msg, ImageTarget target, const std::string& source = "");

inline cv::Mat toGrey(const sensor_msgs::Image& msg, const std::string& source = "") {
  return toCvImage(msg, ImageTarget::kGrey8, source);
}
inline cv::Mat toGreyShare(const sensor_msgs::ImageConstPtr& msg, const std::string& source = "") {
  return toCvImageShare(msg, ImageTarget::kGrey8, source);
}
inline cv::Mat toBgr(const sensor_msgs::Image& msg, const std::string& source = "") {
  return toCvImage(msg, ImageTarget::kBgr8, source);
}
inline cv::Mat toBgrShare(const sensor_msgs::ImageConstPtr& msg, const std::string& source = "") {
  return toCvImageShare(msg, ImageTarget::kBgr8, source);
}

/// Throws ImageConversionError unless `msg` is a well-formed 32FC1 depth image.
void checkDepthImage(const sensor_msgs::Image& msg, const std::string& source = "");
/// Depth (32FC1, metres, NaN invalid) as CV_32FC1: a copy / sharing the message's pixels.
cv::Mat toDepth(const sensor_msgs::Image& msg, const std::string& source = "");
cv::Mat toDepthShare(const sensor_msgs::ImageConstPtr& msg, const std::string& source = "");

/// A cv::Mat as an image message with `header`; the encoding follows the
/// type: CV_8UC1 mono8, CV_8UC3 bgr8, CV_8UC4 bgra8, CV_16UC1 mono16,
/// CV_32FC1 32FC1 (depth, cost, ...). Throws ImageConversionError for other
/// types or an empty Mat.
sensor_msgs::ImagePtr toImageMsg(const std_msgs::Header& header, const cv::Mat& image);
/// Depth (CV_32FC1 only, NaN kept) as a 32FC1 message.
sensor_msgs::ImagePtr toDepthMsg(const std_msgs::Header& header, const cv::Mat& depth);

// ---------------------------------------------------------------------------
// Detections

/// The detections of one image with that image's header (stamp and frame)
/// and size: the core side of fisheye_mapping/Detection2DArray.
struct StampedDetections {
  std_msgs::Header header;
  int image_width = 0, image_height = 0;  ///< 0: not given
  std::vector<Detection> detections;
};

Detection2DArray toDetectionArrayMsg(const std_msgs::Header& header, int image_width, int image_height,
                                     const std::vector<Detection>& detections);
Detection2DArray toDetectionArrayMsg(const StampedDetections& d);
Detection toDetection(const Detection2D& msg);
StampedDetections fromDetectionArrayMsg(const Detection2DArray& msg);

// ---------------------------------------------------------------------------
// TSDF mesh and cloud (the TSDF fusion nodelet's outputs)

/// The marker namespace of the mesh.
extern const char* const kMeshMarkerNamespace;  // "tsdf_mesh"

/// One mesh block as a TRIANGLE_LIST marker (namespace tsdf_mesh, `id`,
/// identity pose, scale 1, one colour per vertex: vertexColor() of
/// `coloring`, with the face's normal and the height ramp over 0..6 m); a
/// DELETE marker for `id` when the block is null or has no triangles.
visualization_msgs::Marker meshBlockMarker(const BlockOutput* block, int id, const std::string& frame,
                                           const ros::Time& stamp,
                                           MeshColoring coloring = MeshColoring::kIntensity);
/// The height ramp's range of the markers (metres, world z).
constexpr double kMarkerHeightMin = 0.0, kMarkerHeightMax = 6.0;
/// A DELETEALL marker in `frame`.
visualization_msgs::Marker deleteAllMarker(const std::string& frame);

/// A whole mesh: DELETEALL first, then one ADD marker per block with
/// triangles (empty blocks are left out), ids from `marker_id`.
visualization_msgs::MarkerArray meshToMarkerArray(
    const std::unordered_map<BlockIndex, BlockOutput, BlockIndexHash>& blocks, const std::string& frame,
    const ros::Time& stamp, const std::function<int(const BlockIndex&)>& marker_id);

/// A cloud as a PointCloud2 in `frame` at `stamp` (fields x y z intensity).
sensor_msgs::PointCloud2 toCloudMsg(const pcl::PointCloud<pcl::PointXYZI>& cloud, const std::string& frame,
                                    const ros::Time& stamp);

// ---------------------------------------------------------------------------
// Poses

/// T (pose of `child` in `parent`) as a stamped transform parent -> child.
geometry_msgs::TransformStamped toTransformMsg(const Eigen::Isometry3d& T, const std::string& parent,
                                               const std::string& child, const ros::Time& stamp);
/// A transform message as an Isometry (pose of the child frame in the parent frame).
Eigen::Isometry3d toIsometry(const geometry_msgs::TransformStamped& t);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_CONVERSIONS_H_

// ---------------------------------------------------------------------------
// Compressed images (sensor_msgs/CompressedImage, as image_transport's
// "compressed" plugin and bags recorded from it carry them)
#ifndef FISHEYE_MAPPING_ROS_CONVERSIONS_COMPRESSED_H_
#define FISHEYE_MAPPING_ROS_CONVERSIONS_COMPRESSED_H_

#include <sensor_msgs/CompressedImage.h>

namespace fisheye_mapping {

/// The image of a CompressedImage (PNG, JPEG, ...: whatever cv::imdecode reads)
/// as 8-bit grey (CV_8UC1), colour converted as cv::IMREAD_GRAYSCALE does.
/// Throws ImageConversionError naming `source` and the message's format when
/// the data is empty, is a compressedDepth image, or cannot be decoded.
cv::Mat toGrey(const sensor_msgs::CompressedImage& msg, const std::string& source = "");

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_CONVERSIONS_COMPRESSED_H_
