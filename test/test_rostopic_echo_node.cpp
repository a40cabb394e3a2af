// rostest of issue 30's "rostopic echo -n1 works on every output topic"
// (test/launch/rostopic_echo.test): vehicle.launch (small rig, the NanoDet
// detector, so that detections and detections/image run too) and a short
// synthetic drive. Before the drive, this node starts one
// `rostopic echo -n1 --noarr` per output topic: the list below (every
// topic the nodelets advertise, src/nodelets/*.cpp) and whatever else is
// advertised under /fisheye_mapping (topics added later, dynamic_reconfigure,
// nodelet bonds), plus /diagnostics; and `rostopic hz` on three of them.
// Once every echo has subscribed it plays the drive with paced_player. Each
// echo must print one message and exit 0; the test names every topic that
// could not be echoed with rostopic's own words ("Cannot load message class
// for [sensor_msgs/Image]" when the Python messages are not installed, as
// scripts/debian-packages.txt now installs them) and every hz that printed
// no rate.
#include <gtest/gtest.h>
#include <ros/master.h>
#include <ros/ros.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "ros_test_utils.h"

namespace {

using fisheye_mapping::test::waitFor;

const std::string kNs = "/fisheye_mapping";

// Every output topic of the stages (their advertise() calls) that this
// launch must offer: a missing one fails the test too.
const std::vector<std::string> kOutputs = {
    "frames",                                        // Sync: fisheye_mapping/CameraFrameSet
    "depth/image", "depth/image_z", "depth/cost",    // Depth: sensor_msgs/Image
    "depth/camera_info",                             // sensor_msgs/CameraInfo
    "depth/self_calibration",                        // fisheye_mapping/RigSelfCalibration (latched)
    "detections",                                    // Detector: fisheye_mapping/Detection2DArray
    "detections/image",                              // sensor_msgs/Image
    "depth_masked/image", "depth_masked/mask", "depth_masked/colour",  // DepthMask: sensor_msgs/Image
    "depth_masked/camera_info",                      // sensor_msgs/CameraInfo
    "depth_masked/vehicles",                         // fisheye_mapping/TrackedVehicleArray
    "tsdf/mesh",                                     // Tsdf: visualization_msgs/MarkerArray
    "tsdf/cloud",                                    // sensor_msgs/PointCloud2 (latched)
    "tsdf/fusion_done",                              // fisheye_mapping/FrameDone
};

pid_t spawn(const std::string& cmd) {
  const std::string shell = "exec " + cmd;  // built before fork(): no allocation in the child
  const pid_t pid = fork();
  if (pid == 0) {
    setpgid(0, 0);  // its own group: a signal reaches the shell's child too
    execl("/bin/sh", "sh", "-c", shell.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  if (pid > 0) setpgid(pid, pid);  // also here: a kill(-pid) right after fork() finds the group
  return pid;
}

std::string readFile(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::string tail(const std::string& s, std::size_t n = 600) { return s.size() > n ? "..." + s.substr(s.size() - n) : s; }

// Topic -> the nodes subscribed to it (the master's getSystemState).
std::map<std::string, std::set<std::string>> subscribers() {
  std::map<std::string, std::set<std::string>> out;
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  if (!ros::master::execute("getSystemState", args, result, payload, true)) return out;
  XmlRpc::XmlRpcValue& subs = payload[1];
  for (int i = 0; i < subs.size(); ++i) {
    const std::string topic = subs[i][0];
    for (int k = 0; k < subs[i][1].size(); ++k) out[topic].insert(std::string(subs[i][1][k]));
  }
  return out;
}

// Advertised topic -> its type.
std::map<std::string, std::string> advertisedTypes() {
  ros::master::V_TopicInfo topics;
  std::map<std::string, std::string> out;
  if (ros::master::getTopics(topics)) {
    for (const auto& t : topics) out[t.name] = t.datatype;
  }
  return out;
}

std::set<std::string> advertised() {
  std::set<std::string> out;
  for (const auto& [name, type] : advertisedTypes()) out.insert(name);
  return out;
}

struct Probe {
  std::string topic, kind, log;  // kind: echo | hz
  pid_t pid = -1;
  int status = -1;  // exit status once it ended
  bool ended = false;
  bool stopped = false;  // still running at the end: stopped here
};

// Reaps a probe that has ended.
void poll(Probe& p) {
  if (p.ended) return;
  int st = 0;
  if (waitpid(p.pid, &st, WNOHANG) == p.pid) {
    p.ended = true;
    p.status = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
  }
}

void stop(Probe& p) {
  poll(p);
  if (p.ended) return;
  p.stopped = true;
  kill(-p.pid, SIGINT);
  for (int i = 0; i < 50 && !p.ended; ++i) {
    usleep(100000);
    poll(p);
  }
  if (!p.ended) {
    kill(-p.pid, SIGKILL);
    int st = 0;
    waitpid(p.pid, &st, 0);
    p.ended = true;
    p.status = 128 + SIGKILL;
  }
}

}  // namespace

TEST(RosTools, RostopicEchoAndHzWorkOnEveryOutputTopic) {
  const std::string dir = "/tmp/fm_rostopic_echo_" + std::to_string(getpid());
  const std::string log = dir + ".log";
  const std::string rig = std::string(" --camchain ") + FM_TEST_DATA_DIR + "/small_rig_camchain.yaml --mount " +
                          FM_TEST_DATA_DIR + "/small_rig_mount.yaml";
  const std::string make = std::string(FM_MAKE_DRIVE) + " --out " + dir + rig +
                           " --preset urban --seed 5 --moving 2 --duration 1 --rate 10 > " + log + " 2>&1";
  ASSERT_EQ(std::system(make.c_str()), 0) << make << " (log: " << log << ")";

  // Every output advertised (the nodelets advertise when they start).
  std::set<std::string> missing;
  const bool up = waitFor([&] {
    const std::set<std::string> topics = advertised();
    missing.clear();
    for (const auto& t : kOutputs) {
      if (!topics.count(kNs + "/" + t)) missing.insert(kNs + "/" + t);
    }
    if (!topics.count("/diagnostics")) missing.insert("/diagnostics");
    return missing.empty();
  }, 90.0);
  std::string missing_list;
  for (const auto& t : missing) missing_list += " " + t;
  ASSERT_TRUE(up) << "not advertised by vehicle.launch:" << missing_list;
  ros::WallDuration(2.0).sleep();  // a stage that advertises more a moment later

  std::set<std::string> topics = {"/diagnostics"};
  for (const auto& t : kOutputs) topics.insert(kNs + "/" + t);
  for (const auto& t : advertised()) {
    if (t.rfind(kNs + "/", 0) == 0) topics.insert(t);
  }
  std::vector<Probe> probes;
  int n = 0;
  for (const auto& t : topics) {
    Probe p;
    p.topic = t;
    p.kind = "echo";
    p.log = dir + "_echo_" + std::to_string(n++) + ".log";
    p.pid = spawn("rostopic echo -n1 --noarr " + t + " > " + p.log + " 2>&1");
    probes.push_back(p);
  }
  for (const std::string& t : std::vector<std::string>{"/diagnostics", kNs + "/depth/image", kNs + "/tsdf/fusion_done"}) {
    Probe p;
    p.topic = t;
    p.kind = "hz";
    p.log = dir + "_hz_" + std::to_string(n++) + ".log";
    p.pid = spawn("rostopic hz --wall-time " + t + " > " + p.log + " 2>&1");
    probes.push_back(p);
  }
  // Each probe subscribed (a rostopic node among the topic's subscribers) or
  // already ended (it could not even subscribe: reported below).
  std::string not_subscribed;
  const bool subscribed = waitFor([&] {
    const auto subs = subscribers();
    not_subscribed.clear();
    std::map<std::string, int> wanted, have;
    for (auto& p : probes) {
      poll(p);
      if (!p.ended) ++wanted[p.topic];
    }
    for (const auto& [topic, count] : wanted) {
      int k = 0;
      auto it = subs.find(topic);
      if (it != subs.end()) {
        for (const auto& node : it->second) k += node.rfind("/rostopic_", 0) == 0;
      }
      if (k < count) not_subscribed += " " + topic;
    }
    return not_subscribed.empty();
  }, 90.0);
  EXPECT_TRUE(subscribed) << "rostopic did not subscribe to" << not_subscribed;
  ros::WallDuration(1.0).sleep();

  // The drive, paced: every frame set through every stage.
  ros::param::set("/echo_player/bag", dir + "/drive.bag");
  ros::param::set("/echo_player/camchain", std::string(FM_TEST_DATA_DIR) + "/small_rig_camchain.yaml");
  ros::param::set("/echo_player/mount", std::string(FM_TEST_DATA_DIR) + "/small_rig_mount.yaml");
  ros::param::set("/echo_player/hold", false);
  ros::param::set("/echo_player/timeout", 60.0);
  ros::param::set("/echo_player/done_topic", kNs + "/tsdf/fusion_done");
  const std::string play = std::string(FM_PACED_PLAYER) + " __name:=echo_player >> " + log + " 2>&1";
  const int played = std::system(play.c_str());
  EXPECT_EQ(played, 0) << play << " (log: " << log << ")";

  // Each echo has its message by now or within a few seconds (mesh and cloud
  // come on the TSDF's publish timer).
  waitFor([&] {
    bool all = true;
    for (auto& p : probes) {
      poll(p);
      if (p.kind == "echo" && !p.ended) all = false;
    }
    return all;
  }, 20.0);
  for (auto& p : probes) stop(p);

  std::string failed;
  int echoed = 0;
  const std::map<std::string, std::string> types = advertisedTypes();
  for (const auto& p : probes) {
    const std::string out = readFile(p.log);
    bool ok = false;
    if (p.kind == "echo") {
      // rostopic echo prints the message (arrays hidden) and "---", then exits 0.
      ok = p.status == 0 && out.find("---") != std::string::npos && out.find("ERROR") == std::string::npos;
      if (ok) {
        ++echoed;
      } else {
        failed += "\n  rostopic echo -n1 " + p.topic + ": " +
                  (p.stopped ? std::string("no message by 20 s after the drive")
                             : "exit status " + std::to_string(p.status)) +
                  ": " + tail(out);
      }
    } else {
      // rostopic hz runs until stopped, printing "average rate: ..." once it has two messages.
      ok = out.find("average rate:") != std::string::npos && out.find("ERROR") == std::string::npos;
      if (!ok) failed += "\n  rostopic hz " + p.topic + ": no rate: " + tail(out);
    }
    std::printf("rostopic %s %s [%s]: %s\n", p.kind.c_str(), p.topic.c_str(),
                types.count(p.topic) ? types.at(p.topic).c_str() : "?", ok ? "ok" : "FAILED");
  }
  std::printf("rostopic echo -n1: %d of %zu topics echoed\n", echoed, topics.size());
  EXPECT_TRUE(failed.empty()) << "topics that a ROS user cannot echo or hz:" << failed << "\n(log: " << log << ")";
  EXPECT_GE(echoed, int(kOutputs.size()) + 1);
  if (failed.empty() && !HasFailure()) {
    std::system(("rm -rf " + dir + " " + dir + "_*.log " + log).c_str());
  }
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_rostopic_echo");
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
