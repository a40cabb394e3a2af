// The core FrameSetMapper (depth stage -> masking -> TSDF fusion): checked on
// the two-camera test rig against hand-computed masks and analytic geometry,
// and against the stage objects run one by one (what the nodelets do).
#include <gtest/gtest.h>

#include <algorithm>
#include <opencv2/imgproc.hpp>

#include <chrono>
#include <cmath>
#include <limits>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/mapping/frame_set_mapper.h"

namespace fm = fisheye_mapping;

namespace {

fm::Rig twoCameraRig() {
  return fm::loadKalibrRig(FM_TEST_DATA_DIR "/two_camera_camchain.yaml", FM_TEST_DATA_DIR "/two_camera_mount.yaml");
}

// Range along cam0's rays to the plane z = wall (cam0's optical frame), NaN
// where a ray does not meet it at a small enough angle.
cv::Mat wallDepth(const fm::Rig& rig, double wall) {
  const auto& cam = rig.cameras[0];
  cv::Mat d(cam.model.height(), cam.model.width(), CV_32FC1, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  for (int v = 0; v < d.rows; ++v) {
    for (int u = 0; u < d.cols; ++u) {
      Eigen::Vector3d ray;
      if (!cam.model.unproject(Eigen::Vector2d(u + 0.5, v + 0.5), &ray)) continue;
      ray.normalize();
      if (ray.z() > 0.5) d.at<float>(v, u) = float(wall / ray.z());
    }
  }
  return d;
}

// Pixels that are not NaN (NaN != NaN).
size_t countValid(const cv::Mat& d) { return size_t(cv::countNonZero(d == d)); }

fm::FrameSetMapperConfig smallConfig() {
  fm::FrameSetMapperConfig c;
  c.tsdf.voxel_size = 0.1;
  c.tsdf.min_observations = 3;
  c.tsdf.max_range = 20.0;
  c.mask.margin_px = 10.0;
  c.mesh_every = 2;
  return c;
}

}  // namespace

// A wall 8 m ahead of cam0, a box in the middle of the image: the mask is the
// box grown by the 10 px margin (pixel centres inside: 120 x 70 pixels, by
// hand), fusion sees every other valid pixel, and the map's surface lies on the
// wall (cam0 looks along base +x from 1.5 m ahead of base_link: x = 9.5 m).
TEST(FrameSetMapper, GivenDepthIsMaskedAndFusedOnTheWall) {
  const fm::Rig rig = twoCameraRig();
  fm::FrameSetMapper mapper(rig, smallConfig());
  const cv::Mat wall = wallDepth(rig, 8.0);
  const size_t valid = countValid(wall);
  ASSERT_GT(valid, 50000u);
  fm::ImageBoxes boxes;
  fm::Detection box;
  box.x_min = 462.25f, box.x_max = 561.75f, box.y_min = 222.25f, box.y_max = 271.75f;
  boxes.boxes = {box};
  boxes.image_width = 1024, boxes.image_height = 544;
  fm::FrameSetResult r;
  double call_ms = 0;  // the last call's wall time, measured here
  for (int i = 0; i < 4; ++i) {
    cv::Mat depth = wall.clone();
    const auto t0 = std::chrono::steady_clock::now();
    r = mapper.processDepth(std::move(depth), Eigen::Isometry3d::Identity(), boxes);
    call_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  }
  EXPECT_EQ(r.masked_pixels, 120u * 70u);
  EXPECT_EQ(countValid(r.depth.depth), valid - 120u * 70u);
  EXPECT_EQ(r.fusion.valid_pixels, valid - 120u * 70u);
  EXPECT_TRUE(std::isnan(r.depth.depth.at<float>(212, 452)));
  EXPECT_TRUE(std::isnan(r.depth.depth.at<float>(281, 571)));
  EXPECT_TRUE(std::isfinite(r.depth.depth.at<float>(211, 452)));
  EXPECT_TRUE(std::isfinite(r.depth.depth.at<float>(281, 572)));
  EXPECT_EQ(mapper.frameSets(), 4u);
  // The total is the call's own time, as measured from outside it (all but
  // the call's entry and return), and the fusion of 50,000 pixels is a real part of it.
  EXPECT_LE(r.ms.total_ms, call_ms + 1e-6);
  EXPECT_GE(r.ms.total_ms, 0.9 * call_ms - 1.0) << "the call took " << call_ms << " ms";
  EXPECT_GT(r.ms.fuse_ms, 0.0);
  EXPECT_GT(r.ms.mask_ms, 0.0);
  mapper.finish();
  const auto cloud = mapper.mesher().surfaceCloud();
  ASSERT_GT(cloud.size(), 1000u);
  size_t on_wall = 0;
  for (const auto& p : cloud) on_wall += std::fabs(p.x - 9.5) <= 0.1;
  EXPECT_GE(double(on_wall) / cloud.size(), 0.95);
  EXPECT_GT(mapper.mesher().numTriangles(), 0u);
}

// Images of a textured wall `wall` metres ahead of cam0 (plane z = wall in
// cam0's frame), rendered for every camera of the rig.
std::vector<cv::Mat> wallImages(const fm::Rig& rig, double wall) {
  // The wall's texture: 2 cm texels over x, y in [-20, 20] m, smoothed.
  cv::Mat texels(2000, 2000, CV_32FC1);
  cv::RNG rng(7);
  rng.fill(texels, cv::RNG::UNIFORM, 0.0, 1.0);
  cv::GaussianBlur(texels, texels, cv::Size(0, 0), 1.5);
  cv::normalize(texels, texels, 0.0, 255.0, cv::NORM_MINMAX);
  const Eigen::Isometry3d T_c0_base = rig.cameras[0].T_base_cam.inverse();
  std::vector<cv::Mat> images;
  for (const auto& cam : rig.cameras) {
    const Eigen::Isometry3d T_c0_c = T_c0_base * cam.T_base_cam;
    cv::Mat img(cam.model.height(), cam.model.width(), CV_8UC1, cv::Scalar(0));
    for (int v = 0; v < img.rows; ++v) {
      for (int u = 0; u < img.cols; ++u) {
        Eigen::Vector3d ray;
        if (!cam.model.unproject(Eigen::Vector2d(u + 0.5, v + 0.5), &ray)) continue;
        const Eigen::Vector3d o = T_c0_c.translation(), d = T_c0_c.linear() * ray.normalized();
        if (d.z() < 0.3) continue;
        const Eigen::Vector3d p = o + (wall - o.z()) / d.z() * d;
        const float tx = float((p.x() + 20.0) / 0.02), ty = float((p.y() + 20.0) / 0.02);
        if (tx < 0 || ty < 0 || tx >= texels.cols - 1 || ty >= texels.rows - 1) continue;
        cv::Mat px;
        cv::getRectSubPix(texels, cv::Size(1, 1), cv::Point2f(tx, ty), px);
        img.at<uchar>(v, u) = cv::saturate_cast<uchar>(px.at<float>(0, 0));
      }
    }
    images.push_back(img);
  }
  return images;
}

// With images, the mapper's depth is the depth stage's, masked: the same as
// running DepthStage and maskDepthBoxes one after the other (the nodelets).
// Images of a textured wall 8 m ahead of cam0 (plane z = 8 in cam0's frame),
// rendered for both cameras of the rig: the depth lies on the wall, the box
// (grown by the 10 px margin: pixel centres in [290, 410] x [90, 210], 120 x
// 120 pixels by hand) is masked, and the mapper's depth is the depth stage's
// run alone and masked (what the nodelets do one stage each).
TEST(FrameSetMapper, ImagesGiveTheDepthStagesDepthMasked) {
  const fm::Rig rig = twoCameraRig();
  fm::FrameSetMapperConfig c = smallConfig();
  c.depth.sweep.far = 30.0;
  const double wall = 8.0;
  const std::vector<cv::Mat> images = wallImages(rig, wall);
  fm::ImageBoxes boxes;
  fm::Detection box;
  box.x_min = 300, box.x_max = 400, box.y_min = 100, box.y_max = 200;
  boxes.boxes = {box};
  boxes.image_width = 1024, boxes.image_height = 544;

  fm::FrameSetMapper mapper(rig, c);
  const fm::FrameSetResult r = mapper.process(images, Eigen::Isometry3d::Identity(), boxes);

  // On the wall: the truth is wallDepth (range along cam0's rays to z = 8).
  const cv::Mat truth = wallDepth(rig, wall);
  std::vector<double> rel;
  for (int v = 0; v < truth.rows; ++v)
    for (int u = 0; u < truth.cols; ++u) {
      const float d = r.depth.depth.at<float>(v, u), t = truth.at<float>(v, u);
      if (std::isfinite(d) && std::isfinite(t)) rel.push_back(std::abs(d - t) / t);
    }
  ASSERT_GT(rel.size(), 20000u);
  std::nth_element(rel.begin(), rel.begin() + rel.size() / 2, rel.end());
  EXPECT_LT(rel[rel.size() / 2], 0.03) << "median relative depth error on the wall";
  // The box, by hand.
  EXPECT_EQ(r.masked_pixels, 120u * 120u);
  for (int v = 90; v < 210; ++v)
    for (int u = 290; u < 410; ++u) ASSERT_TRUE(std::isnan(r.depth.depth.at<float>(v, u))) << u << "," << v;
  EXPECT_EQ(r.mask.at<uchar>(89, 300), 0);
  EXPECT_EQ(r.mask.at<uchar>(90, 290), 255);
  EXPECT_EQ(r.mask.at<uchar>(209, 409), 255);
  EXPECT_EQ(r.mask.at<uchar>(210, 409), 0);

  // The stages one by one give the same depth.
  fm::DepthStage stage(rig, c.depth);
  fm::DepthResult d = stage.compute(images);
  fm::maskDepthBoxes(d.depth, boxes.boxes, float(c.mask.margin_px), 1024, 544);
  ASSERT_EQ(r.depth.depth.size(), d.depth.size());
  size_t differ = 0;
  for (int v = 0; v < d.depth.rows; ++v) {
    for (int u = 0; u < d.depth.cols; ++u) {
      const float a = r.depth.depth.at<float>(v, u), b = d.depth.at<float>(v, u);
      differ += !((std::isnan(a) && std::isnan(b)) || a == b);
    }
  }
  EXPECT_EQ(differ, 0u);
}

// submit(): the depth of a frame set overlaps the previous one's masking and
// fusion, and each result (handed back a frame set late, the last by
// flush()) is the one process() gives, in order; the map ends the same. A
// frame set without the reference image is refused by its submit(), naming
// the camera, and the one before it still comes back.
TEST(FrameSetMapper, SubmitPipelinesAndGivesWhatProcessGives) {
  const fm::Rig rig = twoCameraRig();
  fm::FrameSetMapperConfig c = smallConfig();
  c.depth.sweep.far = 30.0;
  c.mesh_every = 2;
  const std::vector<cv::Mat> images = wallImages(rig, 8.0);
  fm::ImageBoxes boxes;
  fm::Detection box;
  box.x_min = 300, box.x_max = 400, box.y_min = 100, box.y_max = 200;
  boxes.boxes = {box};
  boxes.image_width = 1024, boxes.image_height = 544;
  std::vector<Eigen::Isometry3d> poses;
  for (int k = 0; k < 3; ++k) poses.push_back(Eigen::Isometry3d(Eigen::Translation3d(0.0, 0.2 * k, 0.0)));
  fm::FrameSetMapper one(rig, c), piped(rig, c);
  std::vector<fm::FrameSetResult> expected, got;
  // Wall times measured here: each submit() call, and from a set's submit()
  // to the call that returned its result.
  using SteadyClock = std::chrono::steady_clock;
  auto ms = [](SteadyClock::time_point a, SteadyClock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  std::vector<SteadyClock::time_point> submitted;
  std::vector<double> submit_ms, until_result_ms;
  for (int k = 0; k < 3; ++k) {
    expected.push_back(one.process(images, poses[k], boxes));
    submitted.push_back(SteadyClock::now());
    std::optional<fm::FrameSetResult> previous = piped.submit(images, poses[k], boxes);
    const auto returned = SteadyClock::now();
    submit_ms.push_back(ms(submitted.back(), returned));
    EXPECT_EQ(previous.has_value(), k > 0) << k;
    if (previous) got.push_back(std::move(*previous)), until_result_ms.push_back(ms(submitted[k - 1], returned));
  }
  std::optional<fm::FrameSetResult> last = piped.flush();
  until_result_ms.push_back(ms(submitted[2], SteadyClock::now()));
  ASSERT_TRUE(last);
  got.push_back(std::move(*last));
  EXPECT_FALSE(piped.flush());
  ASSERT_EQ(got.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(cv::norm(got[k].mask, expected[k].mask, cv::NORM_INF), 0.0) << k;
    EXPECT_EQ(got[k].masked_pixels, 120u * 120u) << k;
    const cv::Mat a = got[k].depth.depth, b = expected[k].depth.depth;
    EXPECT_EQ(cv::countNonZero((a != b) & (a == a)), 0) << k;
    EXPECT_EQ(cv::countNonZero(a == a), cv::countNonZero(b == b)) << k;
    EXPECT_EQ(got[k].fusion.valid_pixels, expected[k].fusion.valid_pixels) << k;
    EXPECT_GT(got[k].ms.fuse_ms, 0.0) << k;
    // A set's total runs from its submit() to the end of its fusion: no
    // shorter than its submit() call (the fusion starts as the call returns),
    // no longer than until its result came back.
    EXPECT_GE(got[k].ms.total_ms, 0.9 * submit_ms[k] - 1.0) << k;
    EXPECT_LE(got[k].ms.total_ms, until_result_ms[k] + 1e-6) << k;
  }
  EXPECT_EQ(piped.frameSets(), 3u);
  one.finish();
  piped.finish();
  EXPECT_EQ(piped.mesher().surfaceCloud().size(), one.mesher().surfaceCloud().size());
  EXPECT_GT(piped.mesher().surfaceCloud().size(), 1000u);

  // A frame set without the reference image: refused at once, naming it; the
  // frame set submitted before it comes back from flush().
  fm::FrameSetMapper m(rig, c);
  EXPECT_FALSE(m.submit(images, poses[0], boxes));
  try {
    m.submit({cv::Mat(), images[1]}, poses[1], boxes);
    ADD_FAILURE() << "missing reference image accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("cam0"), std::string::npos) << e.what();
  }
  std::optional<fm::FrameSetResult> first = m.flush();
  ASSERT_TRUE(first);
  EXPECT_EQ(first->masked_pixels, 120u * 120u);
  EXPECT_EQ(m.frameSets(), 1u);
}

TEST(FrameSetMapper, BadStageConfigurationIsNamed) {
  const fm::Rig rig = twoCameraRig();
  fm::FrameSetMapperConfig c = smallConfig();
  c.depth.reference_camera = "cam7";
  try {
    fm::FrameSetMapper m(rig, c);
    ADD_FAILURE() << "unknown reference camera accepted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("reference_camera"), std::string::npos) << e.what();
  }
  c = smallConfig();
  c.depth.support_cameras = {"cam0"};
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = smallConfig();
  c.mesh_every = 0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  // A missing reference image is named, not a crash.
  fm::FrameSetMapper m(rig, smallConfig());
  try {
    m.process({cv::Mat(), cv::Mat(544, 1024, CV_8UC1, cv::Scalar(0))}, Eigen::Isometry3d::Identity());
    ADD_FAILURE() << "missing reference image accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("cam0"), std::string::npos) << e.what();
  }
}
