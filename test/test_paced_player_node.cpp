// paced_player against a stand-in pipeline: this node subscribes to the
// cameras and acknowledges each reference image on /fusion_done after a
// delay (a slow machine), as the TSDF stage does. Checks that every frame set
// of a drive is played, with at most ~in_flight sets in the pipeline (one: none
// overlaps the previous one), and that bags
// without /tf, without a camera or with stamps going backwards are named and
// stop the player with exit status 1. ~hold: after the drive the clock goes
// on and the last pose is published again with a new stamp each time (never
// a stamp tf2 already has: TF_REPEATED_DATA). ~publish_camera_info: each
// image comes with its camera's CameraInfo from the camchain (stamp and
// frame_id of the image); the wrong image size, a bag with CameraInfo of its
// own and a missing camchain are named.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosgraph_msgs/Clock.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <signal.h>
#include <tf2_msgs/TFMessage.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <vector>

#include "fisheye_mapping/FrameDone.h"
#include "ros_test_utils.h"

namespace {

const std::string kCam0 = "/cam0/image_raw", kCam1 = "/cam1/image_raw";

sensor_msgs::Image image(double t, const std::string& frame, int width = 4, int height = 4) {
  sensor_msgs::Image m;
  m.header.stamp = ros::Time(t);
  m.header.frame_id = frame;
  m.height = height;
  m.width = width;
  m.encoding = "mono8";
  m.step = width;
  m.data.assign(std::size_t(width) * height, 100);
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

// What writeBag puts in a bag beyond its frame sets.
struct BagOptions {
  int width = 4, height = 4;      // the images' size
  std::string cam1_frame = "cam1";
  bool with_camera_info = false;  // a CameraInfo of cam0 (/cam0/camera_info) with each frame set
};

// Writes a bag: frame sets at 1.0, 1.1, ... with a pose before each; cam1's
// stamps may be given (to make them go backwards).
std::string writeBag(const std::string& name, int sets, bool with_tf, bool with_cam1,
                     const std::vector<double>& cam1_stamps = {}, const BagOptions& o = BagOptions()) {
  const std::string path = "/tmp/fisheye_mapping_paced_" + std::to_string(getpid()) + "_" + name + ".bag";
  rosbag::Bag bag(path, rosbag::bagmode::Write);
  for (int k = 0; k < sets; ++k) {
    const double t = 1.0 + 0.1 * k;
    const ros::Time rt(t);
    if (with_tf) bag.write("/tf", rt, pose(t));
    if (o.with_camera_info) {
      sensor_msgs::CameraInfo info;
      info.header.stamp = rt;
      info.header.frame_id = "cam0";
      bag.write("/cam0/camera_info", rt, info);
    }
    bag.write(kCam0, rt, image(t, "cam0", o.width, o.height));
    if (with_cam1) bag.write(kCam1, rt, image(cam1_stamps.empty() ? t : cam1_stamps[k], o.cam1_frame, o.width, o.height));
  }
  bag.close();
  return path;
}

struct Pipeline {
  ros::NodeHandle nh;
  ros::Publisher done = nh.advertise<fisheye_mapping::FrameDone>("/fusion_done", 100);
  ros::Subscriber s0, s1;
  std::vector<ros::WallTimer> ack_timers;
  std::mutex mutex;
  std::vector<double> seen;  // reference stamps received
  std::vector<double> acked;
  int overlaps = 0;          // a new reference arrived before the last one was acknowledged
  size_t max_in_flight = 0;  // most references received and not yet acknowledged, this one included
  int drop = -1;             // the index of a reference never acknowledged (a stage dropped it), -1: none

  explicit Pipeline(int drop_index = -1) : drop(drop_index) {
    s0 = nh.subscribe<sensor_msgs::Image>(kCam0, 100, boost::function<void(const sensor_msgs::Image::ConstPtr&)>([this](const sensor_msgs::Image::ConstPtr& m) {
      std::lock_guard<std::mutex> lock(mutex);
      if (seen.size() > acked.size()) ++overlaps;
      seen.push_back(m->header.stamp.toSec());
      if (static_cast<int>(seen.size()) - 1 == drop) return;
      max_in_flight = std::max(max_in_flight, seen.size() - acked.size());
      const std_msgs::Header header = m->header;
      // Acknowledge 0.3 s later: slower than the bag (0.1 s per frame set).
      ack_timers.push_back(nh.createWallTimer(
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
          true));
    }));
    s1 = nh.subscribe<sensor_msgs::Image>(
        kCam1, 100, boost::function<void(const sensor_msgs::Image::ConstPtr&)>([](const sensor_msgs::Image::ConstPtr&) {}));
  }
};

// The poses of base_link the player publishes (stamp, x) and its clock, as they arrive.
struct PosesAndClock {
  ros::NodeHandle nh;
  std::mutex mu;
  std::vector<double> tf_stamps, tf_x, clocks;
  ros::Subscriber tf_sub = nh.subscribe<tf2_msgs::TFMessage>(
      "/tf", 100, boost::function<void(const tf2_msgs::TFMessage::ConstPtr&)>([this](const tf2_msgs::TFMessage::ConstPtr& m) {
        std::lock_guard<std::mutex> lock(mu);
        for (const auto& t : m->transforms) {
          if (t.child_frame_id != "base_link") continue;
          tf_stamps.push_back(t.header.stamp.toSec());
          tf_x.push_back(t.transform.translation.x);
        }
      }));
  ros::Subscriber clock_sub = nh.subscribe<rosgraph_msgs::Clock>(
      "/clock", 100, boost::function<void(const rosgraph_msgs::Clock::ConstPtr&)>([this](const rosgraph_msgs::Clock::ConstPtr& m) {
        std::lock_guard<std::mutex> lock(mu);
        clocks.push_back(m->clock.toSec());
      }));
};

std::string readFile(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

const std::string kTwoCameraRig = std::string(FM_TEST_DATA_DIR) + "/two_camera";

// The player's parameters: `bag`, the two image topics (none with
// `image_topics` false), hold off, short waits; `extra` over them (bool
// values "true" / "false", numbers an int or a double, anything else a string).
void setPlayerParams(const std::string& name, const std::string& bag, bool image_topics = true,
                     const std::map<std::string, std::string>& extra = {}) {
  ros::param::set("/" + name + "/bag", bag);
  if (image_topics) ros::param::set("/" + name + "/image_topics", std::vector<std::string>{kCam0, kCam1});
  ros::param::set("/" + name + "/hold", false);
  ros::param::set("/" + name + "/timeout", 10.0);
  ros::param::set("/" + name + "/wait_subscribers", 20.0);
  for (const auto& [key, value] : extra) {
    if (value == "true" || value == "false") {
      ros::param::set("/" + name + "/" + key, value == "true");
    } else if (!value.empty() && value.find_first_not_of("-0123456789") == std::string::npos) {
      ros::param::set("/" + name + "/" + key, std::stoi(value));
    } else if (!value.empty() && value.find_first_not_of("-0123456789.") == std::string::npos) {
      ros::param::set("/" + name + "/" + key, std::stod(value));
    } else {
      ros::param::set("/" + name + "/" + key, value);
    }
  }
}

std::string playerCommand(const std::string& name, const std::string& out) {
  return std::string(FM_PACED_PLAYER) + " __name:=" + name + " > " + out + " 2>&1";
}

std::string logPath(const std::string& name) {
  return "/tmp/fisheye_mapping_paced_" + std::to_string(getpid()) + "_" + name + ".log";
}

// Runs the player on `bag` under the node name `name`; returns its exit
// status and leaves its output in *log.
int runPlayer(const std::string& name, const std::string& bag, std::string* log, const std::string& summary = "",
              bool image_topics = true, std::map<std::string, std::string> extra = {}) {
  if (!summary.empty()) extra["summary_file"] = summary;
  setPlayerParams(name, bag, image_topics, extra);
  const std::string out = logPath(name);
  const int status = std::system(playerCommand(name, out).c_str());
  *log = readFile(out);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

// ~in_flight 1 (the default): each frame set after the previous one is finished.
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
  EXPECT_EQ(pipeline.max_in_flight, 1u);
  const std::string yaml = readFile(summary);
  EXPECT_NE(yaml.find("played: 6\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("fused: 6\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("timed_out: 0\n"), std::string::npos) << yaml;
}

// ~in_flight 2 (vehicle.launch's): the next frame set goes out while the last is
// still in the pipeline (stages overlap), never a third; the last two are
// waited for at the end, so every set is finished when the player ends.
TEST(PacedPlayer, TwoFrameSetsInFlight) {
  Pipeline pipeline;
  const std::string summary = "/tmp/fisheye_mapping_paced_" + std::to_string(getpid()) + "_two.yaml";
  std::string log;
  ASSERT_EQ(runPlayer("player_two", writeBag("two", 6, true, true), &log, summary, true, {{"in_flight", "2"}}), 0)
      << log;
  {
    std::lock_guard<std::mutex> lock(pipeline.mutex);
    EXPECT_EQ(pipeline.seen.size(), 6u) << log;
    EXPECT_EQ(pipeline.acked.size(), 6u) << "the player ended before the last sets were finished";
    EXPECT_EQ(pipeline.max_in_flight, 2u);
    EXPECT_GE(pipeline.overlaps, 1);  // the third set came while the second was in the pipeline
  }
  const std::string yaml = readFile(summary);
  EXPECT_NE(yaml.find("fused: 6\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("timed_out: 0\n"), std::string::npos) << yaml;
  EXPECT_EQ(runPlayer("player_in_flight_bad", writeBag("in_flight_bad", 2, true, true), &log, "", true,
                      {{"in_flight", "0"}}), 2) << log;
  EXPECT_NE(log.find("~in_flight"), std::string::npos) << log;
}

// A frame set dropped on the way (never acknowledged) while the next ones are:
// counted as lost as soon as a later one is finished, not after ~timeout.
TEST(PacedPlayer, AFrameSetDroppedOnTheWayIsLostAtOnce) {
  Pipeline pipeline(2);
  const std::string summary = "/tmp/fisheye_mapping_paced_" + std::to_string(getpid()) + "_lost.yaml";
  std::string log;
  ASSERT_EQ(runPlayer("player_lost", writeBag("lost", 6, true, true), &log, summary, true,
                      {{"timeout", "30.0"}, {"in_flight", "2"}}), 0) << log;
  const std::string yaml = readFile(summary);
  EXPECT_NE(yaml.find("played: 6\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("fused: 5\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("lost: 1\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("timed_out: 0\n"), std::string::npos) << yaml;
  EXPECT_NE(log.find("frame set 1.200 never reached the fusion stage"), std::string::npos) << log;
}

// ~loops: the drive played three times as one long drive. Each pass is
// later by the drive's length + 0.1 s (0.2 + 0.1 s here): the images' header
// stamps, the poses' and the clock keep going forward, the poses repeat the
// drive's (the vehicle back at its start), and no more than two frame sets of
// the passes are ever in the pipeline at once.
TEST(PacedPlayer, LoopsPlayTheDriveAgainLaterInTime) {
  Pipeline pipeline;
  PosesAndClock seen;
  std::mutex& mu = seen.mu;
  std::vector<double>&tf_stamps = seen.tf_stamps, &tf_x = seen.tf_x, &clocks = seen.clocks;
  const std::string summary = "/tmp/fisheye_mapping_paced_" + std::to_string(getpid()) + "_loops.yaml";
  std::string log;
  const int status = runPlayer("player_loops", writeBag("loops", 3, true, true), &log, summary, true, {{"loops", "3"}});
  ASSERT_EQ(status, 0) << log;
  const std::vector<double> expected = {1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.7, 1.8};
  {
    std::lock_guard<std::mutex> lock(pipeline.mutex);
    ASSERT_EQ(pipeline.seen.size(), expected.size()) << log;
    for (std::size_t i = 0; i < expected.size(); ++i) EXPECT_NEAR(pipeline.seen[i], expected[i], 1e-6) << "frame set " << i;
    EXPECT_LE(pipeline.max_in_flight, 2u);
  }
  ASSERT_TRUE(fisheye_mapping::test::waitFor([&] {
    std::lock_guard<std::mutex> lock(mu);
    return tf_stamps.size() >= expected.size();
  }, 5.0));
  {
    std::lock_guard<std::mutex> lock(mu);
    ASSERT_EQ(tf_stamps.size(), expected.size());
    for (std::size_t i = 0; i < expected.size(); ++i) {
      EXPECT_NEAR(tf_stamps[i], expected[i], 1e-6) << "pose " << i;
      EXPECT_DOUBLE_EQ(tf_x[i], 1.0 + 0.1 * double(i % 3)) << "pose " << i << ": the drive's own";
    }
    for (std::size_t i = 1; i < clocks.size(); ++i) EXPECT_GE(clocks[i], clocks[i - 1]) << "clock " << i;
    ASSERT_FALSE(clocks.empty());
    EXPECT_NEAR(clocks.back(), 1.8, 1e-6);
  }
  const std::string yaml = readFile(summary);
  EXPECT_NE(yaml.find("played: 9\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("fused: 9\n"), std::string::npos) << yaml;
  // ~stop_after: 1000 passes cut at 1 s of wall time (each set acknowledged
  // 0.3 s after it arrives, two in flight: about 0.15 s a set), at a frame set
  // boundary: every frame set played was finished.
  const std::string cut = "/tmp/fisheye_mapping_paced_" + std::to_string(getpid()) + "_cut.yaml";
  ASSERT_EQ(runPlayer("player_cut", writeBag("cut", 3, true, true), &log, cut, true,
                      {{"loops", "1000"}, {"stop_after", "1.0"}}), 0) << log;
  const std::string cut_yaml = readFile(cut);
  EXPECT_NE(cut_yaml.find("stopped_after_s: 1\n"), std::string::npos) << cut_yaml;
  EXPECT_NE(cut_yaml.find("timed_out: 0\n"), std::string::npos) << cut_yaml;
  int played = -1, fused = -2;
  std::sscanf(cut_yaml.c_str(), "played: %d\nfused: %d", &played, &fused);
  EXPECT_EQ(played, fused) << cut_yaml;
  EXPECT_GE(played, 3) << cut_yaml;
  EXPECT_LE(played, 12) << cut_yaml;
  // A count of passes that is not a positive whole number is refused.
  EXPECT_EQ(runPlayer("player_loops_bad", writeBag("loops_bad", 2, true, true), &log, "", true, {{"loops", "0"}}), 2) << log;
  EXPECT_NE(log.find("~loops"), std::string::npos) << log;
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

// ~hold: the drive's last pose keeps coming after the drive, each time with a
// later stamp and the clock at that stamp; tf2 never sees a stamp twice.
TEST(PacedPlayer, HoldAdvancesTheClockAndNeverRepeatsAPoseStamp) {
  Pipeline pipeline;
  PosesAndClock seen;
  std::mutex& mu = seen.mu;
  std::vector<double>&tf_stamps = seen.tf_stamps, &tf_x = seen.tf_x, &clocks = seen.clocks;
  const std::string name = "player_hold";
  setPlayerParams(name, writeBag("hold", 4, true, true), true, {{"hold", "true"}});
  const std::string out = logPath(name);
  const std::string shell = "exec " + playerCommand(name, out);  // no allocation after fork()
  const pid_t pid = fork();
  if (pid == 0) {
    execl("/bin/sh", "sh", "-c", shell.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  ASSERT_GT(pid, 0);
  // The drive's 4 poses (1.0 .. 1.3), then at least 6 held ones (0.5 s apart).
  const auto held = [&] {  // mu held by the caller
    return std::count_if(tf_stamps.begin(), tf_stamps.end(), [](double s) { return s > 1.3 + 1e-6; });
  };
  const auto heldNow = [&] {
    std::lock_guard<std::mutex> lock(mu);
    return held();
  };
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(30.0);
  while (heldNow() < 6 && ros::WallTime::now() < end) ros::WallDuration(0.05).sleep();
  kill(pid, SIGINT);
  int status = -1;
  waitpid(pid, &status, 0);
  const std::string log = readFile(out);
  ASSERT_TRUE(WIFEXITED(status)) << log;
  EXPECT_EQ(WEXITSTATUS(status), 0) << "Ctrl-C while holding is a normal end: " << log;
  EXPECT_NE(log.find("holding the last pose of 1 frames"), std::string::npos) << log;

  std::lock_guard<std::mutex> lock(mu);
  ASSERT_GE(held(), 6) << log;
  ASSERT_GE(tf_stamps.size(), 10u);
  for (std::size_t i = 0; i < 4; ++i) EXPECT_NEAR(tf_stamps[i], 1.0 + 0.1 * i, 1e-9) << "the drive's pose " << i;
  for (std::size_t i = 1; i < tf_stamps.size(); ++i) {
    EXPECT_GT(tf_stamps[i], tf_stamps[i - 1]) << "pose " << i << " repeats or goes back from " << tf_stamps[i - 1];
  }
  for (std::size_t i = 4; i < tf_stamps.size(); ++i) {
    EXPECT_DOUBLE_EQ(tf_x[i], 1.3) << "a held pose is the drive's last one";
    EXPECT_NEAR(tf_stamps[i], 1.3 + 0.5 * (i - 3), 1e-6) << "held pose " << i << ": 0.5 s after the one before";
  }
  // The clock never goes back and reaches the held stamps.
  for (std::size_t i = 1; i < clocks.size(); ++i) EXPECT_GE(clocks[i], clocks[i - 1]) << "clock " << i;
  ASSERT_FALSE(clocks.empty());
  EXPECT_GE(clocks.back(), tf_stamps.back() - 1e-6);
}

// ~publish_camera_info: the camchain's intrinsics (hand values of
// test/data/two_camera_camchain.yaml) with every image, its stamp and frame_id;
// an image without a frame_id gets the mount's frame of its camera. Before
// the drive, the first image's CameraInfo goes out every 0.25 s while
// anything subscribes (here: this test, so for the whole 3 s).
TEST(PacedPlayer, PublishesEachCamerasCameraInfoWithEachImage) {
  Pipeline pipeline;
  ros::NodeHandle nh;
  std::mutex mu;
  std::map<std::string, std::vector<sensor_msgs::CameraInfo>> infos;  // topic -> messages
  std::vector<ros::Subscriber> subs;
  for (const std::string topic : {"/cam0/camera_info", "/cam1/camera_info"}) {
    subs.push_back(nh.subscribe<sensor_msgs::CameraInfo>(
        topic, 100,
        boost::function<void(const sensor_msgs::CameraInfo::ConstPtr&)>([&, topic](const sensor_msgs::CameraInfo::ConstPtr& m) {
          std::lock_guard<std::mutex> lock(mu);
          infos[topic].push_back(*m);
        })));
  }
  BagOptions o;
  o.width = 1024;
  o.height = 544;
  o.cam1_frame = "";
  std::string log;
  const int status = runPlayer("player_info", writeBag("info", 3, true, true, {}, o), &log, "", false,
                               {{"camchain", kTwoCameraRig + "_camchain.yaml"},
                                {"mount", kTwoCameraRig + "_mount.yaml"},
                                {"publish_camera_info", "true"}});
  ASSERT_EQ(status, 0) << log;
  EXPECT_NE(log.find("CameraInfo published for 3."), std::string::npos) << log;
  EXPECT_NE(log.find("(still subscribed: going on)"), std::string::npos) << log;
  ros::WallDuration(0.5).sleep();
  std::lock_guard<std::mutex> lock(mu);
  // 3 s at 4 Hz before the drive (at least 10: the first one, then every 0.25 s), then one per image.
  const std::size_t n = infos["/cam0/camera_info"].size();
  ASSERT_GE(n, 13u) << log;
  ASSERT_LE(n, 17u) << log;
  ASSERT_EQ(infos["/cam1/camera_info"].size(), n) << log;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = i + 3 < n ? 0 : i + 3 - n;  // the primer: the first image's
    const sensor_msgs::CameraInfo& c0 = infos["/cam0/camera_info"][i];
    const sensor_msgs::CameraInfo& c1 = infos["/cam1/camera_info"][i];
    EXPECT_NEAR(c0.header.stamp.toSec(), 1.0 + 0.1 * k, 1e-9) << "CameraInfo " << i << " of " << n;
    EXPECT_NEAR(c1.header.stamp.toSec(), 1.0 + 0.1 * k, 1e-9) << "CameraInfo " << i << " of " << n;
    EXPECT_EQ(c0.header.frame_id, "cam0") << "the image's frame_id";
    EXPECT_EQ(c1.header.frame_id, "cam1_optical") << "no frame_id in the image: the mount's";
    EXPECT_EQ(c0.width, 1024u);
    EXPECT_EQ(c0.height, 544u);
    // cam0: Mei (omni), xi 1, fx = fy = 300, centre (512, 272), no distortion.
    EXPECT_EQ(c0.distortion_model, "omni");
    EXPECT_EQ(c0.D, (std::vector<double>{1.0, 0.0, 0.0, 0.0, 0.0}));
    EXPECT_EQ(c0.K[0], 300.0);
    EXPECT_EQ(c0.K[4], 300.0);
    EXPECT_EQ(c0.K[2], 512.0);
    EXPECT_EQ(c0.K[5], 272.0);
    EXPECT_EQ(c0.K[8], 1.0);
    // cam1: pinhole + equidistant (Kannala-Brandt).
    EXPECT_EQ(c1.distortion_model, "equidistant");
    EXPECT_EQ(c1.D, (std::vector<double>{0.0, 0.0, 0.0, 0.0}));
    EXPECT_EQ(c1.K[0], 300.0);
    EXPECT_EQ(c1.K[2], 512.0);
  }
}

TEST(PacedPlayer, CameraInfoBadInputIsNamed) {
  Pipeline pipeline;
  std::string log;
  const std::map<std::string, std::string> rig = {{"camchain", kTwoCameraRig + "_camchain.yaml"},
                                                  {"mount", kTwoCameraRig + "_mount.yaml"},
                                                  {"publish_camera_info", "true"}};
  // No camchain: the intrinsics are unknown.
  EXPECT_EQ(runPlayer("player_info_no_rig", writeBag("info_no_rig", 2, true, true), &log, "", true,
                      {{"publish_camera_info", "true"}}),
            2)
      << log;
  EXPECT_NE(log.find("~publish_camera_info needs ~camchain and ~mount"), std::string::npos) << log;
  // 4x4 images for 1024x544 cameras: named, and nothing is played past it.
  EXPECT_EQ(runPlayer("player_info_size", writeBag("info_size", 2, true, true), &log, "", false, rig), 1) << log;
  // (cam0's or cam1's first image, whichever the bag gives first at the first stamp)
  EXPECT_NE(log.find("~publish_camera_info: an image on /cam"), std::string::npos) << log;
  EXPECT_NE(log.find("/image_raw is 4x4, its camera in " + kTwoCameraRig + "_camchain.yaml is 1024x544; stopping"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("frame sets 0 played"), std::string::npos) << log;
  {
    std::lock_guard<std::mutex> lock(pipeline.mutex);
    EXPECT_TRUE(pipeline.seen.empty()) << "an image was played";
  }
  // The bag has CameraInfo of its own on cam0's topic.
  BagOptions o;
  o.width = 1024;
  o.height = 544;
  o.with_camera_info = true;
  EXPECT_EQ(runPlayer("player_info_dup", writeBag("info_dup", 2, true, true, {}, o), &log, "", false, rig), 2) << log;
  EXPECT_NE(log.find("already has /cam0/camera_info"), std::string::npos) << log;
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_paced_player");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  // The bags, logs and summaries this run wrote (named by its pid) go.
  const std::string prefix = "fisheye_mapping_paced_" + std::to_string(getpid()) + "_";
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/tmp", ec)) {
    if (e.path().filename().string().rfind(prefix, 0) == 0) std::filesystem::remove(e.path(), ec);
  }
  return result;
}
