// Synthetic drives: ground-truth depth against analytic ray-plane
// intersections, cross-camera consistency, and the bags make_drive writes
// (contents, determinism, option errors), read back with rosbag.
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <cv_bridge/cv_bridge.h>
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Image.h>
#include <tf2_msgs/TFMessage.h>

#include <tf2/buffer_core.h>
#include <tf2_eigen/tf2_eigen.h>

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/tsdf_map.h"
#include "fisheye_mapping/core/tsdf_mesher.h"
#include "fisheye_mapping/core/rig.h"
#include "fisheye_mapping/core/synthetic_world.h"

namespace fm = fisheye_mapping;
using fm::synth::World;
using fm::synth::WorldConfig;

namespace {

const std::string kData = FM_TEST_DATA_DIR;
const std::string kRigArgs = " --camchain " + kData + "/small_rig_camchain.yaml --mount " + kData + "/small_rig_mount.yaml";

fm::Rig smallRig() { return fm::loadKalibrRig(kData + "/small_rig_camchain.yaml", kData + "/small_rig_mount.yaml"); }

TEST(SyntheticWorld, GroundTruthDepthOfFlatGroundIsTheRayPlaneIntersection) {
  WorldConfig wc;
  wc.preset = "flat";
  wc.moving_vehicles = 0;
  const World world(wc);
  const fm::Rig rig = smallRig();
  for (double t : {0.0, 3.3}) {
    for (const auto& cam : rig.cameras) {
      const Eigen::Isometry3d T_W_C = world.egoPose(t) * cam.T_base_cam;
      const auto rays = fm::pixelRays(cam.model);
      const auto frame = world.render(cam.model, rays, T_W_C, t, 1);
      int ground = 0, sky = 0;
      for (int v = 0; v < cam.model.height(); ++v) {
        for (int u = 0; u < cam.model.width(); ++u) {
          const Eigen::Vector3f& r = rays[v * cam.model.width() + u];
          const float got = frame.depth.at<float>(v, u);
          if (!(r.z() == r.z())) {
            EXPECT_TRUE(std::isnan(got));
            continue;
          }
          // Ray from the camera centre; ground z = 0: t = -h / d_z.
          const Eigen::Vector3d d = T_W_C.linear() * r.cast<double>();
          const double h = T_W_C.translation().z();
          const double expected = d.z() < 0 ? -h / d.z() : INFINITY;
          if (expected < 250.0) {
            ASSERT_NEAR(got, expected, 1e-5 * expected) << cam.name << " pixel " << u << "," << v;
            ++ground;
          } else {
            EXPECT_TRUE(std::isnan(got)) << cam.name << " pixel " << u << "," << v << " depth " << got;
            ++sky;
          }
        }
      }
      EXPECT_GT(ground, 10000);
      EXPECT_GT(sky, 1000);
    }
  }
}

TEST(SyntheticWorld, DepthAgreesAcrossCameras) {
  WorldConfig wc;
  const World world(wc);
  const fm::Rig rig = smallRig();
  const double t = 2.0;
  std::vector<World::Frame> frames;
  std::vector<Eigen::Isometry3d> poses;
  std::vector<std::vector<Eigen::Vector3f>> rays;
  for (const auto& cam : rig.cameras) {
    poses.push_back(world.egoPose(t) * cam.T_base_cam);
    rays.push_back(fm::pixelRays(cam.model));
    frames.push_back(world.render(cam.model, rays.back(), poses.back(), t, 7));
  }
  // A surface point seen by cam0 at range d, reprojected into cam1 / cam2:
  // that camera's depth there is the point's range from it.
  for (int other = 1; other < 3; ++other) {
    int checked = 0, agree = 0;
    const auto& cam = rig.cameras[other];
    for (int v = 0; v < 136; v += 2) {
      for (int u = 0; u < 256; u += 2) {
        const float d = frames[0].depth.at<float>(v, u);
        if (!std::isfinite(d)) continue;
        const Eigen::Vector3d X = poses[0] * (d * rays[0][v * 256 + u].cast<double>());
        const Eigen::Vector3d Xc = poses[other].inverse() * X;
        Eigen::Vector2d uv;
        if (!cam.model.project(Xc, &uv) || !cam.model.isInImage(uv)) continue;
        // Bilinear depth of the other camera, on smooth surfaces only (all four
        // neighbours within 5 % of each other): depth edges are where pixel
        // sampling, not the renderer, decides.
        const int u0 = static_cast<int>(std::floor(uv.x())), v0 = static_cast<int>(std::floor(uv.y()));
        if (u0 + 1 >= 256 || v0 + 1 >= 136) continue;
        const cv::Mat& D = frames[other].depth;
        const float q[4] = {D.at<float>(v0, u0), D.at<float>(v0, u0 + 1), D.at<float>(v0 + 1, u0), D.at<float>(v0 + 1, u0 + 1)};
        const float lo = std::min({q[0], q[1], q[2], q[3]}), hi = std::max({q[0], q[1], q[2], q[3]});
        if (!std::isfinite(lo) || !std::isfinite(hi) || hi > 1.05f * lo) continue;
        const double a = uv.x() - u0, b = uv.y() - v0;
        const double d2 = (1 - a) * (1 - b) * q[0] + a * (1 - b) * q[1] + (1 - a) * b * q[2] + a * b * q[3];
        ++checked;
        agree += std::abs(d2 - Xc.norm()) < 0.01 * Xc.norm();
      }
    }
    std::cout << "cam0 -> cam" << other << ": " << agree << " of " << checked << " points agree within 1 %\n";
    EXPECT_GT(checked, 3000);
    // Surfaces seen by cam0 but hidden from the other camera account for the rest.
    EXPECT_GE(agree, checked * 97 / 100);
  }
}

struct ToolRun {
  int status;
  std::string output;
};

ToolRun makeDrive(const std::string& args) {
  const std::string cmd = std::string(FM_MAKE_DRIVE) + " " + args + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  ToolRun r{-1, ""};
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), pipe)) > 0) r.output.append(buf, n);
  r.status = WEXITSTATUS(pclose(pipe));
  return r;
}

std::string readFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

class MakeDrive : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/fm_drive_test_XXXXXX";
    dir_ = mkdtemp(tmpl);
  }
  void TearDown() override { std::system(("rm -rf " + dir_).c_str()); }
  std::string dir_;
};

TEST_F(MakeDrive, BagHoldsImagesTruthAndTf) {
  const ToolRun r = makeDrive("--out " + dir_ + "/a" + kRigArgs + " --duration 0.5 --rate 10 --seed 3");
  ASSERT_EQ(r.status, 0) << r.output;
  rosbag::Bag bag(dir_ + "/a/drive.bag");
  rosbag::View view(bag);
  std::map<std::string, int> count;
  std::map<std::string, ros::Time> last;
  std::vector<ros::Time> image_stamps, det_stamps;
  std::set<std::string> static_children;
  const ros::Time t0(1700000000, 0);
  for (const rosbag::MessageInstance& m : view) {
    const std::string topic = m.getTopic();
    ++count[topic];
    if (last.count(topic)) EXPECT_GE(m.getTime(), last[topic]) << topic;
    last[topic] = m.getTime();
    if (auto img = m.instantiate<sensor_msgs::Image>()) {
      const int cam = topic[4] - '0';
      EXPECT_EQ(img->header.frame_id, "cam" + std::to_string(cam) + "_optical_frame");
      EXPECT_EQ(img->width, 256u);
      EXPECT_EQ(img->height, 136u);
      EXPECT_EQ(img->header.stamp, m.getTime());
      EXPECT_EQ(img->encoding, topic.find("depth") != std::string::npos ? "32FC1" : "mono8") << topic;
      if (topic == "/cam0/image_raw") image_stamps.push_back(img->header.stamp);
    } else if (auto dets = m.instantiate<fisheye_mapping::Detection2DArray>()) {
      EXPECT_EQ(dets->header.frame_id, "cam0_optical_frame");
      det_stamps.push_back(dets->header.stamp);
      for (const auto& d : dets->detections) {
        EXPECT_EQ(d.class_name, "car");
        EXPECT_LT(d.x_min, d.x_max);
        EXPECT_LE(d.x_max, 256.0f);
      }
    } else if (auto tf = m.instantiate<tf2_msgs::TFMessage>()) {
      for (const auto& t : tf->transforms) {
        if (topic == "/tf_static") {
          EXPECT_EQ(t.header.frame_id, "base_link");
          static_children.insert(t.child_frame_id);
        } else {
          EXPECT_EQ(t.header.frame_id, "map");
          EXPECT_EQ(t.child_frame_id, "base_link");
        }
      }
    }
  }
  // 0.5 s at 10 Hz: 5 sets of 3 cameras; truth for cam0 only; tf at 100 Hz.
  EXPECT_EQ(count["/cam0/image_raw"], 5);
  EXPECT_EQ(count["/cam1/image_raw"], 5);
  EXPECT_EQ(count["/cam2/image_raw"], 5);
  EXPECT_EQ(count["/cam0/depth_gt"], 5);
  EXPECT_EQ(count["/cam1/depth_gt"], 0);
  EXPECT_EQ(count["/cam0/detections_gt"], 5);
  EXPECT_EQ(count["/tf_static"], 1);
  EXPECT_EQ(count["/tf"], 56);  // 0 .. 0.55 s every 10 ms
  EXPECT_EQ(static_children, (std::set<std::string>{"cam0_optical_frame", "cam1_optical_frame", "cam2_optical_frame"}));
  ASSERT_EQ(image_stamps.size(), 5u);
  for (int i = 0; i < 5; ++i) EXPECT_EQ(image_stamps[i], t0 + ros::Duration(0.1 * i));
  EXPECT_EQ(det_stamps, image_stamps);
  // The rig and the static scene come along; the rig reads back.
  const fm::Rig back = fm::loadKalibrRig(dir_ + "/a/camchain.yaml", dir_ + "/a/mount.yaml");
  EXPECT_EQ(back.cameras.size(), 3u);
  EXPECT_EQ(readFile(dir_ + "/a/static_scene.ply").substr(0, 3), "ply");
}

// The bag's conventions end to end: depth_gt fused with the poses from /tf and
// /tf_static lands on the world's static geometry.
TEST_F(MakeDrive, FusedTruthLiesOnTheStaticScene) {
  const ToolRun r = makeDrive("--out " + dir_ + "/f" + kRigArgs + " --duration 1.5 --moving 0 --seed 4");
  ASSERT_EQ(r.status, 0) << r.output;
  rosbag::Bag bag(dir_ + "/f/drive.bag");
  tf2::BufferCore tf(ros::Duration(100));
  std::vector<sensor_msgs::ImageConstPtr> depths;
  for (const auto& m : rosbag::View(bag)) {
    if (auto t = m.instantiate<tf2_msgs::TFMessage>()) {
      for (const auto& x : t->transforms) tf.setTransform(x, "bag", m.getTopic() == "/tf_static");
    } else if (m.getTopic() == "/cam0/depth_gt") {
      depths.push_back(m.instantiate<sensor_msgs::Image>());
    }
  }
  ASSERT_EQ(depths.size(), 15u);
  const fm::Rig rig = smallRig();
  fm::TsdfConfig cfg;
  cfg.voxel_size = 0.1;
  fm::TsdfMap map(cfg);
  for (const auto& d : depths) {
    const Eigen::Isometry3d T_W_C = tf2::transformToEigen(tf.lookupTransform("map", d->header.frame_id, d->header.stamp));
    const Eigen::Isometry3d T_W_B = tf2::transformToEigen(tf.lookupTransform("map", "base_link", d->header.stamp));
    map.integrate(cv_bridge::toCvShare(d)->image, rig.cameras[0].model, T_W_C, T_W_B.translation());
  }
  fm::TsdfMesher mesher(3);
  mesher.rebuild(map);
  const auto cloud = mesher.surfaceCloud();
  // The same world as make_drive built (route length = speed * duration + 60).
  WorldConfig wc;
  wc.seed = 4;
  wc.moving_vehicles = 0;
  wc.route_length = 8.0 * 1.5 + 60;
  const World world(wc);
  size_t near = 0;
  for (const auto& p : cloud) {
    const Eigen::Vector3d q(p.x, p.y, p.z);
    double dist = std::abs(q.z());
    for (const auto& b : world.staticBoxes()) {
      const Eigen::Vector3d c = 0.5 * (b.lo + b.hi), h = 0.5 * (b.hi - b.lo);
      const Eigen::Vector3d e = (q - c).cwiseAbs() - h;
      dist = std::min(dist, std::abs(e.cwiseMax(0.0).norm() + std::min(e.maxCoeff(), 0.0)));
    }
    for (const auto& sp : world.staticSpheres()) dist = std::min(dist, std::abs((q - sp.c).norm() - sp.r));
    near += dist < cfg.voxel_size;
  }
  std::cout << cloud.size() << " surface points, " << near << " within one voxel of the static scene\n";
  EXPECT_GT(cloud.size(), 5000u);
  // The rest sits at box edges and depth discontinuities, which a TSDF rounds off.
  EXPECT_GE(near, cloud.size() * 95 / 100);
}

TEST_F(MakeDrive, JitterAndDropsExerciseSynchronisation) {
  const ToolRun r = makeDrive("--out " + dir_ + "/j" + kRigArgs + " --duration 2 --jitter-ms 5 --drop 0.2 --gt-depth none --moving 0");
  ASSERT_EQ(r.status, 0) << r.output;
  rosbag::Bag bag(dir_ + "/j/drive.bag");
  rosbag::View view(bag, rosbag::TopicQuery({"/cam0/image_raw", "/cam1/image_raw", "/cam2/image_raw"}));
  int images = 0, off_grid = 0;
  const ros::Time t0(1700000000, 0);
  for (const auto& m : view) {
    ++images;
    const double dt = (m.getTime() - t0).toSec();
    const double nearest = std::round(dt * 10) / 10;
    EXPECT_LE(std::abs(dt - nearest), 0.005 + 1e-9);
    off_grid += std::abs(dt - nearest) > 1e-6;
  }
  // 60 images less about 20 % dropped.
  EXPECT_LT(images, 58);
  EXPECT_GT(images, 36);
  EXPECT_GT(off_grid, images / 2);
}

TEST_F(MakeDrive, SameSeedSameBag) {
  const std::string args = kRigArgs + " --duration 0.3 --pose-noise 0.05 --jitter-ms 3 --drop 0.1";
  ASSERT_EQ(makeDrive("--out " + dir_ + "/1 --seed 5" + args).status, 0);
  ASSERT_EQ(makeDrive("--out " + dir_ + "/2 --seed 5" + args).status, 0);
  ASSERT_EQ(makeDrive("--out " + dir_ + "/3 --seed 6" + args).status, 0);
  const std::string a = readFile(dir_ + "/1/drive.bag"), b = readFile(dir_ + "/2/drive.bag"), c = readFile(dir_ + "/3/drive.bag");
  EXPECT_GT(a.size(), 100000u);
  EXPECT_TRUE(a == b) << "same seed, different bags";
  EXPECT_FALSE(a == c) << "another seed gave the same bag";
}

TEST_F(MakeDrive, BadOptionsGiveClearErrors) {
  std::ofstream(dir_ + "/empty.yaml") << "{}\n";
  const struct {
    std::string args, expected;
  } cases[] = {
      {"--out " + dir_ + "/x --camchain " + dir_ + "/empty.yaml --mount " + kData + "/small_rig_mount.yaml",
       "cam0: missing (no camera in the camchain)"},
      {"--out " + dir_ + "/x" + kRigArgs + " --rate -10", "--rate must be positive"},
      {"--out " + dir_ + "/x" + kRigArgs + " --rate ten", "--rate needs a number, got 'ten'"},
      {"--out " + dir_ + "/x" + kRigArgs + " --preset moon", "preset must be urban, forest or flat"},
      {"--out " + dir_ + "/x" + kRigArgs + " --drop 1.5", "--drop must lie in [0, 1)"},
      {"--out /proc/no_such_dir/x" + kRigArgs, "/proc/no_such_dir"},
      {kRigArgs, "--out, --camchain and --mount are required"},
  };
  for (const auto& c : cases) {
    const ToolRun r = makeDrive(c.args);
    EXPECT_NE(r.status, 0) << c.args;
    EXPECT_NE(r.output.find(c.expected), std::string::npos) << c.args << "\n" << r.output;
  }
}

}  // namespace
