// Message <-> core conversions (include/fisheye_mapping/ros/conversions.h):
// messages built in memory, no roscore.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

#include <sensor_msgs/image_encodings.h>

#include "fisheye_mapping/ros/conversions.h"

namespace fm = fisheye_mapping;
using fm::ImageTarget;

namespace {

// A w x h image message whose every pixel holds `pixel` (the bytes of one pixel).
sensor_msgs::ImagePtr uniformImage(const std::string& encoding, int w, int h, const std::vector<uint8_t>& pixel) {
  sensor_msgs::ImagePtr m(new sensor_msgs::Image);
  m->header.stamp = ros::Time(1700000000, 5);
  m->header.frame_id = "cam0_optical";
  m->encoding = encoding;
  m->width = w;
  m->height = h;
  m->step = uint32_t(w * pixel.size());
  for (int i = 0; i < w * h; ++i) m->data.insert(m->data.end(), pixel.begin(), pixel.end());
  return m;
}

std::vector<uint8_t> bytesOf(const void* p, size_t n) {
  const auto* b = static_cast<const uint8_t*>(p);
  return std::vector<uint8_t>(b, b + n);
}

std::vector<uint8_t> u16(std::initializer_list<uint16_t> v) {  // little-endian (is_bigendian = 0, x86)
  std::vector<uint8_t> out;
  for (uint16_t x : v) {
    out.push_back(uint8_t(x & 0xff));
    out.push_back(uint8_t(x >> 8));
  }
  return out;
}

// OpenCV's fixed-point RGB -> grey (imgproc color.hpp: R 4899, G 9617, B 1868, 14 bits, rounded).
int cvGrey(int r, int g, int b) { return (r * 4899 + g * 9617 + b * 1868 + (1 << 13)) >> 14; }

template <class F>
std::string thrownMessage(F&& f) {
  try {
    f();
  } catch (const fm::ImageConversionError& e) {
    return e.what();
  }
  return "(nothing thrown)";
}

}  // namespace

// ---------------------------------------------------------------------------
// Camera images: each accepted encoding gives the right pixels.

TEST(ConversionsImage, Mono8GreyIsSharedAndBgrReplicated) {
  const auto m = uniformImage("mono8", 4, 3, {77});
  const cv::Mat g = fm::toGreyShare(m, "/cam0/image_raw");
  ASSERT_EQ(g.type(), CV_8UC1);
  ASSERT_EQ(g.size(), cv::Size(4, 3));
  EXPECT_EQ(g.at<uint8_t>(2, 3), 77);
  EXPECT_EQ(static_cast<const void*>(g.data), static_cast<const void*>(m->data.data())) << "mono8 grey is not shared";
  const cv::Mat copy = fm::toGrey(*m);
  EXPECT_NE(static_cast<const void*>(copy.data), static_cast<const void*>(m->data.data())) << "toGrey must copy";
  EXPECT_EQ(copy.at<uint8_t>(0, 0), 77);
  const cv::Mat bgr = fm::toBgr(*m);
  ASSERT_EQ(bgr.type(), CV_8UC3);
  EXPECT_EQ(bgr.at<cv::Vec3b>(1, 1), cv::Vec3b(77, 77, 77));
}

TEST(ConversionsImage, ColourChannelOrderAndGreyWeights) {
  // One pixel with R = 30, G = 20, B = 10, in every 8-bit colour layout.
  const int r = 30, g = 20, b = 10;
  const int grey = cvGrey(r, g, b);
  EXPECT_EQ(grey, 22);  // 0.299 * 30 + 0.587 * 20 + 0.114 * 10 = 21.85
  struct Case {
    std::string enc;
    std::vector<uint8_t> px;
  };
  for (const Case& c : {Case{"bgr8", {10, 20, 30}}, Case{"rgb8", {30, 20, 10}}, Case{"bgra8", {10, 20, 30, 200}},
                        Case{"rgba8", {30, 20, 10, 200}}}) {
    const auto m = uniformImage(c.enc, 3, 2, c.px);
    const cv::Mat bgr = fm::toBgr(*m);
    ASSERT_EQ(bgr.type(), CV_8UC3) << c.enc;
    EXPECT_EQ(bgr.at<cv::Vec3b>(1, 2), cv::Vec3b(b, g, r)) << c.enc;
    const cv::Mat gr = fm::toGrey(*m);
    ASSERT_EQ(gr.type(), CV_8UC1) << c.enc;
    EXPECT_EQ(int(gr.at<uint8_t>(1, 2)), grey) << c.enc;
    // Shared variants give the same pixels.
    EXPECT_EQ(fm::toBgrShare(m).at<cv::Vec3b>(0, 0), cv::Vec3b(b, g, r)) << c.enc;
    EXPECT_EQ(int(fm::toGreyShare(m).at<uint8_t>(0, 0)), grey) << c.enc;
    // The detector and the sweep get BGR (alpha dropped).
    for (ImageTarget t : {ImageTarget::kDetector, ImageTarget::kSweep}) {
      const cv::Mat x = fm::toCvImageShare(m, t);
      ASSERT_EQ(x.type(), CV_8UC3) << c.enc;
      EXPECT_EQ(x.at<cv::Vec3b>(0, 1), cv::Vec3b(b, g, r)) << c.enc;
    }
  }
  // rgb8 pixel (R, G, B) = (10, 20, 30): 0.299 * 10 + 0.587 * 20 + 0.114 * 30 = 18.15 -> 18; BGR (30, 20, 10).
  const auto rgb = uniformImage("rgb8", 1, 1, {10, 20, 30});
  EXPECT_EQ(int(fm::toGrey(*rgb).at<uint8_t>(0, 0)), 18);
  EXPECT_EQ(cvGrey(10, 20, 30), 18);
  EXPECT_EQ(fm::toBgr(*rgb).at<cv::Vec3b>(0, 0), cv::Vec3b(30, 20, 10));
  // bgr8 is shared as it is.
  const auto m = uniformImage("bgr8", 3, 2, {10, 20, 30});
  EXPECT_EQ(static_cast<const void*>(fm::toBgrShare(m).data), static_cast<const void*>(m->data.data()));
}

TEST(ConversionsImage, Mono16) {
  const auto m = uniformImage("mono16", 2, 2, u16({0x1234}));  // 4660
  // The sweep keeps the 16 bits.
  const cv::Mat s = fm::toCvImageShare(m, ImageTarget::kSweep, "cam1");
  ASSERT_EQ(s.type(), CV_16UC1);
  EXPECT_EQ(s.at<uint16_t>(1, 1), 4660);
  // 8 bits for grey and the detector: cv_bridge's scaling x 255 / 65535, 4660 / 257 = 18.1 -> 18.
  const cv::Mat g = fm::toGrey(*m);
  ASSERT_EQ(g.type(), CV_8UC1);
  EXPECT_EQ(int(g.at<uint8_t>(0, 0)), 18);
  const cv::Mat d = fm::toCvImage(*m, ImageTarget::kDetector);
  ASSERT_EQ(d.type(), CV_8UC1);
  EXPECT_EQ(int(d.at<uint8_t>(0, 1)), 18);
  const cv::Mat bgr = fm::toBgr(*m);
  EXPECT_EQ(bgr.at<cv::Vec3b>(0, 0), cv::Vec3b(18, 18, 18));
  // 51000 * 255 / 65535 = 198.45 -> 198 (a division by 256 would give 199).
  EXPECT_EQ(int(fm::toGrey(*uniformImage("mono16", 1, 1, u16({51000}))).at<uint8_t>(0, 0)), 198);
  EXPECT_EQ(int(fm::toGrey(*uniformImage("mono16", 1, 1, u16({65535}))).at<uint8_t>(0, 0)), 255);
}

TEST(ConversionsImage, Colour16AndRawFormats) {
  // 16-bit colour: R = 30 * 257, G = 20 * 257, B = 10 * 257 -> (30, 20, 10) in 8 bits.
  const auto rgb16 = uniformImage("rgb16", 2, 2, u16({30 * 257, 20 * 257, 10 * 257}));
  EXPECT_EQ(fm::toBgr(*rgb16).at<cv::Vec3b>(1, 0), cv::Vec3b(10, 20, 30));
  EXPECT_EQ(int(fm::toGrey(*rgb16).at<uint8_t>(0, 0)), 22);
  const auto bgra16 = uniformImage("bgra16", 2, 2, u16({10 * 257, 20 * 257, 30 * 257, 65535}));
  EXPECT_EQ(fm::toBgr(*bgra16).at<cv::Vec3b>(1, 0), cv::Vec3b(10, 20, 30));
  // Bayer and yuv422 of a uniform grey 90: grey 90 everywhere.
  for (const std::string enc : {"bayer_rggb8", "bayer_bggr8", "bayer_gbrg8", "bayer_grbg8"}) {
    const auto m = uniformImage(enc, 8, 6, {90});
    const cv::Mat g = fm::toGrey(*m, "raw");
    ASSERT_EQ(g.type(), CV_8UC1) << enc;
    EXPECT_EQ(int(g.at<uint8_t>(3, 4)), 90) << enc;
    EXPECT_EQ(fm::toBgr(*m).at<cv::Vec3b>(3, 4), cv::Vec3b(90, 90, 90)) << enc;
  }
  const auto yuv = uniformImage("yuv422", 4, 2, {128, 90});  // UYVY: U, Y, V, Y; neutral chroma
  EXPECT_EQ(int(fm::toGrey(*yuv).at<uint8_t>(1, 3)), 90);
}

TEST(ConversionsImage, Float32OnlyForTheSweep) {
  const float v = 0.25f;
  const auto m = uniformImage("32FC1", 3, 2, bytesOf(&v, 4));
  const cv::Mat s = fm::toCvImageShare(m, ImageTarget::kSweep);
  ASSERT_EQ(s.type(), CV_32FC1);
  EXPECT_EQ(s.at<float>(1, 2), 0.25f);
  EXPECT_TRUE(fm::acceptsImageEncoding("32FC1", ImageTarget::kSweep));
  for (ImageTarget t : {ImageTarget::kGrey8, ImageTarget::kBgr8, ImageTarget::kDetector}) {
    EXPECT_FALSE(fm::acceptsImageEncoding("32FC1", t));
    const std::string what = thrownMessage([&] { fm::toCvImageShare(m, t, "/cam0/image_raw"); });
    EXPECT_NE(what.find("'32FC1'"), std::string::npos) << what;
    EXPECT_NE(what.find("/cam0/image_raw"), std::string::npos) << what;
    EXPECT_NE(what.find("unsupported encoding"), std::string::npos) << what;
  }
}

// ---------------------------------------------------------------------------
// Rejected images: the message names the source, the encoding and the size.

TEST(ConversionsImage, RejectsUnknownEncodings) {
  for (const std::string enc : {"16SC1", "8UC3", "64FC1", "jpeg", ""}) {
    const auto m = uniformImage(enc, 3, 2, {0, 0});
    for (ImageTarget t : {ImageTarget::kGrey8, ImageTarget::kBgr8, ImageTarget::kDetector, ImageTarget::kSweep}) {
      const std::string what = thrownMessage([&] { fm::toCvImage(*m, t, "/cam1/image_raw"); });
      EXPECT_NE(what.find("'" + enc + "'"), std::string::npos) << what;
      EXPECT_NE(what.find("/cam1/image_raw"), std::string::npos) << what;
      EXPECT_NE(what.find("3x2"), std::string::npos) << what;
      EXPECT_NE(what.find("accepted: mono8"), std::string::npos) << what;
    }
  }
  // An ImageConversionError is a std::invalid_argument.
  EXPECT_THROW(fm::toGrey(*uniformImage("16SC1", 1, 1, {0, 0})), std::invalid_argument);
  EXPECT_THROW(fm::toGreyShare(sensor_msgs::ImageConstPtr()), fm::ImageConversionError);
}

TEST(ConversionsImage, RejectsMalformedMessages) {
  // Data shorter than step x height.
  auto short_data = uniformImage("rgb8", 4, 3, {1, 2, 3});
  short_data->data.resize(short_data->data.size() - 1);
  std::string what = thrownMessage([&] { fm::toBgr(*short_data, "/cam2/image_raw"); });
  EXPECT_NE(what.find("'rgb8'"), std::string::npos) << what;
  EXPECT_NE(what.find("4x3"), std::string::npos) << what;
  EXPECT_NE(what.find("data holds 35 bytes, step x height = 36"), std::string::npos) << what;
  EXPECT_NE(what.find("/cam2/image_raw"), std::string::npos) << what;
  // A step shorter than a row.
  auto bad_step = uniformImage("bgr8", 4, 3, {1, 2, 3});
  bad_step->step = 8;
  bad_step->data.resize(24);
  what = thrownMessage([&] { fm::toGrey(*bad_step); });
  EXPECT_NE(what.find("step 8 < width x 3 bytes per pixel = 12"), std::string::npos) << what;
  EXPECT_NE(what.find("'bgr8'"), std::string::npos) << what;
  // No pixels.
  auto empty = uniformImage("mono8", 4, 3, {1});
  empty->data.clear();
  what = thrownMessage([&] { fm::toGrey(*empty); });
  EXPECT_NE(what.find("no pixels"), std::string::npos) << what;
  auto zero = uniformImage("mono8", 0, 0, {1});
  EXPECT_NE(thrownMessage([&] { fm::checkCameraImage(*zero, "cam0"); }).find("0x0 'mono8'"), std::string::npos);
  // Padded rows are fine.
  auto padded = uniformImage("mono8", 3, 2, {5});
  padded->step = 4;
  padded->data.assign(8, 5);
  EXPECT_EQ(int(fm::toGrey(*padded).at<uint8_t>(1, 2)), 5);
}

// ---------------------------------------------------------------------------
// Depth

TEST(ConversionsDepth, Float32NanPreserved) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  sensor_msgs::ImagePtr m = uniformImage("32FC1", 3, 2, bytesOf(&nan, 4));
  const float d = 7.5f;
  std::memcpy(&m->data[4 * 4], &d, 4);  // pixel (row 1, col 1)
  for (const cv::Mat& depth : {fm::toDepth(*m, "depth"), fm::toDepthShare(m, "depth")}) {
    ASSERT_EQ(depth.type(), CV_32FC1);
    ASSERT_EQ(depth.size(), cv::Size(3, 2));
    EXPECT_TRUE(std::isnan(depth.at<float>(0, 0)));
    EXPECT_TRUE(std::isnan(depth.at<float>(1, 2)));
    EXPECT_EQ(depth.at<float>(1, 1), 7.5f);
  }
  EXPECT_EQ(static_cast<const void*>(fm::toDepthShare(m).data), static_cast<const void*>(m->data.data()));
  EXPECT_NE(static_cast<const void*>(fm::toDepth(*m).data), static_cast<const void*>(m->data.data()));
  // Back to a message: 32FC1, same bytes (NaN kept), header kept.
  const sensor_msgs::ImagePtr back = fm::toDepthMsg(m->header, fm::toDepth(*m));
  EXPECT_EQ(back->encoding, "32FC1");
  EXPECT_EQ(back->header.frame_id, "cam0_optical");
  EXPECT_EQ(back->header.stamp, m->header.stamp);
  EXPECT_EQ(back->width, 3u);
  EXPECT_EQ(back->height, 2u);
  EXPECT_EQ(back->data, m->data);
}

TEST(ConversionsDepth, RejectsOtherEncodingsAndBadSizes) {
  const auto mono = uniformImage("mono8", 3, 2, {5});
  std::string what = thrownMessage([&] { fm::toDepth(*mono, "/cam0/depth"); });
  EXPECT_NE(what.find("'mono8'"), std::string::npos) << what;
  EXPECT_NE(what.find("/cam0/depth"), std::string::npos) << what;
  EXPECT_NE(what.find("32FC1"), std::string::npos) << what;
  const auto mm = uniformImage("16UC1", 3, 2, u16({1000}));
  EXPECT_THROW(fm::toDepthShare(mm), fm::ImageConversionError);
  EXPECT_THROW(fm::checkDepthImage(*mm), fm::ImageConversionError);
  const float one = 1.f;
  auto truncated = uniformImage("32FC1", 3, 2, bytesOf(&one, 4));
  truncated->data.resize(20);
  what = thrownMessage([&] { fm::toDepth(*truncated); });
  EXPECT_NE(what.find("data holds 20 bytes, step x height = 24"), std::string::npos) << what;
  EXPECT_THROW(fm::toDepthMsg(std_msgs::Header(), cv::Mat(2, 2, CV_8UC1)), fm::ImageConversionError);
}

TEST(ConversionsImage, ImageMessagesFromMats) {
  std_msgs::Header h;
  h.frame_id = "cam0_optical";
  h.stamp = ros::Time(12, 34);
  struct Case {
    int type;
    const char* enc;
  };
  for (const Case& c : {Case{CV_8UC1, "mono8"}, Case{CV_8UC3, "bgr8"}, Case{CV_8UC4, "bgra8"},
                        Case{CV_16UC1, "mono16"}, Case{CV_32FC1, "32FC1"}}) {
    const cv::Mat m(2, 5, c.type, cv::Scalar::all(3));
    const sensor_msgs::ImagePtr msg = fm::toImageMsg(h, m);
    EXPECT_EQ(msg->encoding, c.enc);
    EXPECT_EQ(msg->width, 5u);
    EXPECT_EQ(msg->height, 2u);
    EXPECT_EQ(msg->header.frame_id, "cam0_optical");
    EXPECT_EQ(msg->header.stamp, h.stamp);
    EXPECT_EQ(msg->data.size(), size_t(msg->step) * 2);
  }
  // bgr8 round trip keeps the channel order.
  cv::Mat bgr(1, 1, CV_8UC3, cv::Scalar(10, 20, 30));
  EXPECT_EQ(fm::toBgr(*fm::toImageMsg(h, bgr)).at<cv::Vec3b>(0, 0), cv::Vec3b(10, 20, 30));
  EXPECT_THROW(fm::toImageMsg(h, cv::Mat(2, 2, CV_16SC1)), fm::ImageConversionError);
  EXPECT_THROW(fm::toImageMsg(h, cv::Mat()), fm::ImageConversionError);
}

// ---------------------------------------------------------------------------
// Detections

TEST(ConversionsDetections, RoundTripKeepsEveryField) {
  fm::StampedDetections in;
  in.header.seq = 42;
  in.header.stamp = ros::Time(1700000001, 250000000);
  in.header.frame_id = "cam0_optical";
  in.image_width = 1024;
  in.image_height = 544;
  fm::Detection a;
  a.class_id = 2, a.class_name = "car", a.score = 0.875f;
  a.x_min = 10.5f, a.y_min = 20.25f, a.x_max = 110.f, a.y_max = 220.75f;
  fm::Detection b;
  b.class_id = 7, b.class_name = "truck", b.score = 0.5f;
  b.x_min = 0.f, b.y_min = 1.f, b.x_max = 2.f, b.y_max = 3.f;
  in.detections = {a, b};

  const fm::Detection2DArray msg = fm::toDetectionArrayMsg(in);
  EXPECT_EQ(msg.header.seq, 42u);
  EXPECT_EQ(msg.header.stamp, in.header.stamp);
  EXPECT_EQ(msg.header.frame_id, "cam0_optical");
  EXPECT_EQ(msg.image_width, 1024u);
  EXPECT_EQ(msg.image_height, 544u);
  ASSERT_EQ(msg.detections.size(), 2u);
  EXPECT_EQ(msg.detections[0].class_id, 2);
  EXPECT_EQ(msg.detections[0].class_name, "car");
  EXPECT_EQ(msg.detections[0].score, 0.875f);
  EXPECT_EQ(msg.detections[0].x_min, 10.5f);
  EXPECT_EQ(msg.detections[0].y_min, 20.25f);
  EXPECT_EQ(msg.detections[0].x_max, 110.f);
  EXPECT_EQ(msg.detections[0].y_max, 220.75f);
  EXPECT_EQ(msg.detections[1].class_name, "truck");

  const fm::StampedDetections out = fm::fromDetectionArrayMsg(msg);
  EXPECT_EQ(out.header.seq, 42u);
  EXPECT_EQ(out.header.stamp, in.header.stamp);
  EXPECT_EQ(out.header.frame_id, "cam0_optical");
  EXPECT_EQ(out.image_width, 1024);
  EXPECT_EQ(out.image_height, 544);
  ASSERT_EQ(out.detections.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    const fm::Detection& x = in.detections[i];
    const fm::Detection& y = out.detections[i];
    EXPECT_EQ(x.class_id, y.class_id);
    EXPECT_EQ(x.class_name, y.class_name);
    EXPECT_EQ(x.score, y.score);
    EXPECT_EQ(x.x_min, y.x_min);
    EXPECT_EQ(x.y_min, y.y_min);
    EXPECT_EQ(x.x_max, y.x_max);
    EXPECT_EQ(x.y_max, y.y_max);
  }
  // The header / size overload gives the same message; no size: 0.
  const fm::Detection2DArray same = fm::toDetectionArrayMsg(in.header, 1024, 544, in.detections);
  EXPECT_EQ(same.detections.size(), 2u);
  EXPECT_EQ(same.detections[1].score, 0.5f);
  EXPECT_EQ(fm::fromDetectionArrayMsg(fm::toDetectionArrayMsg(in.header, 0, 0, {})).image_width, 0);
}

// ---------------------------------------------------------------------------
// Mesh and cloud

TEST(ConversionsMesh, OneTriangleMarker) {
  fm::BlockOutput block;
  block.triangles = {Eigen::Vector3f(1, 2, 0), Eigen::Vector3f(4, 5, 3), Eigen::Vector3f(7, 8, 6)};
  const ros::Time stamp(1700000002, 0);
  const visualization_msgs::Marker m = fm::meshBlockMarker(&block, 5, "map", stamp);
  EXPECT_EQ(m.header.frame_id, "map");
  EXPECT_EQ(m.header.stamp, stamp);
  EXPECT_EQ(m.ns, "tsdf_mesh");
  EXPECT_EQ(m.id, 5);
  EXPECT_EQ(m.type, visualization_msgs::Marker::TRIANGLE_LIST);
  EXPECT_EQ(m.action, visualization_msgs::Marker::ADD);
  EXPECT_EQ(m.pose.orientation.w, 1.0);
  EXPECT_EQ(m.scale.x, 1.0);
  EXPECT_EQ(m.scale.y, 1.0);
  EXPECT_EQ(m.scale.z, 1.0);
  EXPECT_EQ(m.color.a, 1.0f);
  ASSERT_EQ(m.points.size(), 3u);
  ASSERT_EQ(m.colors.size(), 3u);
  EXPECT_EQ(m.points[0].x, 1.0);
  EXPECT_EQ(m.points[0].y, 2.0);
  EXPECT_EQ(m.points[0].z, 0.0);
  EXPECT_EQ(m.points[2].x, 7.0);
  EXPECT_EQ(m.points[2].z, 6.0);
  // Intensity colour: the vertex's grey as r = g = b; a vertex without one
  // (0) takes the height ramp over 0..6 m (z 6 m: the ramp's red end).
  block.triangle_grey = {200, 51, 0};
  const visualization_msgs::Marker mi = fm::meshBlockMarker(&block, 5, "map", stamp);
  EXPECT_FLOAT_EQ(mi.colors[0].r, 200 / 255.0f);
  EXPECT_FLOAT_EQ(mi.colors[0].g, 200 / 255.0f);
  EXPECT_FLOAT_EQ(mi.colors[0].b, 200 / 255.0f);
  EXPECT_FLOAT_EQ(mi.colors[1].r, 51 / 255.0f);
  EXPECT_FLOAT_EQ(mi.colors[2].r, 1.0f);
  EXPECT_FLOAT_EQ(mi.colors[2].g, 0.0f);
  EXPECT_FLOAT_EQ(mi.colors[2].b, 0.0f);
  // Height: z 0 blue (hue 240), z 3 hue 120 (green), z 6 red.
  const visualization_msgs::Marker mh = fm::meshBlockMarker(&block, 5, "map", stamp, fm::MeshColoring::kHeight);
  EXPECT_FLOAT_EQ(mh.colors[0].b, 1.0f);
  EXPECT_FLOAT_EQ(mh.colors[0].r, 0.0f);
  EXPECT_FLOAT_EQ(mh.colors[1].g, 1.0f);
  EXPECT_FLOAT_EQ(mh.colors[1].r, 0.0f);
  EXPECT_FLOAT_EQ(mh.colors[2].r, 1.0f);
  // Normal: the face normal of (1,2,0) (4,5,3) (7,8,6) is degenerate (collinear
  // points); a right triangle in the x-y plane has normal +z: (0.5, 0.5, 1).
  fm::BlockOutput flat;
  flat.triangles = {Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(1, 0, 0), Eigen::Vector3f(0, 1, 0)};
  const visualization_msgs::Marker mn = fm::meshBlockMarker(&flat, 6, "map", stamp, fm::MeshColoring::kNormal);
  for (const auto& c : mn.colors) {
    EXPECT_FLOAT_EQ(c.r, 128 / 255.0f);
    EXPECT_FLOAT_EQ(c.g, 128 / 255.0f);
    EXPECT_FLOAT_EQ(c.b, 1.0f);
  }
  for (const auto& c : m.colors) EXPECT_EQ(c.a, 1.0f);

  // An empty or missing block: DELETE of that id, same frame.
  const fm::BlockOutput empty;
  for (const fm::BlockOutput* b : {static_cast<const fm::BlockOutput*>(nullptr), &empty}) {
    const visualization_msgs::Marker del = fm::meshBlockMarker(b, 9, "map", stamp);
    EXPECT_EQ(del.action, visualization_msgs::Marker::DELETE);
    EXPECT_EQ(del.id, 9);
    EXPECT_EQ(del.ns, "tsdf_mesh");
    EXPECT_EQ(del.header.frame_id, "map");
    EXPECT_TRUE(del.points.empty());
  }
}

TEST(ConversionsMesh, WholeMeshArray) {
  std::unordered_map<fm::BlockIndex, fm::BlockOutput, fm::BlockIndexHash> blocks;
  fm::BlockOutput tri;
  tri.triangles = {Eigen::Vector3f(0, 0, 1), Eigen::Vector3f(1, 0, 1), Eigen::Vector3f(0, 1, 1)};
  blocks[fm::BlockIndex(1, 2, 3)] = tri;
  blocks[fm::BlockIndex(0, 0, 0)] = fm::BlockOutput();  // empty: left out
  int asked = 0;
  const visualization_msgs::MarkerArray a = fm::meshToMarkerArray(blocks, "world", ros::Time(3, 0),
                                                                 [&](const fm::BlockIndex& b) {
                                                                   ++asked;
                                                                   EXPECT_TRUE(b == fm::BlockIndex(1, 2, 3));
                                                                   return 11;
                                                                 });
  EXPECT_EQ(asked, 1);
  ASSERT_EQ(a.markers.size(), 2u);
  EXPECT_EQ(a.markers[0].action, visualization_msgs::Marker::DELETEALL);
  EXPECT_EQ(a.markers[0].header.frame_id, "world");
  EXPECT_EQ(a.markers[1].action, visualization_msgs::Marker::ADD);
  EXPECT_EQ(a.markers[1].id, 11);
  EXPECT_EQ(a.markers[1].header.frame_id, "world");
  EXPECT_EQ(a.markers[1].header.stamp, ros::Time(3, 0));
  ASSERT_EQ(a.markers[1].points.size(), 3u);
  EXPECT_EQ(a.markers[1].points[1].x, 1.0);
  EXPECT_EQ(a.markers[1].points[1].z, 1.0);
}

TEST(ConversionsMesh, Cloud) {
  pcl::PointCloud<pcl::PointXYZI> cloud;
  pcl::PointXYZI a, b;
  a.x = 1, a.y = 2, a.z = 3, a.intensity = 0;
  b.x = 4, b.y = 5, b.z = 6, b.intensity = 77;
  cloud.push_back(a);
  cloud.push_back(b);
  const sensor_msgs::PointCloud2 msg = fm::toCloudMsg(cloud, "map", ros::Time(5, 6));
  EXPECT_EQ(msg.header.frame_id, "map");
  EXPECT_EQ(msg.header.stamp, ros::Time(5, 6));
  EXPECT_EQ(msg.width * msg.height, 2u);
  ASSERT_GE(msg.fields.size(), 3u);
  EXPECT_EQ(msg.fields[0].name, "x");
  float p[3];
  std::memcpy(p, &msg.data[msg.point_step], sizeof(p));
  EXPECT_EQ(p[0], 4.f);
  EXPECT_EQ(p[1], 5.f);
  EXPECT_EQ(p[2], 6.f);
  // The intensity field (the voxels' grey; 0 = none).
  bool found = false;
  for (const auto& f : msg.fields) {
    if (f.name != "intensity") continue;
    found = true;
    float g;
    std::memcpy(&g, &msg.data[msg.point_step + f.offset], sizeof(g));
    EXPECT_EQ(g, 77.f);
  }
  EXPECT_TRUE(found);
}

// ---------------------------------------------------------------------------
// Poses

TEST(ConversionsPose, TransformRoundTrip) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(1.5, -2.0, 0.25);
  const geometry_msgs::TransformStamped t = fm::toTransformMsg(T, "base_link", "cam0_optical", ros::Time(7, 8));
  EXPECT_EQ(t.header.frame_id, "base_link");
  EXPECT_EQ(t.child_frame_id, "cam0_optical");
  EXPECT_EQ(t.header.stamp, ros::Time(7, 8));
  EXPECT_DOUBLE_EQ(t.transform.translation.x, 1.5);
  EXPECT_DOUBLE_EQ(t.transform.translation.y, -2.0);
  EXPECT_DOUBLE_EQ(t.transform.translation.z, 0.25);
  const Eigen::Quaterniond q(T.linear());
  EXPECT_NEAR(std::abs(t.transform.rotation.w * q.w() + t.transform.rotation.x * q.x() +
                       t.transform.rotation.y * q.y() + t.transform.rotation.z * q.z()),
              1.0, 1e-12);
  const Eigen::Isometry3d back = fm::toIsometry(t);
  EXPECT_TRUE(back.isApprox(T, 1e-12));
}
