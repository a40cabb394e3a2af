// rostest of vehicle.launch's paced player as a ROS user meets it (issue 30,
// test/launch/player_launch.test). The node starts `roslaunch fisheye_mapping
// vehicle.launch` itself (on the rostest's master) with a small-rig drive and:
//  - a camchain the player cannot open (test/data/bad_camchain.yaml): the
//    player dies and, being required, ends the whole launch, naming the file;
//  - a drive whose stamps go backwards after its last frame set: the player
//    plays the drive, stops on the bad stamps, the launch ends and the TSDF
//    stage saves the map on its way down (~save_map_on_shutdown);
//  - rig_source:=camera_info with publish_camera_info:=true (the player
//    publishes the camchain's CameraInfo, as for the demo bag, which has
//    none): every frame set is fused; the drive played to its end does not
//    end the launch (the player holds the clock and the last pose), and the
//    held pose never gives TF_REPEATED_DATA in any stage's log.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <set>
#include <utility>
#include <sstream>
#include <string>

#include "ros_test_utils.h"

namespace {

using fisheye_mapping::test::waitFor;

const std::string kData = FM_TEST_DATA_DIR;
const std::string kRig = " camchain:=" + kData + "/small_rig_camchain.yaml mount:=" + kData + "/small_rig_mount.yaml";

pid_t spawn(const std::string& cmd) {
  const std::string shell = "exec " + cmd;  // built before fork(): no allocation in the child
  const pid_t pid = fork();
  if (pid == 0) {
    execl("/bin/sh", "sh", "-c", shell.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

// Waits up to `seconds` for `pid` to end; its exit status, or -1 if it still runs.
int waitExit(pid_t pid, double seconds) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(seconds);
  int st = 0;
  while (ros::WallTime::now() < end) {
    if (waitpid(pid, &st, WNOHANG) == pid) return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
    usleep(100000);
  }
  return -1;
}

// Ctrl-C: roslaunch shuts its nodes down.
int interrupt(pid_t pid) {
  kill(pid, SIGINT);
  int status = waitExit(pid, 40.0);
  if (status < 0) {
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
  }
  return status;
}

std::string readFile(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::size_t fileSize(const std::string& path) {
  struct stat st;
  return stat(path.c_str(), &st) == 0 ? std::size_t(st.st_size) : 0;
}

int count(const std::string& text, const std::string& what) {
  int n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// `key: <integer>` of the player's summary YAML; -1 when absent.
int summaryValue(const std::string& yaml, const std::string& key) {
  const std::size_t at = yaml.find(key + ": ");
  return at == std::string::npos ? -1 : std::atoi(yaml.c_str() + at + key.size() + 2);
}

class PlayerLaunch : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = "/tmp/fm_player_launch_" + std::to_string(getpid()) + "_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name();
    ASSERT_EQ(std::system(("rm -rf " + dir_ + " && mkdir -p " + dir_).c_str()), 0);
  }
  // The logs and drives stay for a look after a failure.
  void TearDown() override {
    if (!HasFailure()) std::system(("rm -rf " + dir_).c_str());
  }
  // A 1 s small-rig drive at 10 Hz (10 frame sets) in dir_/drive.
  void makeDrive() {
    const std::string make = std::string(FM_MAKE_DRIVE) + " --out " + dir_ + "/drive --camchain " + kData +
                             "/small_rig_camchain.yaml --mount " + kData +
                             "/small_rig_mount.yaml --preset urban --seed 7 --duration 1 --rate 10 > " + dir_ +
                             "/make_drive.log 2>&1";
    ASSERT_EQ(std::system(make.c_str()), 0) << make;
  }
  // test/data/ros_tools.yaml with `sync` and `tsdf` lines (YAML, indented)
  // added to its sync: and tsdf: sections.
  std::string config(const std::string& sync, const std::string& tsdf) {
    std::string text = readFile(kData + "/ros_tools.yaml");
    for (const auto& [section, lines] : {std::make_pair(std::string("\nsync:\n"), sync), {"\ntsdf:\n", tsdf}}) {
      const std::size_t at = text.find(section);
      if (at == std::string::npos) ADD_FAILURE() << "no" << section << "in ros_tools.yaml";
      else text.insert(at + section.size(), lines);
    }
    const std::string path = dir_ + "/config.yaml";
    std::ofstream(path) << text;
    return path;
  }
  std::string dir_;
};

}  // namespace

// The player cannot open the camchain: it dies at once, and the launch with it.
TEST_F(PlayerLaunch, APlayerThatDiesEndsTheLaunch) {
  const std::string bag = dir_ + "/drive.bag";
  std::ofstream(bag) << "";  // launch checks that it exists; the player stops at the camchain first
  const std::string log = dir_ + "/roslaunch.log";
  const std::string launch = "roslaunch fisheye_mapping vehicle.launch rviz:=false detector:=ground_truth bag:=" + bag +
                             " camchain:=" + kData + "/bad_camchain.yaml mount:=" + kData +
                             "/small_rig_mount.yaml > " + log + " 2>&1";
  const pid_t pid = spawn(launch);
  ASSERT_GT(pid, 0);
  const int status = waitExit(pid, 90.0);
  if (status < 0) interrupt(pid);
  const std::string out = readFile(log);
  ASSERT_GE(status, 0) << "roslaunch still runs 90 s after the player died: " << launch << "\n" << out;
  EXPECT_NE(out.find("paced_player: rig " + kData + "/bad_camchain.yaml"), std::string::npos) << out;
  EXPECT_NE(out.find("REQUIRED process [player"), std::string::npos) << out;
  EXPECT_NE(out.find("shutting down processing monitor"), std::string::npos) << out;
}

// The player dies in the middle of a launch (stamps going backwards after
// the drive's 10 frame sets): the launch ends, the TSDF stage saves the map
// of the frame sets played.
TEST_F(PlayerLaunch, APlayerThatStopsOnBadInputEndsTheLaunchAndTheMapIsSaved) {
  makeDrive();
  // The drive, then cam0's first image again 0.5 s later in bag time: its
  // stamp goes back.
  const std::string bag = dir_ + "/backwards.bag";
  {
    rosbag::Bag in(dir_ + "/drive/drive.bag", rosbag::bagmode::Read), out(bag, rosbag::bagmode::Write);
    rosbag::View view(in);
    const ros::Time end = view.getEndTime();
    bool appended = false;
    for (const rosbag::MessageInstance& m : view) out.write(m.getTopic(), m.getTime(), m, m.getConnectionHeader());
    for (const rosbag::MessageInstance& m : view) {
      if (m.getTopic() != "/cam0/image_raw") continue;
      out.write(m.getTopic(), end + ros::Duration(0.5), m, m.getConnectionHeader());
      appended = true;
      break;
    }
    ASSERT_TRUE(appended);
  }
  const std::string map = dir_ + "/map.tsdf", summary = dir_ + "/summary.yaml", log = dir_ + "/roslaunch.log";
  const std::string launch = "roslaunch fisheye_mapping vehicle.launch rviz:=false detector:=ground_truth bag:=" + bag +
                             kRig + " summary_file:=" + summary + " config:=" +
                             config("", "  save_directory: " + dir_ + "\n  save_map_on_shutdown: " + map + "\n") + " > " + log + " 2>&1";
  const pid_t pid = spawn(launch);
  ASSERT_GT(pid, 0);
  const int status = waitExit(pid, 150.0);
  if (status < 0) interrupt(pid);
  const std::string out = readFile(log);
  ASSERT_GE(status, 0) << "roslaunch still runs 150 s after it started: " << launch << "\n" << out;
  EXPECT_NE(out.find("stamps go backwards on /cam0/image_raw"), std::string::npos) << out;
  EXPECT_NE(out.find("REQUIRED process [player"), std::string::npos) << out;
  const std::string yaml = readFile(summary);
  EXPECT_NE(yaml.find("played: 10\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("fused: 10\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("stopped_on_bad_input: true\n"), std::string::npos) << yaml;
  EXPECT_GT(fileSize(map), 1000u) << "no map saved at " << map << " when the launch ended:\n" << out;
}

// rig_source:=camera_info with the player publishing the camchain's
// CameraInfo: the drive is fused; the launch goes on holding after it.
TEST_F(PlayerLaunch, CameraInfoFromThePlayerGivesTheRigAndTheHeldPoseNeverRepeats) {
  makeDrive();
  const std::string summary = dir_ + "/summary.yaml", log = dir_ + "/roslaunch.log";
  const std::string launch =
      "roslaunch fisheye_mapping vehicle.launch rviz:=false detector:=ground_truth bag:=" + dir_ + "/drive/drive.bag" +
      kRig + " rig_source:=camera_info publish_camera_info:=true summary_file:=" + summary + " config:=" +
      config("  image_topics: [/cam0/image_raw, /cam1/image_raw, /cam2/image_raw]\n", "") + " > " + log + " 2>&1";
  const pid_t pid = spawn(launch);
  ASSERT_GT(pid, 0);
  const bool played = waitFor([&] { return fileSize(summary) > 0; }, 150.0);
  std::string out = readFile(log);
  if (!played) interrupt(pid);
  ASSERT_TRUE(played) << "the player wrote no summary within 150 s: " << launch << "\n" << out;
  const std::string yaml = readFile(summary);
  // Every frame set through the pipeline (none timed out: the player's
  // CameraInfo before the drive gave the sync its rig in time), every one
  // fused: a depth frame whose CameraInfo (depth_masked/camera_info,
  // republished by the mask stage) comes after it waits for it.
  EXPECT_NE(yaml.find("played: 10\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("timed_out: 0\n"), std::string::npos) << yaml << out;
  const int fused = summaryValue(yaml, "fused"), skipped = summaryValue(yaml, "skipped");
  EXPECT_EQ(fused, 10) << yaml << out;
  EXPECT_EQ(skipped, 0) << yaml;
  EXPECT_EQ(out.find("no camera_info for frame"), std::string::npos) << out;
  // Holding (clock and last pose): 4 s, 8 held poses; the launch keeps running.
  ros::WallDuration(4.0).sleep();
  EXPECT_LT(waitExit(pid, 0.1), 0) << "the launch ended after a drive played to its end";
  const int status = interrupt(pid);
  out = readFile(log);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("rig from the frame sets' camera_infos"), std::string::npos) << out;
  EXPECT_NE(out.find("holding the last pose of"), std::string::npos) << out;
  EXPECT_EQ(count(out, "TF_REPEATED_DATA"), 0) << out;
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_player_launch");
  return RUN_ALL_TESTS();
}
