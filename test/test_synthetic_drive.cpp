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
#include <yaml-cpp/yaml.h>
#include <opencv2/imgproc.hpp>

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"

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
      // Bounds (issue 15): beyond them a run would hang or fill the memory.
      {"--out " + dir_ + "/x" + kRigArgs + " --moving 100000", "--moving must lie in [0, 100], got 100000"},
      {"--out " + dir_ + "/x" + kRigArgs + " --moving 2.5", "--moving needs a whole number, got '2.5'"},
      {"--out " + dir_ + "/x" + kRigArgs + " --duration 1e9 --rate 1e9", "--rate must be at most 100 Hz, got 1000000000"},
      {"--out " + dir_ + "/x" + kRigArgs + " --duration 1e9", "--duration must be at most 3600 s, got 1000000000"},
      {"--out " + dir_ + "/x" + kRigArgs + " --duration 3600 --rate 100",
       "--duration x --rate must give at most 36000 frame sets, got 360000"},
      {"--out " + dir_ + "/x" + kRigArgs + " --duration 0.05", "--duration x --rate must give at least 1 frame set, got 0.5"},
      {"--out " + dir_ + "/x" + kRigArgs + " --speed 0", "--speed must lie in (0, 60] m/s, got 0"},
      {"--out " + dir_ + "/x" + kRigArgs + " --speed 60 --duration 3600 --rate 1",
       "--speed x --duration must be at most 50000 m of route, got 216000"},
      {"--out " + dir_ + "/x" + kRigArgs + " --seed -1", "--seed must lie in [0, 4294967295], got -1"},
      {"--out " + dir_ + "/x" + kRigArgs + " --seed 1.5", "--seed needs a whole number, got '1.5'"},
      {"--out " + dir_ + "/x" + kRigArgs + " --rate nan", "--rate needs a number, got 'nan'"},
      {"--out " + dir_ + "/x --camchain /tmp --mount " + kData + "/small_rig_mount.yaml",
       "/tmp: is a directory, expected a calibration file"},
  };
  for (const auto& c : cases) {
    const ToolRun r = makeDrive(c.args);
    EXPECT_NE(r.status, 0) << c.args;
    EXPECT_NE(r.output.find(c.expected), std::string::npos) << c.args << "\n" << r.output;
  }
}

// --- Realistic drives: each perturbation differs from the truth by the seeded amount.

TEST(RealisticRig, ExtrinsicErrorsHaveTheSeededSpreadAndDependOnTheCameraAlone) {
  const double rot = 0.3, trans = 5.0;
  const auto errors = fm::synth::drawExtrinsicErrors(3001, rot, trans, 9);
  EXPECT_EQ(errors[0].rotation_deg.norm(), 0.0);  // the reference is the frame of the others
  EXPECT_EQ(errors[0].translation_mm.norm(), 0.0);
  Eigen::Vector3d sr = Eigen::Vector3d::Zero(), st = Eigen::Vector3d::Zero();
  for (size_t i = 1; i < errors.size(); ++i) {
    sr += errors[i].rotation_deg.cwiseAbs2();
    st += errors[i].translation_mm.cwiseAbs2();
  }
  const double n = static_cast<double>(errors.size() - 1);
  for (int a = 0; a < 3; ++a) {  // sample std. dev. of 3000 normals: within 5 % of sigma
    EXPECT_NEAR(std::sqrt(sr[a] / n), rot, 0.05 * rot);
    EXPECT_NEAR(std::sqrt(st[a] / n), trans, 0.05 * trans);
  }
  // Camera i's error comes from (seed, i) alone: a smaller rig gets the same.
  const auto few = fm::synth::drawExtrinsicErrors(3, rot, trans, 9);
  EXPECT_EQ(few[2].rotation_deg, errors[2].rotation_deg);
  EXPECT_NE(fm::synth::drawExtrinsicErrors(3, rot, trans, 10)[2].rotation_deg, errors[2].rotation_deg);
}

TEST(RealisticRig, PerturbedRigDiffersFromTheTruthByTheErrors) {
  const fm::Rig truth = fm::loadKalibrRig(kData + "/small_rig_camchain.yaml", kData + "/small_rig_mount.yaml");
  std::vector<fm::synth::ExtrinsicError> errors(truth.cameras.size());
  ASSERT_GE(errors.size(), 2u);
  errors[1].rotation_deg = Eigen::Vector3d(0.3, -0.4, 0.0);  // 0.5 deg about (0.6, -0.8, 0)
  errors[1].translation_mm = Eigen::Vector3d(0.0, 3.0, 4.0);  // 5 mm
  const fm::Rig given = fm::synth::perturbRig(truth, errors);
  const Eigen::Isometry3d d = truth.cameras[1].T_cam0_cam.inverse() * given.cameras[1].T_cam0_cam;
  const Eigen::AngleAxisd aa(d.linear());
  EXPECT_NEAR(aa.angle() * 180.0 / M_PI, 0.5, 1e-9);
  EXPECT_NEAR(aa.axis().dot(Eigen::Vector3d(0.6, -0.8, 0.0)), 1.0, 1e-9);
  EXPECT_NEAR((d.translation() - Eigen::Vector3d(0.0, 0.003, 0.004)).norm(), 0.0, 1e-12);
  EXPECT_TRUE(given.cameras[0].T_cam0_cam.isApprox(truth.cameras[0].T_cam0_cam, 1e-12));
  // The mount of the reference stays; every camera's mount follows from it.
  for (size_t i = 0; i < truth.cameras.size(); ++i) {
    EXPECT_TRUE((given.cameras[0].T_base_cam * given.cameras[i].T_cam0_cam).isApprox(given.cameras[i].T_base_cam, 1e-12));
  }
  EXPECT_TRUE(given.cameras[0].T_base_cam.isApprox(truth.cameras[0].T_base_cam, 1e-12));
}

TEST_F(MakeDrive, CalibrationErrorIsWrittenBesideTheTruth) {
  const ToolRun r = makeDrive("--out " + dir_ + "/c" + kRigArgs + " --duration 0.2 --seed 4 --calib-rot-deg 0.5 --calib-trans-mm 10");
  ASSERT_EQ(r.status, 0) << r.output;
  const fm::Rig given = fm::loadKalibrRig(dir_ + "/c/camchain.yaml", dir_ + "/c/mount.yaml");
  const fm::Rig truth = fm::loadKalibrRig(dir_ + "/c/camchain_true.yaml", dir_ + "/c/mount.yaml");
  const auto errors = fm::synth::drawExtrinsicErrors(static_cast<int>(truth.cameras.size()), 0.5, 10.0, 4);
  const YAML::Node listed = YAML::LoadFile(dir_ + "/c/calibration_error.yaml");
  for (size_t i = 1; i < truth.cameras.size(); ++i) {
    const Eigen::Isometry3d d = truth.cameras[i].T_cam0_cam.inverse() * given.cameras[i].T_cam0_cam;
    const double angle = Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI;
    EXPECT_NEAR(angle, errors[i].rotation_deg.norm(), 1e-5) << truth.cameras[i].name;  // YAML keeps ~1e-9
    EXPECT_NEAR((d.translation() * 1e3 - errors[i].translation_mm).norm(), 0.0, 1e-4) << truth.cameras[i].name;
    const auto rot = listed[truth.cameras[i].name]["rotation_deg"].as<std::vector<double>>();
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(rot[a], errors[i].rotation_deg[a], 1e-4);
    EXPECT_GT(angle, 0.0);
  }
  // The bag's /tf_static is the calibration the pipeline is given.
  rosbag::Bag bag(dir_ + "/c/drive.bag");
  int checked = 0;
  for (const rosbag::MessageInstance& m : rosbag::View(bag, rosbag::TopicQuery("/tf_static"))) {
    const auto msg = m.instantiate<tf2_msgs::TFMessage>();
    ASSERT_TRUE(msg);
    for (const auto& t : msg->transforms) {
      for (size_t c = 0; c < given.cameras.size(); ++c) {
        if (given.cameras[c].frame_id != t.child_frame_id) continue;
        EXPECT_TRUE(tf2::transformToEigen(t).isApprox(given.cameras[c].T_base_cam, 1e-6)) << t.child_frame_id;
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, static_cast<int>(given.cameras.size()));
  // Without a calibration error there is no truth file to confuse.
  ASSERT_EQ(makeDrive("--out " + dir_ + "/c" + kRigArgs + " --duration 0.2").status, 0);
  EXPECT_FALSE(std::ifstream(dir_ + "/c/camchain_true.yaml").good());
}

// The sensor model on the flat world: response, noise and blur as specified.
class SensorModelTest : public ::testing::Test {
 protected:
  SensorModelTest() : world_(config()), camera_(camera()), rays_(fm::pixelRays(camera_)) {}
  static fm::synth::WorldConfig config() {
    fm::synth::WorldConfig c;
    c.preset = "flat";
    c.route_length = 60;
    c.asphalt_grain = 0.3;
    return c;
  }
  static fm::CameraModel camera() {
    fm::Intrinsics k;
    k.fx = k.fy = 200;
    k.cx = 159.5;
    k.cy = 119.5;
    k.width = 320;
    k.height = 240;
    return fm::CameraModel::pinhole(k);
  }
  // Looking down at the ground from 1.5 m: every pixel sees asphalt, with
  // grain at the pixel scale (7.5 mm footprint).
  cv::Mat render(const fm::synth::SensorModel& s, uint64_t seed = 1) const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(3, 1.5, 1.5);
    cv::Mat img;
    world_.render(camera_, rays_, T, 0.0, seed, s).image.convertTo(img, CV_64F);
    return img;
  }
  fm::synth::World world_;
  fm::CameraModel camera_;
  std::vector<Eigen::Vector3f> rays_;
};

TEST_F(SensorModelTest, ResponseNoiseAndBlurAreTheSpecifiedOnes) {
  fm::synth::SensorModel clean;
  clean.read_noise = 0;
  clean.vignetting = 0;
  const cv::Mat base = render(clean);
  const double mean = cv::mean(base)[0];
  ASSERT_GT(mean, 20);
  ASSERT_LT(mean, 150);
  fm::synth::SensorModel s = clean;
  s.gain = 1.2;
  s.offset = 10;
  EXPECT_NEAR(cv::mean(render(s))[0], 1.2 * mean + 10, 0.6);  // quantization: +-0.5 DN
  s = clean;
  s.gamma = 1.25;  // DN = 255 (I)^1.25 per pixel
  cv::Mat expected;
  cv::pow(base / 255.0, 1.25, expected);
  EXPECT_NEAR(cv::mean(render(s))[0], cv::mean(expected * 255.0)[0], 0.6);
  // Read noise: two seeds differ by sqrt(2) sigma.
  s = clean;
  s.read_noise = 3;
  cv::Scalar m, sd;
  cv::meanStdDev(render(s, 1) - render(s, 2), m, sd);
  EXPECT_NEAR(sd[0], std::sqrt(2.0) * 3, 0.15);
  // Shot noise: variance = read^2 + k * signal.
  s.shot_noise = 0.5;
  cv::meanStdDev(render(s, 1) - render(s, 2), m, sd);
  EXPECT_NEAR(sd[0], std::sqrt(2.0 * (9 + 0.5 * mean)), 0.05 * sd[0]);
  // Blur lowers the grain's fine detail (the Laplacian's energy).
  s = clean;
  s.blur_px = 1.5;
  cv::Mat lap_sharp, lap_blur;
  cv::Laplacian(base, lap_sharp, CV_64F);
  cv::Laplacian(render(s), lap_blur, CV_64F);
  ASSERT_GT(cv::norm(lap_sharp), 2000.0);  // the grain is in view
  EXPECT_LT(cv::norm(lap_blur), 0.5 * cv::norm(lap_sharp));
  // Vignetting: the corner darker than the centre by the model's factor.
  s = clean;
  s.vignetting = 0.4;
  const cv::Mat v = render(s);
  const double ratio = cv::mean(v(cv::Rect(0, 0, 20, 20)))[0] / cv::mean(base(cv::Rect(0, 0, 20, 20)))[0];
  Eigen::Vector3d corner;
  ASSERT_TRUE(camera_.unproject(Eigen::Vector2d(10, 10), &corner));
  const double off = std::acos(corner.normalized().z()) / M_PI_2;
  EXPECT_NEAR(ratio, 1.0 - 0.4 * off * off, 0.02);
  // Per-camera spread: camera i from (seed, i), within the spread.
  fm::synth::SensorSpread spread;
  spread.gain = 0.2;
  spread.offset = 4;
  spread.gamma = 0.1;
  const auto sensors = fm::synth::drawSensors(spread, 50, 3);
  bool differ = false;
  for (const auto& c : sensors) {
    EXPECT_LE(std::abs(c.gain - 1.0), 0.2);
    EXPECT_LE(std::abs(c.offset), 4.0);
    EXPECT_LE(std::abs(c.gamma - 1.0), 0.1);
    differ |= std::abs(c.gain - sensors[0].gain) > 0.01;
  }
  EXPECT_TRUE(differ);
  EXPECT_EQ(fm::synth::drawSensors(spread, 2, 3)[1].gain, sensors[1].gain);
  fm::synth::SensorModel bad;
  bad.gain = -1;
  EXPECT_THROW(render(bad), std::invalid_argument);
}

}  // namespace
