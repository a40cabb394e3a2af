// Synthetic drives: ground-truth depth against analytic ray-plane
// intersections, cross-camera consistency, the vehicles (glass, wheels,
// lights, visible boxes under occlusion and at the image edge, YOLO labels),
// and the bags and training sets make_drive writes (contents, determinism,
// option errors), read back with rosbag.
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <random>
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
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"
#include "fisheye_mapping/core/sim/vehicle_labels.h"

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

// The overcast sky (make_drive --cloudy-sky) is as contrasted as the real
// overcast sky of shared/data/vcharge_fisheye (right sequence, 1280x800):
// there clean sky patches' 9x9 windows have a median standard deviation of
// 0.008-0.011 (image values in [0, 1], the same box filters; the sensor's
// noise there is 0.002, so this is the clouds'). Here, noiseless, in the
// default rig's forward camera (1024x544, a similar angular resolution):
// within a factor of 1.5 of 0.0095; the faint clouds of --realistic (0.06)
// stay well below it.
TEST(SyntheticWorld, OvercastSkyIsAsContrastedAsARealOne) {
  const fm::Rig rig = fm::loadKalibrRig(FM_CONFIG_DIR "/rig/default_camchain.yaml", FM_CONFIG_DIR "/rig/default_mount.yaml");
  const auto& cam = rig.cameras[0];
  auto skyWindowStd = [&](bool overcast, double clouds) {
    WorldConfig wc;
    wc.overcast = overcast;
    wc.clouds = clouds;
    const World world(wc);
    fm::synth::SensorModel exact;
    exact.read_noise = 0.0;  // the clouds' own contrast
    const std::vector<Eigen::Vector3f> rays = fm::pixelRays(cam.model);
    const auto f = world.render(cam.model, rays, world.egoPose(2.0) * cam.T_base_cam, 2.0, 7, exact);
    cv::Mat grey, mean, sq, sky = f.materials == 0;  // kSky, also outside the lens's domain
    for (int i = 0; i < sky.rows * sky.cols; ++i) {
      if (!rays[static_cast<size_t>(i)].allFinite()) sky.data[i] = 0;
    }
    f.image.convertTo(grey, CV_32F, 1.0 / 255);
    cv::boxFilter(grey, mean, CV_32F, cv::Size(9, 9));
    cv::boxFilter(grey.mul(grey), sq, CV_32F, cv::Size(9, 9));
    cv::erode(sky, sky, cv::Mat::ones(9, 9, CV_8UC1));  // windows wholly in the sky
    std::vector<float> s;
    for (int v = 0; v < grey.rows; ++v) {
      for (int u = 0; u < grey.cols; ++u) {
        if (sky.at<uint8_t>(v, u)) s.push_back(std::sqrt(std::max(0.0f, sq.at<float>(v, u) - mean.at<float>(v, u) * mean.at<float>(v, u))));
      }
    }
    EXPECT_GT(s.size(), 5000u);
    std::nth_element(s.begin(), s.begin() + s.size() / 2, s.end());
    return s.empty() ? 0.0f : s[s.size() / 2];
  };
  const float overcast = skyWindowStd(true, WorldConfig::kOvercastClouds), faint = skyWindowStd(false, 0.06);
  std::cout << "sky 9x9 window std, median: overcast " << overcast << ", faint clouds " << faint << " (real: 0.0095)\n";
  EXPECT_GT(overcast, 0.0095 / 1.5);
  EXPECT_LT(overcast, 0.0095 * 1.5);
  EXPECT_LT(faint, 0.0095 / 4);
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
      if (topic == "/cam0/detections_gt") det_stamps.push_back(dets->header.stamp);
      for (const auto& d : dets->detections) {
        // COCO names and ids of the vehicle kinds (a van is a COCO car).
        const std::map<std::string, int> coco = {{"car", 2}, {"bus", 5}, {"truck", 7}};
        ASSERT_TRUE(coco.count(d.class_name)) << d.class_name;
        EXPECT_EQ(d.class_id, coco.at(d.class_name));
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
  EXPECT_EQ(count["/cam0/vehicles_gt"], 5);
  EXPECT_EQ(count["/cam1/detections_gt"], 0);  // --gt-boxes ref
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
    for (int id = world.numVehicles(); id < world.numVehicleIds(); ++id) {  // parked vehicles
      const Eigen::Isometry3d T = world.vehiclePoseById(id, 0.0);
      if ((T.translation() - q).norm() > world.vehicleModel(id).radius() + 1) continue;
      dist = std::min(dist, std::abs(world.vehicleModel(id).distance(T.inverse() * q)));
    }
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

// --- Vehicles: built from more than boxes, with occlusion-aware visible boxes.

using fm::synth::VehicleDims;
using fm::synth::VehicleKind;
using fm::synth::VehicleModel;

fm::CameraModel pinhole480() {
  fm::Intrinsics k;
  k.fx = k.fy = 300;
  k.cx = 239.5;
  k.cy = 159.5;
  k.width = 480;
  k.height = 320;
  return fm::CameraModel::pinhole(k);
}

// A camera 1.5 m above the ground at the origin, looking along world +x.
Eigen::Isometry3d lookAlongX() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = Eigen::Vector3d(0, -1, 0);
  T.linear().col(1) = Eigen::Vector3d(0, 0, -1);
  T.linear().col(2) = Eigen::Vector3d(1, 0, 0);
  T.translation() = Eigen::Vector3d(0, 0, 1.5);
  return T;
}

Eigen::Isometry3d placed(double x, double y, double heading_deg) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(heading_deg * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, 0);
  return T;
}

WorldConfig emptyFlat() {
  WorldConfig wc;
  wc.preset = "flat";
  wc.moving_vehicles = 0;
  wc.route_length = 60;
  return wc;
}

VehicleDims dimsOf(VehicleKind kind, float paint) {
  VehicleDims d;
  d.kind = kind;
  d.paint = paint;
  switch (kind) {
    case VehicleKind::kCar: d.length = 4.5, d.width = 1.8, d.height = 1.45; break;
    case VehicleKind::kVan: d.length = 5.2, d.width = 2.0, d.height = 2.1; break;
    case VehicleKind::kTruck: d.length = 9.0, d.width = 2.5, d.height = 3.5; break;
    case VehicleKind::kBus: d.length = 11.5, d.width = 2.5, d.height = 3.1; break;
  }
  return d;
}

// The extent of the vehicle's projected vertices, as the pixel box of the
// pixel centres inside it (pixel u's centre at u; box [x, x + width)).
cv::Rect2d projectedBox(const fm::CameraModel& cam, const Eigen::Isometry3d& T_W_C, const VehicleModel& m,
                        const Eigen::Isometry3d& T_W_V) {
  double u0 = 1e9, v0 = 1e9, u1 = -1e9, v1 = -1e9;
  for (const auto& tri : m.triangles()) {
    for (const auto& p : tri) {
      Eigen::Vector2d uv;
      if (!cam.project(T_W_C.inverse() * (T_W_V * p), &uv)) continue;
      u0 = std::min(u0, uv.x()), u1 = std::max(u1, uv.x()), v0 = std::min(v0, uv.y()), v1 = std::max(v1, uv.y());
    }
  }
  return cv::Rect2d(std::ceil(u0), std::ceil(v0), std::floor(u1) + 1 - std::ceil(u0), std::floor(v1) + 1 - std::ceil(v0));
}

TEST(Vehicles, EachKindShowsDarkGlassWheelsAndLightsAndItsDepthLiesOnItsSurface) {
  const fm::CameraModel cam = pinhole480();
  const auto rays = fm::pixelRays(cam);
  const Eigen::Isometry3d T_W_C = lookAlongX();
  const std::map<VehicleKind, double> distance = {
      {VehicleKind::kCar, 8}, {VehicleKind::kVan, 9}, {VehicleKind::kTruck, 14}, {VehicleKind::kBus, 17}};
  for (const auto& [kind, dist] : distance) {
    for (float paint : {0.3f, 0.85f}) {
      World world(emptyFlat());
      // Front three-quarter view: the front and the right side face the camera.
      const Eigen::Isometry3d T_W_V = placed(dist, 0, 215);
      const int id = world.addParkedVehicle(dimsOf(kind, paint), T_W_V);
      const VehicleModel& model = world.vehicleModel(id);
      const auto frame = world.render(cam, rays, T_W_C, 0.0, 1);
      const std::string what = std::string(fm::synth::kindName(kind)) + " paint " + std::to_string(paint);
      if (std::getenv("FM_SAVE_RENDERS")) cv::imwrite("/tmp/fm_vehicle_" + what.substr(0, what.find(' ')) + ".png", frame.image);
      double sum[2] = {0, 0};
      int n[2] = {0, 0}, lamps = 0;
      for (int v = 0; v < cam.height(); ++v) {
        for (int u = 0; u < cam.width(); ++u) {
          if (frame.ids.at<int16_t>(v, u) != id) continue;
          const uint8_t m = frame.materials.at<uint8_t>(v, u), g = frame.image.at<uint8_t>(v, u);
          if (m == fm::synth::kGlass || m == fm::synth::kCarPaint) sum[m == fm::synth::kGlass] += g, ++n[m == fm::synth::kGlass];
          lamps += m == fm::synth::kLight && g > 200;
          // Ground-truth depth: the point lies on the vehicle's surface.
          const Eigen::Vector3d X = T_W_C * (frame.depth.at<float>(v, u) * rays[v * cam.width() + u].cast<double>());
          ASSERT_NEAR(model.distance(T_W_V.inverse() * X), 0.0, 1e-4) << what << " pixel " << u << "," << v;
        }
      }
      ASSERT_GT(n[0], 300) << what;
      ASSERT_GT(n[1], 100) << what;
      const double body = sum[0] / n[0], glass = sum[1] / n[1];
      std::cout << what << ": body " << body << " (" << n[0] << " px), glass " << glass << " (" << n[1] << " px), "
                << lamps << " lit head light pixels\n";
      EXPECT_LT(glass, 0.8 * body) << what;
      EXPECT_GE(lamps, 4) << what;
      // Wheels on the visible (right, -y) side: a light hub at the centre of
      // the outer face, a dark tyre below it, near the ground.
      int wheels = 0;
      for (const Eigen::Vector3d& c : model.wheelCentres()) {
        if (c.y() > 0) continue;
        auto pixelAt = [&](const Eigen::Vector3d& local) {
          Eigen::Vector2d uv;
          EXPECT_TRUE(cam.project(T_W_C.inverse() * (T_W_V * local), &uv));
          return cv::Point(static_cast<int>(std::round(uv.x())), static_cast<int>(std::round(uv.y())));
        };
        const cv::Point hub = pixelAt(c), tyre = pixelAt(c - Eigen::Vector3d(0, 0, 0.82 * model.wheelRadius()));
        EXPECT_EQ(frame.ids.at<int16_t>(hub), id) << what;
        EXPECT_EQ(frame.materials.at<uint8_t>(hub), fm::synth::kHub) << what;
        EXPECT_EQ(frame.materials.at<uint8_t>(tyre), fm::synth::kTyre) << what;
        EXPECT_LT(frame.image.at<uint8_t>(tyre), 0.6 * body) << what;
        ++wheels;
      }
      EXPECT_EQ(wheels, kind == VehicleKind::kTruck ? 3 : 2) << what;  // a 9 m truck has two rear axles
    }
  }
}

TEST(Vehicles, VisibleBoxIsTheExtentOfTheIdPixels) {
  // By hand: id 0 at (u, v) = (2, 1), (5, 3), (3, 6) -> x 2..5, y 1..6; id 1 at
  // (9, 7) alone; id 2 has 2 pixels, fewer than asked for; id 7 is beyond num_ids.
  cv::Mat ids(8, 10, CV_16SC1, cv::Scalar(-1));
  ids.at<int16_t>(1, 2) = 0, ids.at<int16_t>(3, 5) = 0, ids.at<int16_t>(6, 3) = 0;
  ids.at<int16_t>(7, 9) = 1;
  ids.at<int16_t>(0, 0) = 2, ids.at<int16_t>(0, 1) = 2;
  ids.at<int16_t>(4, 4) = 7;
  const auto boxes = fm::synth::visibleBoxes(ids, 3, 1);
  ASSERT_EQ(boxes.size(), 3u);
  EXPECT_EQ(boxes[0].id, 0);
  EXPECT_EQ(boxes[0].box, cv::Rect(2, 1, 4, 6));
  EXPECT_EQ(boxes[0].pixels, 3);
  EXPECT_EQ(boxes[1].box, cv::Rect(9, 7, 1, 1));
  EXPECT_EQ(boxes[2].box, cv::Rect(0, 0, 2, 1));
  const auto big = fm::synth::visibleBoxes(ids, 3, 3);
  ASSERT_EQ(big.size(), 1u);
  EXPECT_EQ(big[0].id, 0);
  EXPECT_THROW(fm::synth::visibleBoxes(cv::Mat(2, 2, CV_8UC1), 3, 1), std::invalid_argument);
}

TEST(Vehicles, AnOccludedVehiclesBoxIsSmallerThanItsProjectedBox) {
  const fm::CameraModel cam = pinhole480();
  const auto rays = fm::pixelRays(cam);
  const Eigen::Isometry3d T_W_C = lookAlongX();
  const VehicleDims car = dimsOf(VehicleKind::kCar, 0.6f);
  const Eigen::Isometry3d far = placed(14, 0, 90), near = placed(9, 2.2, 90);  // broadside, near one to the left
  World alone(emptyFlat()), both(emptyFlat());
  const int id = alone.addParkedVehicle(car, far);
  ASSERT_EQ(both.addParkedVehicle(car, far), id);
  both.addParkedVehicle(car, near);
  const cv::Rect2d projected = projectedBox(cam, T_W_C, alone.vehicleModel(id), far);
  const auto seen_alone = fm::synth::visibleBoxes(alone.render(cam, rays, T_W_C, 0, 1).ids, alone.numVehicleIds(), 1);
  const auto seen_both = fm::synth::visibleBoxes(both.render(cam, rays, T_W_C, 0, 1).ids, both.numVehicleIds(), 1);
  ASSERT_EQ(seen_alone.size(), 1u);
  ASSERT_EQ(seen_both.size(), 2u);
  const cv::Rect a = seen_alone[0].box, b = seen_both[0].box;
  std::cout << "projected " << projected << ", seen alone " << a << ", behind the other car " << b << "\n";
  // Unoccluded, the visible box is the projected one (to the pixel); behind
  // the near car it loses its left part (the near car hides world +y).
  EXPECT_NEAR(a.x, projected.x, 1.0);
  EXPECT_NEAR(a.x + a.width, projected.x + projected.width, 1.0);
  EXPECT_NEAR(a.y, projected.y, 1.0);
  EXPECT_NEAR(a.y + a.height, projected.y + projected.height, 1.0);
  EXPECT_GT(b.x, projected.x + 20);
  EXPECT_LT(b.width, projected.width - 20);
  EXPECT_EQ(b.x + b.width, a.x + a.width);
  EXPECT_LT(seen_both[0].pixels, seen_alone[0].pixels);
}

TEST(Vehicles, AVehicleCutByTheImageEdgeHasABoxClippedToTheImage) {
  const fm::CameraModel cam = pinhole480();
  const auto rays = fm::pixelRays(cam);
  const Eigen::Isometry3d T_W_C = lookAlongX();
  World world(emptyFlat());
  const Eigen::Isometry3d T = placed(7, 5.5, 0);
  const int id = world.addParkedVehicle(dimsOf(VehicleKind::kVan, 0.6f), T);
  const cv::Rect2d projected = projectedBox(cam, T_W_C, world.vehicleModel(id), T);
  const auto seen = fm::synth::visibleBoxes(world.render(cam, rays, T_W_C, 0, 1).ids, world.numVehicleIds(), 1);
  ASSERT_EQ(seen.size(), 1u);
  std::cout << "projected " << projected << ", visible " << seen[0].box << "\n";
  EXPECT_LT(projected.x, -50);  // beyond the left edge
  EXPECT_EQ(seen[0].box.x, 0);
  EXPECT_NEAR(seen[0].box.x + seen[0].box.width, projected.x + projected.width, 1.0);
  EXPECT_LE(seen[0].box.y + seen[0].box.height, cam.height());
}

TEST(Vehicles, YoloLabelsRoundTripToThePixelBoxes) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  for (int i = 0; i < 1000; ++i) {
    const cv::Size image(64 + static_cast<int>(2000 * U(rng)), 64 + static_cast<int>(1000 * U(rng)));
    const int x = static_cast<int>(U(rng) * (image.width - 2)), y = static_cast<int>(U(rng) * (image.height - 2));
    const cv::Rect box(x, y, 1 + static_cast<int>(U(rng) * (image.width - x - 1)), 1 + static_cast<int>(U(rng) * (image.height - y - 1)));
    int cls = -1;
    cv::Rect2d back;
    fm::synth::parseYoloLine(fm::synth::yoloLine(i % 4, box, image), image, &cls, &back);
    ASSERT_EQ(cls, i % 4);
    ASSERT_NEAR(back.x, box.x, 0.5) << image;
    ASSERT_NEAR(back.y, box.y, 0.5) << image;
    ASSERT_NEAR(back.x + back.width, box.x + box.width, 0.5) << image;
    ASSERT_NEAR(back.y + back.height, box.y + box.height, 0.5) << image;
  }
  // By hand: a 100 x 50 box at (200, 100) in a 1000 x 500 image.
  EXPECT_EQ(fm::synth::yoloLine(3, cv::Rect(200, 100, 100, 50), cv::Size(1000, 500)), "3 0.2500000 0.2500000 0.100000 0.100000");
  // A box touching the image's edges stays inside it: cx -+ w / 2 in [0, 1].
  const std::string edge = fm::synth::yoloLine(0, cv::Rect(0, 0, 1023, 544), cv::Size(1023, 544));
  EXPECT_EQ(edge, "0 0.5000000 0.5000000 1.000000 1.000000");
  const std::string odd = fm::synth::yoloLine(0, cv::Rect(0, 3, 7, 533), cv::Size(1023, 544));
  int c;
  cv::Rect2d b;
  fm::synth::parseYoloLine(odd, cv::Size(1023, 544), &c, &b);
  std::istringstream fields(odd);
  double cls, cx, cy, w, h;
  fields >> cls >> cx >> cy >> w >> h;
  EXPECT_GE(cx - 0.5 * w, -1e-12) << odd;
  EXPECT_LE(cy + 0.5 * h, 1.0 + 1e-12) << odd;
  const struct {
    std::string line, expected;
  } bad[] = {{"1 0.5 0.5 0.1", "needs 5 fields"},
             {"1 0.5 x 0.1 0.1", "field 3 is not a number: 'x'"},
             {"1 0.5 1.5 0.1 0.1", "field 3 must lie in [0, 1], got 1.5"},
             {"-1 0.5 0.5 0.1 0.1", "class must be a whole number >= 0, got -1"}};
  for (const auto& b : bad) {
    int cls;
    cv::Rect2d box;
    try {
      fm::synth::parseYoloLine(b.line, cv::Size(100, 100), &cls, &box);
      ADD_FAILURE() << "accepted '" << b.line << "'";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(b.expected), std::string::npos) << e.what();
    }
  }
}

std::vector<std::string> lines(const std::string& path) {
  std::ifstream f(path);
  std::vector<std::string> out;
  for (std::string l; std::getline(f, l);) out.push_back(l);
  return out;
}

TEST_F(MakeDrive, DatasetHoldsImagesYoloLabelsAndClassesAndEveryCameraGetsBoxes) {
  const std::string ds = dir_ + "/ds";
  const ToolRun r = makeDrive("--out " + dir_ + "/d" + kRigArgs +
                              " --duration 1 --seed 3 --moving 12 --gt-boxes all --dataset " + ds + " --dataset-every 5");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(lines(ds + "/classes.txt"), (std::vector<std::string>{"car", "van", "truck", "bus"}));
  EXPECT_NE(readFile(ds + "/README.txt").find("preset urban, seed 3"), std::string::npos);
  // Frame sets 0 and 5 of 10, three cameras each.
  const std::vector<std::string> csv = lines(ds + "/boxes.csv");
  ASSERT_FALSE(csv.empty());
  std::map<std::string, std::vector<std::string>> csv_rows;
  for (size_t i = 1; i < csv.size(); ++i) csv_rows[csv[i].substr(0, csv[i].find(','))].push_back(csv[i]);
  int labels = 0;
  std::set<int> classes;
  for (int set : {0, 5}) {
    for (int c = 0; c < 3; ++c) {
      char name[64];
      std::snprintf(name, sizeof(name), "s3_f%05d_cam%d", set, c);
      const cv::Mat img = cv::imread(ds + "/images/" + name + ".png", cv::IMREAD_UNCHANGED);
      ASSERT_EQ(img.size(), cv::Size(256, 136)) << name;
      ASSERT_EQ(img.type(), CV_8UC1);
      const std::vector<std::string> rows = lines(ds + "/labels/" + name + ".txt");
      ASSERT_EQ(rows.size(), csv_rows[name].size()) << name;
      for (size_t i = 0; i < rows.size(); ++i) {
        // The label and the pixel box in boxes.csv agree within half a pixel.
        int cls;
        cv::Rect2d box;
        fm::synth::parseYoloLine(rows[i], img.size(), &cls, &box);
        std::stringstream ss(csv_rows[name][i]);
        std::vector<std::string> f;
        for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
        ASSERT_EQ(f.size(), 9u);
        EXPECT_EQ(lines(ds + "/classes.txt")[cls], f[2]);
        EXPECT_NEAR(box.x, std::stod(f[4]), 0.5);
        EXPECT_NEAR(box.y + box.height, std::stod(f[7]), 0.5);
        EXPECT_GE(box.width, 4 - 1e-3);  // --dataset-min-px 4, less the inward rounding
        EXPECT_GE(box.x, -1e-9);
        EXPECT_LE(box.x + box.width, 256 + 1e-9);
        classes.insert(cls);
        ++labels;
      }
    }
  }
  EXPECT_FALSE(std::ifstream(ds + "/images/s3_f00001_cam0.png").good());
  std::cout << labels << " labels, " << classes.size() << " classes\n";
  EXPECT_GT(labels, 10);
  EXPECT_GE(classes.size(), 2u);
  // --gt-boxes all: every camera has its boxes; moving ones are also among all vehicles.
  rosbag::Bag bag(dir_ + "/d/drive.bag");
  std::map<std::string, int> count;
  for (const auto& m : rosbag::View(bag)) {
    if (auto d = m.instantiate<fisheye_mapping::Detection2DArray>()) {
      ++count[m.getTopic()];
      for (const auto& b : d->detections) {
        EXPECT_GE(b.x_min, 0);
        EXPECT_LE(b.y_max, 136);
      }
    }
  }
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(count["/cam" + std::to_string(c) + "/detections_gt"], 10);
    EXPECT_EQ(count["/cam" + std::to_string(c) + "/vehicles_gt"], 10);
  }
}

TEST_F(MakeDrive, BadDatasetOptionsGiveClearErrors) {
  const ToolRun every = makeDrive("--out " + dir_ + "/x" + kRigArgs + " --dataset " + dir_ + "/ds --dataset-every 0");
  EXPECT_EQ(every.status, 2);
  EXPECT_NE(every.output.find("--dataset-every must lie in [1, 1000], got 0"), std::string::npos) << every.output;
  const ToolRun boxes = makeDrive("--out " + dir_ + "/x" + kRigArgs + " --gt-boxes some");
  EXPECT_EQ(boxes.status, 2);
  EXPECT_NE(boxes.output.find("--gt-boxes must be ref or all, got 'some'"), std::string::npos) << boxes.output;
}

}  // namespace
