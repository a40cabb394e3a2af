// rostest: the Tsdf node's life cycle, with the node in its own process
// (started, signalled and respawned here): SIGTERM saves the map like SIGINT
// and a restart with ~reload_map_on_start resumes it bit for bit; a respawn
// after kill -9 never writes an empty map over the saved one; autosave keeps
// the previous file as .1; swap files deleted under a running node lose their
// blocks (reported in /diagnostics) but never the process; a depth stamp far
// in the past (bag replayed) keeps the map and fusing goes on (or, with
// ~clear_map_on_time_reset, starts a new map).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <tuple>

#include <cv_bridge/cv_bridge.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <tf2_eigen/tf2_eigen.h>

#include "fisheye_mapping/FilePath.h"
#include "fisheye_mapping/FrameDone.h"
#include "fisheye_mapping/core/sim/analytic_scene.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "ros_test_utils.h"

namespace fm = fisheye_mapping;
namespace fs = std::filesystem;

namespace {

using fisheye_mapping::test::waitFor;

fm::analytic::Scene scene() {
  fm::analytic::Scene s;
  s.ground_extent = 8.0;
  s.spheres.push_back({Eigen::Vector3d(3.0, 0.9, 0.7), 0.7});
  s.boxes.push_back({Eigen::Vector3d(2.2, -1.6, 0.0), Eigen::Vector3d(3.6, -0.4, 0.8)});
  return s;
}

// Camera pose i of an orbit of n views around the objects.
Eigen::Isometry3d orbitPose(int i, int n) {
  const double a = 2 * M_PI * i / n;
  return fm::analytic::lookAt(Eigen::Vector3d(3 + 4.5 * std::cos(a), 4.5 * std::sin(a), 2.5),
                              Eigen::Vector3d(3, 0, 0.3));
}

std::string readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// The map in a file, block by block (loaded through the core's checks).
std::map<std::tuple<int, int, int>, fm::VoxelBlock> loadBlocks(const std::string& path) {
  fm::TsdfMap map;  // the node's voxel size and truncation (defaults)
  map.load(path);
  std::map<std::tuple<int, int, int>, fm::VoxelBlock> out;
  for (const auto& b : map.allBlocks()) out[{b.x(), b.y(), b.z()}] = *map.block(b);
  return out;
}

::testing::AssertionResult sameMap(const std::string& a, const std::string& b) {
  const auto ma = loadBlocks(a), mb = loadBlocks(b);
  if (ma.size() != mb.size()) return ::testing::AssertionFailure() << ma.size() << " vs " << mb.size() << " blocks";
  for (const auto& kv : ma) {
    auto it = mb.find(kv.first);
    if (it == mb.end()) return ::testing::AssertionFailure() << "a block of " << a << " is missing in " << b;
    if (std::memcmp(kv.second.voxels.data(), it->second.voxels.data(), sizeof(kv.second.voxels)) != 0) {
      return ::testing::AssertionFailure() << "a block differs";
    }
  }
  return ::testing::AssertionSuccess();
}

// One Tsdf in its own process (`nodelet standalone`), named `name`,
// its topics prefixed with the name.
// Its ~save_directory (the test's folder; set by the fixture): the
// shutdown/autosave and service paths below lie in it.
std::string g_save_directory;

class FusionProcess {
 public:
  FusionProcess(const std::string& name, const std::map<std::string, XmlRpc::XmlRpcValue>& params) : name_(name) {
    const std::string data = ros::package::getPath("fisheye_mapping") + "/test/data/";
    ros::param::del("/" + name);
    ros::param::set("/" + name + "/camchain", data + "small_fisheye_camchain.yaml");
    ros::param::set("/" + name + "/mount", data + "small_fisheye_mount.yaml");
    ros::param::set("/" + name + "/publish_period", 0.2);
    ros::param::set("/" + name + "/save_directory", g_save_directory);
    for (const auto& kv : params) ros::param::set("/" + name + "/" + kv.first, kv.second);
    const std::vector<std::string> args = {"rosrun", "nodelet", "nodelet", "standalone", "fisheye_mapping/Tsdf",
                                           "__name:=" + name, "depth_masked/image:=/" + name + "/depth_in",
                                           "tsdf/fusion_done:=/" + name + "/done", "tsdf/mesh:=/" + name + "/mesh",
                                           "tsdf/cloud:=/" + name + "/cloud"};
    pid_ = fork();
    if (pid_ == 0) {
      std::vector<char*> argv;
      for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execvp(argv[0], argv.data());
      _exit(127);
    }
  }
  ~FusionProcess() {
    if (running()) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  bool running() {
    if (pid_ <= 0 || exited_) return false;
    int st;
    if (waitpid(pid_, &st, WNOHANG) == pid_) {
      exited_ = true;
      status_ = st;
      return false;
    }
    return true;
  }
  bool waitReady(double seconds) {
    return ros::service::waitForService("/" + name_ + "/save_map", ros::Duration(seconds));
  }
  // Sends `sig`; the wait status once the process has ended (-1 if it did not
  // within `seconds`).
  int signal(int sig, double seconds) {
    if (!running()) return status_;
    kill(pid_, sig);
    waitFor([this] { return !running(); }, seconds);
    return exited_ ? status_ : -1;
  }
  const std::string& name() const { return name_; }

 private:
  std::string name_;
  pid_t pid_ = -1;
  bool exited_ = false;
  int status_ = -1;
};

bool cleanExit(int status) { return status >= 0 && WIFEXITED(status) && WEXITSTATUS(status) == 0; }

class TsdfLifecycle : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string data = ros::package::getPath("fisheye_mapping") + "/test/data/";
    rig_ = fm::loadKalibrRig(data + "small_fisheye_camchain.yaml", data + "small_fisheye_mount.yaml");
    char tmpl[] = "/tmp/fm_tsdf_lifecycle_XXXXXX";
    dir_ = mkdtemp(tmpl);
    g_save_directory = dir_;
    spinner_.start();
    diag_sub_ = nh_.subscribe<diagnostic_msgs::DiagnosticArray>(
        "/diagnostics", 50, boost::function<void(const diagnostic_msgs::DiagnosticArrayConstPtr&)>([this](const auto& m) {
          std::lock_guard<std::mutex> lock(diag_mutex_);
          for (const auto& s : m->status) {
            for (const auto& kv : s.values) diag_[s.name + "|" + kv.key] = kv.value;
          }
        }));
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Connects to a node's topics.
  void attach(const FusionProcess& node) {
    done_ = fused_ = 0;
    depth_pub_ = nh_.advertise<sensor_msgs::Image>("/" + node.name() + "/depth_in", 50);
    done_sub_ = nh_.subscribe<fisheye_mapping::FrameDone>(
        "/" + node.name() + "/done", 100,
        boost::function<void(const fisheye_mapping::FrameDoneConstPtr&)>([this](const auto& m) {
          ++done_;
          fused_ += m->fused;
        }));
    ASSERT_TRUE(waitFor([this] {
      return depth_pub_.getNumSubscribers() > 0 && done_sub_.getNumPublishers() > 0 && tf_.getNumSubscribers() > 0;
    }, 30.0)) << node.name() << " never connected";
  }

  // Plays views [from, to) of an n-view orbit at stamps t0 + 0.1 s * i and
  // waits until the node has finished with all of them.
  void play(int from, int to, int n, const ros::Time& t0) {
    const int before = done_;
    const fm::RigCamera& cam = rig_.cameras[0];
    for (int i = from; i < to; ++i) {
      const Eigen::Isometry3d T_W_C = orbitPose(i, n);
      const ros::Time stamp = t0 + ros::Duration(0.1 * i);
      geometry_msgs::TransformStamped t = tf2::eigenToTransform(T_W_C * cam.T_base_cam.inverse());
      t.header.stamp = stamp;
      t.header.frame_id = "map";
      t.child_frame_id = "base_link";
      tf_.sendTransform(t);
      cv_bridge::CvImage img;
      img.header.stamp = stamp;
      img.header.frame_id = cam.frame_id;
      img.encoding = "32FC1";
      img.image = scene().render(cam.model, T_W_C);
      depth_pub_.publish(img.toImageMsg());
      ros::WallDuration(0.08).sleep();
    }
    EXPECT_TRUE(waitFor([&] { return done_ >= before + (to - from); }, 30.0))
        << "the node finished " << done_ - before << " of " << to - from << " frames";
  }

  bool callSave(const std::string& node, const std::string& path, std::string* message = nullptr) {
    fisheye_mapping::FilePath srv;
    srv.request.path = path;
    if (!ros::service::call("/" + node + "/save_map", srv)) return false;
    if (message) *message = srv.response.message;
    return srv.response.success;
  }

  // A numeric value the node reported in /diagnostics (-1 if none yet).
  double diagValue(const std::string& node, const std::string& key) {
    std::lock_guard<std::mutex> lock(diag_mutex_);
    for (const auto& kv : diag_) {
      if (kv.first.find(node) != std::string::npos && kv.first.size() > key.size() &&
          kv.first.compare(kv.first.size() - key.size(), key.size(), key) == 0) {
        return std::stod(kv.second);
      }
    }
    return -1;
  }

  ros::NodeHandle nh_;
  ros::AsyncSpinner spinner_{2};
  fisheye_mapping::test::TfPublisher tf_;
  ros::Publisher depth_pub_;
  ros::Subscriber done_sub_, diag_sub_;
  std::atomic<int> done_{0}, fused_{0};
  std::mutex diag_mutex_;
  std::map<std::string, std::string> diag_;
  fm::Rig rig_;
  std::string dir_;
};

XmlRpc::XmlRpcValue vec3(double x, double y, double z) {
  XmlRpc::XmlRpcValue v;
  v.setSize(3);
  v[0] = x, v[1] = y, v[2] = z;
  return v;
}

TEST_F(TsdfLifecycle, SigtermSavesTheMapAndARestartResumesIt) {
  const std::string path = dir_ + "/map.fmtsdf";
  const std::map<std::string, XmlRpc::XmlRpcValue> params = {
      {"save_map_on_shutdown", XmlRpc::XmlRpcValue(path)},
      {"reload_map_on_start", XmlRpc::XmlRpcValue(true)},
      {"local_map_size", vec3(60, 60, 20)}};
  {
    FusionProcess node("tsdf_term", params);
    ASSERT_TRUE(node.waitReady(30.0));
    attach(node);
    play(0, 8, 16, ros::Time::now());
    EXPECT_EQ(fused_, 8);
    ASSERT_TRUE(callSave("tsdf_term", dir_ + "/reference.fmtsdf"));
    const int status = node.signal(SIGTERM, 30.0);
    EXPECT_TRUE(cleanExit(status)) << "SIGTERM did not shut the node down cleanly (wait status " << status << ")";
  }
  ASSERT_TRUE(fs::exists(path)) << "SIGTERM saved no map";
  EXPECT_FALSE(fs::exists(path + ".tmp"));
  EXPECT_GT(loadBlocks(path).size(), 100u);
  EXPECT_TRUE(sameMap(path, dir_ + "/reference.fmtsdf"));
  const std::string first = readBytes(path);

  // Restarted with ~reload_map_on_start, it resumes from that file, fuses on,
  // and its shutdown save keeps the first file as .1.
  {
    FusionProcess node("tsdf_term", params);
    ASSERT_TRUE(node.waitReady(30.0));
    ASSERT_TRUE(callSave("tsdf_term", dir_ + "/resumed.fmtsdf"));
    EXPECT_TRUE(sameMap(dir_ + "/resumed.fmtsdf", dir_ + "/reference.fmtsdf"));
    attach(node);
    play(8, 12, 16, ros::Time::now());
    EXPECT_EQ(fused_, 4);
    EXPECT_TRUE(cleanExit(node.signal(SIGTERM, 30.0)));
  }
  EXPECT_EQ(readBytes(path + ".1"), first);
  EXPECT_GT(loadBlocks(path).size(), loadBlocks(path + ".1").size());
}

TEST_F(TsdfLifecycle, RespawnAfterKillNeverReplacesTheSavedMapByAnEmptyOne) {
  const std::string path = dir_ + "/map.fmtsdf";
  const std::map<std::string, XmlRpc::XmlRpcValue> params = {{"save_map_on_shutdown", XmlRpc::XmlRpcValue(path)},
                                                             {"autosave_period", XmlRpc::XmlRpcValue(0.5)},
                                                             {"local_map_size", vec3(60, 60, 20)}};
  // A first run fuses and autosaves, then dies by kill -9.
  {
    FusionProcess node("tsdf_respawn", params);
    ASSERT_TRUE(node.waitReady(30.0));
    attach(node);
    play(0, 6, 16, ros::Time::now());
    ASSERT_TRUE(waitFor([&] { return fs::exists(path); }, 10.0)) << "no autosave";
    ros::WallDuration(1.0).sleep();  // the last frames' autosave
    const int status = node.signal(SIGKILL, 10.0);
    EXPECT_TRUE(WIFSIGNALED(status));
  }
  ASSERT_TRUE(fs::exists(path));
  EXPECT_FALSE(fs::exists(path + ".tmp"));
  const std::string saved = readBytes(path);
  const size_t blocks = loadBlocks(path).size();
  EXPECT_GT(blocks, 100u);

  // Respawned (no ~reload_map_on_start): it starts empty, and neither its
  // autosave nor its shutdown save replaces the file by an empty map.
  {
    FusionProcess node("tsdf_respawn", params);
    ASSERT_TRUE(node.waitReady(30.0));
    ros::WallDuration(1.2).sleep();  // two autosave periods
    EXPECT_TRUE(cleanExit(node.signal(SIGTERM, 30.0)));
  }
  EXPECT_EQ(readBytes(path), saved) << "the saved map was overwritten";
  EXPECT_FALSE(fs::exists(path + ".1"));
  EXPECT_FALSE(fs::exists(path + ".tmp"));

  // Respawned again, it fuses something new: its first save keeps the old
  // map as .1.
  {
    FusionProcess node("tsdf_respawn", params);
    ASSERT_TRUE(node.waitReady(30.0));
    attach(node);
    play(8, 10, 16, ros::Time::now());
    EXPECT_TRUE(cleanExit(node.signal(SIGTERM, 30.0)));
  }
  EXPECT_EQ(readBytes(path + ".1"), saved);
  EXPECT_GT(loadBlocks(path).size(), 0u);
}

TEST_F(TsdfLifecycle, DeletedSwapFilesDoNotAbortTheNode) {
  const std::string swap = dir_ + "/swap";
  FusionProcess node("tsdf_swap", {{"swap_directory", XmlRpc::XmlRpcValue(swap)},
                                   {"local_map_size", vec3(5, 5, 20)}});
  ASSERT_TRUE(node.waitReady(30.0));
  attach(node);
  const ros::Time t0 = ros::Time::now();
  play(0, 16, 16, t0);  // once around: blocks leave the 5 m local map
  size_t files = 0;
  for (const auto& e : fs::directory_iterator(swap)) files += fs::remove(e.path());
  ASSERT_GT(files, 0u) << "nothing was swapped out";
  // Around again: the blocks coming back are gone.
  play(16, 32, 16, t0);
  ASSERT_TRUE(node.running()) << "the node died";
  std::string message;
  EXPECT_TRUE(callSave("tsdf_swap", dir_ + "/after.fmtsdf", &message)) << message;
  EXPECT_GT(loadBlocks(dir_ + "/after.fmtsdf").size(), 0u);
  EXPECT_TRUE(waitFor([&] { return diagValue("tsdf_swap", "lost swapped blocks") > 0; }, 5.0))
      << "no lost blocks in /diagnostics";
  EXPECT_EQ(diagValue("tsdf_swap", "exceptions in depth callbacks"), 0);
  std::cout << files << " swap files deleted; the node reports " << diagValue("tsdf_swap", "lost swapped blocks")
            << " lost blocks\n";

  // The swap directory replaced by a plain file: blocks stay in RAM.
  fs::remove_all(swap);
  std::ofstream(swap) << "not a directory";
  play(32, 40, 16, t0);
  ASSERT_TRUE(node.running());
  EXPECT_TRUE(waitFor([&] { return diagValue("tsdf_swap", "swap write failures") > 0; }, 5.0));
  EXPECT_TRUE(callSave("tsdf_swap", dir_ + "/after2.fmtsdf", &message)) << message;

  // A bag played again from the start (stamps 4 s back): the map is kept and
  // fusing resumes after the reset.
  // Blocks swapped out before the swap folder went away come back lost on
  // the way round again; nothing else may go.
  const double blocks_before = diagValue("tsdf_swap", "blocks");
  const double lost_before = diagValue("tsdf_swap", "lost swapped blocks");
  play(0, 4, 16, t0);
  play(4, 8, 16, t0);
  EXPECT_TRUE(waitFor([&] { return diagValue("tsdf_swap", "time resets") == 1; }, 5.0));
  EXPECT_GE(diagValue("tsdf_swap", "blocks") + (diagValue("tsdf_swap", "lost swapped blocks") - lost_before),
            blocks_before);
  EXPECT_GE(fused_, 32 + 8 + 4);  // all but the frames around the reset fused
  EXPECT_TRUE(cleanExit(node.signal(SIGTERM, 30.0)));
}

// save_map to a directory fails with a clear message, leaves nothing and is
// counted; with ~clear_map_on_time_reset a replayed bag starts a new map.
TEST_F(TsdfLifecycle, SaveToADirectoryFailsCleanlyAndTimeResetCanClear) {
  FusionProcess node("tsdf_dir", {{"clear_map_on_time_reset", XmlRpc::XmlRpcValue(true)},
                                  {"local_map_size", vec3(60, 60, 20)}});
  ASSERT_TRUE(node.waitReady(30.0));
  fs::create_directory(dir_ + "/sub");
  std::string message;
  EXPECT_FALSE(callSave("tsdf_dir", dir_ + "/sub", &message));
  // resolveOutputPath refuses it: "output path '<path>' (...) is an existing directory; ...".
  EXPECT_NE(message.find("existing directory"), std::string::npos) << message;
  EXPECT_NE(message.find(dir_ + "/sub"), std::string::npos) << message;
  std::vector<std::string> entries;
  for (const auto& e : fs::directory_iterator(dir_)) entries.push_back(e.path().filename().string());
  EXPECT_EQ(entries, std::vector<std::string>{"sub"});
  EXPECT_TRUE(fs::is_empty(dir_ + "/sub"));
  EXPECT_TRUE(waitFor([&] { return diagValue("tsdf_dir", "failed service requests") == 1; }, 5.0));

  attach(node);
  const ros::Time t0 = ros::Time::now();
  play(0, 4, 16, t0 + ros::Duration(10.0));
  EXPECT_EQ(fused_, 4);
  ASSERT_TRUE(waitFor([&] { return diagValue("tsdf_dir", "blocks") > 100; }, 5.0));
  play(0, 1, 16, t0);  // 10 s back: the map is cleared
  EXPECT_TRUE(waitFor([&] { return diagValue("tsdf_dir", "time resets") == 1 && diagValue("tsdf_dir", "blocks") == 0; },
                      5.0));
  play(1, 4, 16, t0);  // and a new one fused
  EXPECT_EQ(fused_, 4 + 3);
  EXPECT_TRUE(waitFor([&] { return diagValue("tsdf_dir", "blocks") > 100; }, 5.0));
  EXPECT_TRUE(cleanExit(node.signal(SIGINT, 30.0)));
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_tsdf_lifecycle_node");
  ros::NodeHandle nh;  // keeps the node up across the tests
  return RUN_ALL_TESTS();
}
