// The core FrameSetMapper (depth stage -> masking -> TSDF fusion): checked on
// the two-camera test rig against hand-computed masks and analytic geometry,
// and against the stage objects run one by one (what the nodelets do).
#include <gtest/gtest.h>

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
  for (int i = 0; i < 4; ++i) r = mapper.processDepth(wall.clone(), Eigen::Isometry3d::Identity(), boxes);
  EXPECT_EQ(r.masked_pixels, 120u * 70u);
  EXPECT_EQ(countValid(r.depth.depth), valid - 120u * 70u);
  EXPECT_EQ(r.fusion.valid_pixels, valid - 120u * 70u);
  EXPECT_TRUE(std::isnan(r.depth.depth.at<float>(212, 452)));
  EXPECT_TRUE(std::isnan(r.depth.depth.at<float>(281, 571)));
  EXPECT_TRUE(std::isfinite(r.depth.depth.at<float>(211, 452)));
  EXPECT_TRUE(std::isfinite(r.depth.depth.at<float>(281, 572)));
  EXPECT_EQ(mapper.frameSets(), 4u);
  EXPECT_GE(r.ms.total_ms, r.ms.fuse_ms);
  mapper.finish();
  const auto cloud = mapper.mesher().surfaceCloud();
  ASSERT_GT(cloud.size(), 1000u);
  size_t on_wall = 0;
  for (const auto& p : cloud) on_wall += std::fabs(p.x - 9.5) <= 0.1;
  EXPECT_GE(double(on_wall) / cloud.size(), 0.95);
  EXPECT_GT(mapper.mesher().numTriangles(), 0u);
}

// With images, the mapper's depth is the depth stage's, masked: the same as
// running DepthStage and maskDepthBoxes one after the other (the nodelets).
TEST(FrameSetMapper, ImagesGiveTheDepthStagesDepthMasked) {
  const fm::Rig rig = twoCameraRig();
  fm::FrameSetMapperConfig c = smallConfig();
  c.depth.sweep.far = 30.0;
  cv::Mat texture(544, 1024, CV_8UC1);
  cv::RNG rng(7);
  rng.fill(texture, cv::RNG::UNIFORM, 0, 256);
  const std::vector<cv::Mat> images{texture, texture.clone()};
  fm::ImageBoxes boxes;
  fm::Detection box;
  box.x_min = 300, box.x_max = 400, box.y_min = 100, box.y_max = 200;
  boxes.boxes = {box};
  boxes.image_width = 1024, boxes.image_height = 544;

  fm::FrameSetMapper mapper(rig, c);
  const fm::FrameSetResult r = mapper.process(images, Eigen::Isometry3d::Identity(), boxes);

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
  EXPECT_EQ(r.masked_pixels, size_t(cv::countNonZero(r.mask)));
  EXPECT_GT(r.masked_pixels, 0u);
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
