// paced_player against a stand-in pipeline: this node subscribes to the
// cameras and acknowledges each reference image on /fusion_done after a
// delay (a slow machine), as the TSDF stage does. Checks that every frame set
// of a drive is played and none overlaps the previous one, and that bags
// without /tf, without a camera or with stamps going backwards are named and
// stop the player with exit status 1.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <sensor_msgs/Image.h>
#include <tf2_msgs/TFMessage.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <vector>

#include "fisheye_mapping/FrameDone.h"

namespace {

const std::string kCam0 = "/cam0/image_raw", kCam1 = "/cam1/image_raw";

sensor_msgs::Image image(double t, const std::string& frame) {
  sensor_msgs::Image m;
  m.header.stamp = ros::Time(t);
  m.header.frame_id = frame;
  m.height = m.width = 4;
  m.encoding = "mono8";
  m.step = 4;
  m.data.assign(16, 100);
  return m;
}

tf2_msgs::TFMessage pose(double t) {
  tf2_msgs::TFMessage m;
  geometry_msgs::TransformStamped p;
  p.header.stamp = ros::Time(t);
  p.header.frame_id = "map";
  p.child_frame_id = "base_link";
  p.transform.translation.x = t;
  p.transform.rotation.w = 1.0;
  m.transforms.push_back(p);
  return m;
}

// Writes a bag: frame sets at 1.0, 1.1, ... with a pose before each; cam1's
// stamps may be given (to make them go backwards).
std::string writeBag(const std::string& name, int sets, bool with_tf, bool with_cam1,
                     const std::vector<double>& cam1_stamps = {}) {
  const std::string path = "/tmp/fisheye_mapping_paced_" + std::to_string(getpid()) + "_" + name + ".bag";
  rosbag::Bag bag(path, rosbag::bagmode::Write);
  for (int k = 0; k < sets; ++k) {
    const double t = 1.0 + 0.1 * k;
    const ros::Time rt(t);
    if (with_tf) bag.write("/tf", rt, pose(t));
    bag.write(kCam0, rt, image(t, "cam0"));
    if (with_cam1) bag.write(kCam1, rt, image(cam1_stamps.empty() ? t : cam1_stamps[k], "cam1"));
  }
  bag.close();
  return path;
}

struct Pipeline {
  ros::NodeHandle nh;
  ros::Publisher done = nh.advertise<fisheye_mapping::FrameDone>("/fusion_done", 100);
  ros::Subscriber s0, s1;
  ros::WallTimer ack_timer;
  std::mutex mutex;
  std::vector<double> seen;  // reference stamps received
  std::vector<double> acked;
  int overlaps = 0;          // a new reference arrived before the last one was acknowledged

  Pipeline() {
    s0 = nh.subscribe<sensor_msgs::Image>(kCam0, 100, boost::function<void(const sensor_msgs::Image::ConstPtr&)>([this](const sensor_msgs::Image::ConstPtr& m) {
      std::lock_guard<std::mutex> lock(mutex);
      if (seen.size() > acked.size()) ++overlaps;
      seen.push_back(m->header.stamp.toSec());
      const std_msgs::Header header = m->header;
      // Acknowledge 0.3 s later: slower than the bag (0.1 s per frame set).
      ack_timer = nh.createWallTimer(
          ros::WallDuration(0.3),
          [this, header](const ros::WallTimerEvent&) {
            fisheye_mapping::FrameDone d;
            d.header = header;
            d.fused = true;
            {
              std::lock_guard<std::mutex> lock(mutex);
              acked.push_back(header.stamp.toSec());
            }
            done.publish(d);
          },
          true);
    }));
    s1 = nh.subscribe<sensor_msgs::Image>(
        kCam1, 100, boost::function<void(const sensor_msgs::Image::ConstPtr&)>([](const sensor_msgs::Image::ConstPtr&) {}));
  }
};

// Runs the player on `bag` under the node name `name`; returns its exit
// status and leaves its output in *log.
int runPlayer(const std::string& name, const std::string& bag, std::string* log, const std::string& summary = "") {
  ros::param::set("/" + name + "/bag", bag);
  ros::param::set("/" + name + "/image_topics", std::vector<std::string>{kCam0, kCam1});
  ros::param::set("/" + name + "/hold", false);
  ros::param::set("/" + name + "/timeout", 10.0);
  ros::param::set("/" + name + "/wait_subscribers", 20.0);
  if (!summary.empty()) ros::param::set("/" + name + "/summary_file", summary);
  const std::string out = "/tmp/fisheye_mapping_paced_" + std::to_string(getpid()) + "_" + name + ".log";
  const std::string cmd = std::string(FM_PACED_PLAYER) + " __name:=" + name + " > " + out + " 2>&1";
  const int status = std::system(cmd.c_str());
  std::ifstream f(out);
  std::stringstream ss;
  ss << f.rdbuf();
  *log = ss.str();
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string readFile(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

}  // namespace

TEST(PacedPlayer, EveryFrameSetIsPlayedAfterThePreviousOneIsFinished) {
  Pipeline pipeline;
  const std::string summary = "/tmp/fisheye_mapping_paced_" + std::to_string(getpid()) + "_summary.yaml";
  std::string log;
  const int status = runPlayer("player_good", writeBag("good", 6, true, true), &log, summary);
  ASSERT_EQ(status, 0) << log;
  std::lock_guard<std::mutex> lock(pipeline.mutex);
  EXPECT_EQ(pipeline.seen.size(), 6u) << log;
  EXPECT_EQ(pipeline.acked.size(), 6u);
  EXPECT_EQ(pipeline.overlaps, 0) << "a frame set was played before the previous one was finished";
  const std::string yaml = readFile(summary);
  EXPECT_NE(yaml.find("played: 6\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("fused: 6\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("timed_out: 0\n"), std::string::npos) << yaml;
}

TEST(PacedPlayer, BadBagsAreNamedAndStopThePlayer) {
  Pipeline pipeline;
  std::string log;
  EXPECT_EQ(runPlayer("player_no_tf", writeBag("no_tf", 3, false, true), &log), 1) << log;
  EXPECT_NE(log.find("has no /tf"), std::string::npos) << log;
  EXPECT_EQ(runPlayer("player_no_cam1", writeBag("no_cam1", 3, true, false), &log), 1) << log;
  EXPECT_NE(log.find("no messages on /cam1/image_raw"), std::string::npos) << log;
  EXPECT_EQ(runPlayer("player_missing_bag", "/nonexistent/drive.bag", &log), 1) << log;
  EXPECT_NE(log.find("cannot read the bag /nonexistent/drive.bag"), std::string::npos) << log;
  // cam1 goes back in time at the fourth frame set: the first three are still
  // played and finished, then the player stops naming the topic.
  EXPECT_EQ(runPlayer("player_backwards", writeBag("backwards", 6, true, true, {1.0, 1.1, 1.2, 0.5, 1.4, 1.5}), &log),
            1)
      << log;
  EXPECT_NE(log.find("stamps go backwards on /cam1/image_raw"), std::string::npos) << log;
  std::lock_guard<std::mutex> lock(pipeline.mutex);
  EXPECT_GE(pipeline.acked.size(), 3u);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_paced_player");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
