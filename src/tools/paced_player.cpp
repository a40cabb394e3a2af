// paced_player: plays a logged drive (rosbag) so that no frame set is lost,
// whatever the speed of the machine. It publishes /clock and the bag's
// messages in order, and before each new frame set (a new stamp on the
// reference camera) it waits until the pipeline has finished the one
// ~in_flight sets back (default 1: the previous one; vehicle.launch plays with
// 2, the previous but one, so that the depth of the new set overlaps the
// fusion of the last, as on a live car; that needs the depth stage's
// ~input_queue at 2 as well):
// the TSDF fusion stage sends a fisheye_mapping/FrameDone per depth frame
// (topic ~done_topic). A frame set that is not finished within ~timeout
// seconds is counted as timed out and the drive goes on.
//
//   rosrun fisheye_mapping paced_player _bag:=drive.bag _camchain:=camchain.yaml _mount:=mount.yaml
//
// Parameters (private):
//   bag            the rosbag (required)
//   camchain, mount  the rig (Kalibr camchain + mount) whose cameras'
//                  `rostopic` fields name the image topics (or image_topics:
//                  a list)
//   reference_topic  the reference camera's image topic (default: the first)
//   done_topic     default /fusion_done
//   timeout        seconds to wait for one frame set (default 120)
//   in_flight      frame sets in the pipeline at once, 1 to 16 (default 1:
//                  each set waits for the one before; more needs the depth
//                  stage's ~input_queue as large, or sets are dropped as busy)
//   wait_subscribers  seconds to wait for the pipeline to subscribe (default 120)
//   start          seconds into the bag to begin (default 0)
//   loops          play the drive this many times in a row (default 1; a
//                  soak: scripts/checks/soak). Each pass after the first is
//                  moved later in time by the drive's length + 0.1 s (far
//                  under the stages' 1 s time-reset threshold: the clock
//                  reaches a node after a pass's first images): every
//                  stamp (headers, /tf, /clock) keeps going forward, so
//                  the pipeline sees one long drive in which the vehicle
//                  jumps back to the start; /tf_static goes out once
//   stop_after     wall seconds after which the drive ends early: at the next
//                  frame set, once the pipeline has finished the one before
//                  (default 0: play every pass to its end)
//   require_tf     the bag must hold /tf (default true: the map needs poses)
//   summary_file   YAML with the counts, written at the end (optional)
//   hold           after the drive, keep running until shut down: the clock
//                  goes on at wall-clock speed and the last pose of every /tf
//                  frame is published again twice a second, each time
//                  stamped with the new clock (a stamp never repeats: tf2
//                  would drop it as TF_REPEATED_DATA), so that a viewer
//                  started later still places the map (default true)
//   publish_camera_info  publish each camera's sensor_msgs/CameraInfo from
//                  the camchain (its intrinsics, toCameraInfo) on
//                  <image topic's namespace>/camera_info (image_transport's
//                  convention: /cam0/image_raw -> /cam0/camera_info), just
//                  before each image, with the image's stamp and frame_id, for
//                  rig_source camera_info on a bag without CameraInfo
//                  (default false; needs ~camchain and ~mount). Before the
//                  drive it publishes the bag's /tf_static and every
//                  camera's first CameraInfo until the pipeline has its rig
//                  (at most 3 s), so that no frame set waits for it
//
// Exit status: 0 when the drive was played to its end (with hold: when shut
// down after it), 1 on bad input (no bag, a camera topic or /tf missing,
// stamps going backwards, an image whose size is not its camera's with
// ~publish_camera_info: the message names it), 2 on bad parameters. On bad
// input in the drive (stamps going backwards) it stops there, after the
// pipeline has finished the frame sets already played, and exits without
// holding.
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <rosgraph_msgs/Clock.h>
#include <std_msgs/Header.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/CameraInfo.h>
#include <tf2_msgs/TFMessage.h>
#include <topic_tools/shape_shifter.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/FrameDone.h"
#include "fisheye_mapping/core/sync/frame_pacer.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/ros/bag_reading.h"
#include "fisheye_mapping/ros/camera_info.h"

namespace fm = fisheye_mapping;

namespace {

// An image message's header (raw or compressed) and, for a raw image, its
// size; false for any other type.
struct ImageHeader {
  std_msgs::Header header;
  int width = -1, height = -1;  // -1: compressed (not decoded here)
};
bool imageHeader(const rosbag::MessageInstance& m, ImageHeader* out) {
  if (auto img = m.instantiate<sensor_msgs::Image>()) {
    out->header = img->header;
    out->width = int(img->width);
    out->height = int(img->height);
    return true;
  }
  if (auto img = m.instantiate<sensor_msgs::CompressedImage>()) {
    out->header = img->header;
    out->width = out->height = -1;
    return true;
  }
  return false;
}

// Whether a message type's first field is a std_msgs/Header (its definition's
// first field line), so that its stamp sits at bytes 4-11 of the message.
bool startsWithHeader(const std::string& definition) {
  std::istringstream in(definition);
  std::string line;
  while (std::getline(in, line)) {
    const auto b = line.find_first_not_of(" \t");
    if (b == std::string::npos || line[b] == '#') continue;
    return line.compare(b, 7, "Header ") == 0 || line.compare(b, 16, "std_msgs/Header ") == 0;
  }
  return false;
}

// A recorded message (first field a Header) with its header stamp moved by `shift`.
topic_tools::ShapeShifter shiftedMessage(const rosbag::MessageInstance& m, const ros::Duration& shift) {
  std::vector<uint8_t> buf(m.size());
  ros::serialization::OStream out(buf.data(), uint32_t(buf.size()));
  m.write(out);
  if (buf.size() >= 12) {
    uint32_t sec, nsec;
    std::memcpy(&sec, &buf[4], 4);
    std::memcpy(&nsec, &buf[8], 4);
    const ros::Time t = ros::Time(sec, nsec) + shift;
    std::memcpy(&buf[4], &t.sec, 4);
    std::memcpy(&buf[8], &t.nsec, 4);
  }
  topic_tools::ShapeShifter shifted;
  shifted.morph(m.getMD5Sum(), m.getDataType(), m.getMessageDefinition(), "");
  ros::serialization::IStream in(buf.data(), uint32_t(buf.size()));
  shifted.read(in);
  return shifted;
}

// image_transport's CameraInfo topic of an image topic: its namespace +
// "/camera_info" (/cam0/image_raw -> /cam0/camera_info).
std::string cameraInfoTopic(const std::string& image_topic) {
  const auto slash = image_topic.rfind('/');
  return slash == std::string::npos ? "camera_info" : image_topic.substr(0, slash) + "/camera_info";
}

const char* kUsage =
    "usage: rosrun fisheye_mapping paced_player _bag:=drive.bag _camchain:=camchain.yaml _mount:=mount.yaml\n"
    "  Plays a rosbag so that no frame set is lost: before each new frame set it waits\n"
    "  for the pipeline's fisheye_mapping/FrameDone of the one ~in_flight sets back. Parameters (private):\n"
    "  ~bag               the rosbag (required)\n"
    "  ~camchain, ~mount  the rig whose cameras' rostopic fields name the image topics\n"
    "  ~image_topics      or the image topics as a list\n"
    "  ~reference_topic   the reference camera's image topic (default: the first)\n"
    "  ~done_topic        default /fusion_done\n"
    "  ~timeout           seconds to wait for one frame set (default 120)\n"
    "  ~in_flight         frame sets in the pipeline at once, 1 to 16 (default 1; 2 overlaps the stages:\n"
    "                     give the depth node ~input_queue 2 too, as vehicle.launch does)\n"
    "  ~wait_subscribers  seconds to wait for the pipeline to subscribe (default 120)\n"
    "  ~start             seconds into the bag to begin (default 0)\n"
    "  ~loops             play the drive this many times, each pass later in time (default 1)\n"
    "  ~stop_after        end the drive at the next frame set after this many wall seconds (default 0: never)\n"
    "  ~require_tf        the bag must hold /tf (default true)\n"
    "  ~summary_file      YAML with the counts, written at the end (optional)\n"
    "  ~hold              after the drive, keep running: the clock goes on and the last poses\n"
    "                     are published again, stamped with it (default true)\n"
    "  ~publish_camera_info  publish each camera's CameraInfo from the camchain on\n"
    "                     <image namespace>/camera_info with each image (default false)\n"
    "Exit status: 0 played to the end, 1 bad input, 2 bad parameters.\n";

struct Done {
  std::mutex mutex;
  std::condition_variable cv;
  std::map<double, bool> frames;  // stamp -> fused
  std::map<double, std::string> reasons;
};

}  // namespace

int main(int argc, char** argv) {
  // Options before ros::init, so that --help needs no ROS master; ros::init
  // then takes away the remappings (_param:=value, __name:=...), and any
  // option left is unknown.
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::cout << kUsage;
      return 0;
    }
  }
  ros::init(argc, argv, "paced_player");
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.size() > 1 && a[0] == '-') {
      std::cerr << "paced_player: unknown option '" << a << "' (parameters are given as _name:=value)\n" << kUsage;
      return 2;
    }
  }
  ros::NodeHandle nh, pnh("~");
  std::string bag_path, camchain, mount, reference_topic, done_topic = "/fusion_done", summary_file;
  std::vector<std::string> image_topics;
  double timeout = 120.0, wait_subscribers = 120.0, start = 0.0, stop_after = 0.0;
  int loops = 1, in_flight = 1;
  bool require_tf = true, hold = true, publish_camera_info = false;
  pnh.getParam("bag", bag_path);
  pnh.getParam("camchain", camchain);
  pnh.getParam("mount", mount);
  pnh.getParam("image_topics", image_topics);
  pnh.getParam("reference_topic", reference_topic);
  pnh.getParam("done_topic", done_topic);
  pnh.getParam("timeout", timeout);
  pnh.getParam("wait_subscribers", wait_subscribers);
  pnh.getParam("start", start);
  pnh.getParam("loops", loops);
  pnh.getParam("in_flight", in_flight);
  pnh.getParam("stop_after", stop_after);
  pnh.getParam("require_tf", require_tf);
  pnh.getParam("summary_file", summary_file);
  pnh.getParam("hold", hold);
  pnh.getParam("publish_camera_info", publish_camera_info);
  if (bag_path.empty()) {
    ROS_FATAL("paced_player: parameter ~bag (the rosbag to play) is required");
    return 2;
  }
  // Bounds of the numeric parameters: finite, and no wait longer than a day.
  const auto bad_number = [](const char* name, double v, double lo, double hi) {
    if (std::isfinite(v) && v >= lo && v <= hi) return false;
    ROS_FATAL("paced_player: parameter ~%s must lie in [%g, %g], got %g", name, lo, hi, v);
    return true;
  };
  if (bad_number("timeout", timeout, 0.001, 86400) || bad_number("wait_subscribers", wait_subscribers, 0, 86400) ||
      bad_number("start", start, 0, 1e7) || bad_number("loops", loops, 1, 1e6) ||
      bad_number("in_flight", in_flight, 1, 16) ||
      bad_number("stop_after", stop_after, 0, 1e7)) {
    return 2;
  }
  try {
    if (!summary_file.empty()) fm::cli::requireOutputFile("~summary_file", summary_file);
  } catch (const fm::cli::UsageError& e) {
    ROS_FATAL("paced_player: %s", e.what());
    return 2;
  }
  try {
    fm::cli::requireInputFile("~bag", bag_path);
  } catch (const fm::cli::UsageError& e) {  // bad input, as an unreadable bag below
    ROS_FATAL("paced_player: cannot read the bag %s: %s", bag_path.c_str(), e.what());
    return 1;
  }
  if (publish_camera_info && (camchain.empty() || mount.empty())) {
    ROS_FATAL("paced_player: ~publish_camera_info needs ~camchain and ~mount (the cameras' intrinsics)");
    return 2;
  }
  // With ~publish_camera_info: the rig camera of each image topic (the
  // camchain's rostopic; with ~image_topics, the camera at the same index).
  std::map<std::string, fm::RigCamera> topic_camera;
  if (image_topics.empty() || publish_camera_info) {
    if (camchain.empty() || mount.empty()) {
      ROS_FATAL("paced_player: give ~camchain and ~mount (the cameras' rostopic fields) or ~image_topics");
      return 2;
    }
    try {
      const fm::Rig rig = fm::loadKalibrRig(camchain, mount);
      const bool from_rig = image_topics.empty();
      if (!from_rig && image_topics.size() != rig.cameras.size()) {
        throw std::runtime_error("~image_topics has " + std::to_string(image_topics.size()) + " topics for " +
                                 std::to_string(rig.cameras.size()) + " cameras");
      }
      for (std::size_t i = 0; i < rig.cameras.size(); ++i) {
        const fm::RigCamera& c = rig.cameras[i];
        if (from_rig) {
          if (c.rostopic.empty()) throw std::runtime_error("camera " + c.name + " has no rostopic field");
          image_topics.push_back(c.rostopic);
        }
        topic_camera[image_topics[i]] = c;
      }
    } catch (const std::exception& e) {
      ROS_FATAL("paced_player: rig %s: %s", camchain.c_str(), e.what());
      return 2;
    }
  }
  if (reference_topic.empty()) reference_topic = image_topics.front();

  rosbag::Bag bag;
  try {
    fm::openBagForReading(bag, bag_path);  // a bag cut short: the rosbag reindex command
  } catch (const std::exception& e) {
    ROS_FATAL("paced_player: %s", e.what());
    return 1;
  }
  // Input checks before anything is published.
  std::set<std::string> bag_topics;
  {
    rosbag::View all(bag);
    for (const auto* c : all.getConnections()) bag_topics.insert(c->topic);
  }
  // A camchain names the base topic (image_transport): a bag of compressed
  // images carries <topic>/compressed instead.
  for (auto& t : image_topics) {
    if (bag_topics.count(t) || !bag_topics.count(t + "/compressed")) continue;
    if (reference_topic == t) reference_topic += "/compressed";
    if (topic_camera.count(t)) topic_camera[t + "/compressed"] = topic_camera[t];
    t += "/compressed";
  }
  std::unique_ptr<fm::FramePacer> pacer;
  try {
    pacer = std::make_unique<fm::FramePacer>(reference_topic, image_topics, in_flight);
  } catch (const std::exception& e) {
    ROS_FATAL("paced_player: %s", e.what());
    return 2;
  }
  for (const auto& t : image_topics) {
    if (!bag_topics.count(t)) {
      ROS_FATAL("paced_player: the bag %s has no messages on %s (a camera of the rig): nothing to map",
                bag_path.c_str(), t.c_str());
      return 1;
    }
  }
  if (require_tf && !bag_topics.count("/tf")) {
    ROS_FATAL("paced_player: the bag %s has no /tf: the map needs the vehicle's poses (map -> base_link) at every "
              "frame set (set ~require_tf false if they come from elsewhere)",
              bag_path.c_str());
    return 1;
  }

  // ~publish_camera_info: one CameraInfo per camera, on the base topic's
  // namespace (a compressed topic's base: the topic without /compressed).
  struct InfoOut {
    std::string topic;
    sensor_msgs::CameraInfo info;
    int width = 0, height = 0;
  };
  std::map<std::string, InfoOut> info_out;  // image topic (as played) -> its CameraInfo
  if (publish_camera_info) {
    for (const auto& t : image_topics) {
      // A topic renamed to <base>/compressed above keeps its base's camera.
      const std::string suffix = "/compressed";
      const bool renamed = t.size() > suffix.size() && t.compare(t.size() - suffix.size(), suffix.size(), suffix) == 0 &&
                           topic_camera.count(t.substr(0, t.size() - suffix.size())) > 0;
      const std::string base = renamed ? t.substr(0, t.size() - suffix.size()) : t;
      const fm::RigCamera& cam = topic_camera.at(t);
      InfoOut o;
      o.topic = cameraInfoTopic(base);
      o.info = fm::toCameraInfo(cam, ros::Time());
      o.width = cam.model.width();
      o.height = cam.model.height();
      if (bag_topics.count(o.topic)) {
        ROS_FATAL("paced_player: ~publish_camera_info: the bag %s already has %s (CameraInfo of %s); set "
                  "~publish_camera_info false to use the bag's",
                  bag_path.c_str(), o.topic.c_str(), t.c_str());
        return 2;
      }
      info_out[t] = o;
    }
  }

  Done done;
  ros::Subscriber done_sub = nh.subscribe<fm::FrameDone>(done_topic, 100, [&](const fm::FrameDone::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(done.mutex);
    done.frames[msg->header.stamp.toSec()] = msg->fused;
    if (!msg->fused) done.reasons[msg->header.stamp.toSec()] = msg->reason;
    done.cv.notify_all();
  });
  ros::AsyncSpinner spinner(1);
  spinner.start();

  ros::Publisher clock_pub = nh.advertise<rosgraph_msgs::Clock>("/clock", 10);
  std::map<std::string, ros::Publisher> pubs;
  rosbag::View view(bag);
  const ros::Time begin = view.getBeginTime() + ros::Duration(start);
  rosbag::View play(bag, begin, ros::TIME_MAX);
  for (const auto* c : play.getConnections()) {
    if (pubs.count(c->topic)) continue;
    ros::AdvertiseOptions opts(c->topic, 100, c->md5sum, c->datatype, c->msg_def);
    opts.latch = c->topic == "/tf_static";
    pubs[c->topic] = nh.advertise(opts);
  }
  std::map<std::string, ros::Publisher> info_pubs;  // CameraInfo topic -> publisher
  for (const auto& [image_topic, o] : info_out) {
    if (!info_pubs.count(o.topic)) info_pubs[o.topic] = nh.advertise<sensor_msgs::CameraInfo>(o.topic, 100);
  }
  if (!info_out.empty()) ROS_INFO("paced_player: publishing the camchain's CameraInfo of %zu cameras", info_out.size());

  // Wait until the pipeline listens: every image topic subscribed, and the
  // fusion stage's done topic published.
  const auto t_wait = std::chrono::steady_clock::now();
  for (;;) {
    std::string missing;
    for (const auto& t : image_topics) {
      if (pubs[t].getNumSubscribers() == 0) missing = "nothing subscribes to " + t;
    }
    if (missing.empty() && done_sub.getNumPublishers() == 0) missing = "nothing publishes " + done_topic;
    if (missing.empty()) break;
    if (!ros::ok()) return 1;
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t_wait).count() > wait_subscribers) {
      ROS_FATAL("paced_player: after %.0f s, %s: is the pipeline (vehicle.launch) running?", wait_subscribers,
                missing.c_str());
      return 1;
    }
    ros::WallDuration(0.1).sleep();
  }
  ros::WallDuration(0.5).sleep();  // connections settle

  // ~publish_camera_info: a pipeline with rig_source camera_info builds its
  // rig from the first CameraInfo of every camera and tf (Sync tries
  // every 0.5 s, then unsubscribes) and drops the frame sets before that,
  // which would leave the player waiting ~timeout for the first one. So the
  // bag's /tf_static and each camera's CameraInfo (the first image's stamp
  // and frame_id) go out first, again every 0.25 s until nothing subscribes
  // to the CameraInfo topics any more (the rig is built) or 3 s have passed.
  if (!info_out.empty()) {
    rosbag::View statics(bag, rosbag::TopicQuery("/tf_static"));
    for (const rosbag::MessageInstance& m : statics) {
      if (pubs.count("/tf_static")) pubs["/tf_static"].publish(m);
    }
    std::map<std::string, sensor_msgs::CameraInfo> primer;  // CameraInfo topic -> message
    for (const auto& [image_topic, o] : info_out) {
      rosbag::View first(bag, rosbag::TopicQuery(image_topic), begin);
      for (const rosbag::MessageInstance& m : first) {
        ImageHeader h;
        if (!imageHeader(m, &h)) break;
        sensor_msgs::CameraInfo info = o.info;
        info.header.stamp = h.header.stamp;
        if (!h.header.frame_id.empty()) info.header.frame_id = h.header.frame_id;
        primer[o.topic] = info;
        break;
      }
    }
    const auto t_primer = std::chrono::steady_clock::now();
    for (int round = 0; ros::ok(); ++round) {
      for (const auto& [topic, info] : primer) info_pubs[topic].publish(info);
      bool listened = false;
      for (const auto& [topic, pub] : info_pubs) listened = listened || pub.getNumSubscribers() > 0;
      const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_primer).count();
      if (!listened || waited > 3.0) {
        if (round > 0) {
          ROS_INFO("paced_player: CameraInfo published for %.2f s before the drive%s", waited,
                   listened ? " (still subscribed: going on)" : " (the rig is built)");
        }
        break;
      }
      ros::WallDuration(0.25).sleep();
    }
  }

  int timed_out = 0, lost = 0, bad_input = 0;
  std::vector<double> played;
  // Waits until the pipeline has finished the frame set `stamp`. The stages
  // keep the frame sets' order, so once a later set is finished this one never
  // will be (a stage dropped it on the way): it is counted as lost at once
  // rather than after ~timeout.
  auto waitFor = [&](double stamp) {
    std::unique_lock<std::mutex> lock(done.mutex);
    const auto later_done = [&] { return !done.frames.empty() && done.frames.rbegin()->first > stamp; };
    const bool got = done.cv.wait_for(lock, std::chrono::duration<double>(timeout), [&] {
      return done.frames.count(stamp) > 0 || later_done() || !ros::ok();
    });
    if (!got) {
      ++timed_out;
      ROS_WARN("paced_player: frame set %.3f not finished by the pipeline within %.0f s; going on", stamp, timeout);
    } else if (done.frames.count(stamp) == 0 && later_done()) {
      ++lost;
      ROS_WARN("paced_player: frame set %.3f never reached the fusion stage (a later one was finished first: "
               "dropped on the way); going on", stamp);
    }
  };
  const auto t0 = std::chrono::steady_clock::now();
  int last_progress = -1;
  std::map<std::string, geometry_msgs::TransformStamped> last_pose;  // child frame -> latest /tf
  ros::Time last_clock, last_tf_stamp;
  const double duration = (view.getEndTime() - begin).toSec();
  // ~loops: how much later each pass is played. The gap between passes stays
  // far under the stages' time-reset threshold (1 s): a node's clock lags the
  // images a little, and with a 1 s gap a sync that saw a new pass's second
  // frame set before its clock caught up took the clock for one jumping back
  // (a soak lost 2 frame sets so).
  const ros::Duration pass_length(duration + 0.1);
  std::map<std::string, bool> has_header;           // topic -> its type's first field is a Header
  bool stopped_early = false;  // ~stop_after
  for (int pass = 0; pass < loops && ros::ok() && !bad_input && !stopped_early; ++pass) {
    const ros::Duration shift = pass_length * double(pass);
    if (pass > 0) ROS_INFO("paced_player: pass %d of %d, stamps %.1f s later", pass + 1, loops, shift.toSec());
    for (const rosbag::MessageInstance& m : play) {
      if (!ros::ok()) break;
      const std::string& topic = m.getTopic();
      if (pass > 0 && topic == "/tf_static") continue;  // latched since the first pass
      const bool is_image = pacer->isImageTopic(topic);
      ImageHeader image;
      if (is_image && !imageHeader(m, &image)) {
        ROS_ERROR("paced_player: %s is not a sensor_msgs/Image or CompressedImage topic; stopping", topic.c_str());
        bad_input = 1;
        break;
      }
      image.header.stamp += shift;
      const double stamp = is_image ? image.header.stamp.toSec() : 0.0;
      const auto info_it = is_image ? info_out.find(topic) : info_out.end();
      if (info_it != info_out.end() && image.width >= 0 &&
          (image.width != info_it->second.width || image.height != info_it->second.height)) {
        ROS_ERROR("paced_player: ~publish_camera_info: an image on %s is %dx%d, its camera in %s is %dx%d; stopping",
                  topic.c_str(), image.width, image.height, camchain.c_str(), info_it->second.width,
                  info_it->second.height);
        bad_input = 1;
        break;
      }
      const fm::FramePacer::Step step = pacer->next(topic, stamp);
      if (step.kind == fm::FramePacer::Step::kStampsBackwards) {
        ROS_ERROR("paced_player: %s; stopping here (a bag played twice or a clock reset?)", step.error.c_str());
        bad_input = 1;
        break;
      }
      if (step.kind == fm::FramePacer::Step::kWaitThenPublish) {
        waitFor(step.wait_for);
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (stop_after > 0 && elapsed > stop_after) {
          ROS_INFO("paced_player: ~stop_after %.0f s reached after %.0f s: the drive ends here", stop_after, elapsed);
          stopped_early = true;
          break;
        }
      }
      if (topic == reference_topic && (played.empty() || played.back() != stamp)) played.push_back(stamp);
      rosgraph_msgs::Clock clock;
      clock.clock = m.getTime() + shift;
      clock_pub.publish(clock);
      last_clock = clock.clock;
      if (info_it != info_out.end()) {
        // The CameraInfo first: a subscriber pairing the two finds it there.
        sensor_msgs::CameraInfo info = info_it->second.info;
        info.header.stamp = image.header.stamp;
        if (!image.header.frame_id.empty()) info.header.frame_id = image.header.frame_id;
        info_pubs[info_it->second.topic].publish(info);
      }
      tf2_msgs::TFMessage::Ptr tf = topic == "/tf" && (hold || pass > 0) ? m.instantiate<tf2_msgs::TFMessage>() : nullptr;
      if (pass == 0) {
        pubs[topic].publish(m);
      } else if (tf) {
        for (auto& t : tf->transforms) t.header.stamp += shift;
        pubs[topic].publish(*tf);
      } else {
        auto known = has_header.find(topic);
        if (known == has_header.end()) known = has_header.emplace(topic, startsWithHeader(m.getMessageDefinition())).first;
        if (known->second) {
          pubs[topic].publish(shiftedMessage(m, shift));
        } else {
          pubs[topic].publish(m);
        }
      }
      if (hold && tf) {
        for (const auto& t : tf->transforms) {
          last_pose[t.child_frame_id] = t;
          last_tf_stamp = std::max(last_tf_stamp, t.header.stamp);
        }
      }
      const int progress = static_cast<int>(100.0 * (pass * duration + (m.getTime() - begin).toSec()) /
                                            std::max(loops * duration, 1e-9));
      if (progress / 10 != last_progress / 10) {
        last_progress = progress;
        ROS_INFO("paced_player: %3d %% of the drive%s, %zu frame sets played", progress,
                 loops > 1 ? "s" : "", played.size());
      }
    }
  }
  for (double stamp : pacer->unwaited()) {  // the last sets in flight (played: not one held back by ~stop_after)
    if (!ros::ok()) break;
    if (std::binary_search(played.begin(), played.end(), stamp)) waitFor(stamp);
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  int fused = 0, skipped = 0;
  {
    std::lock_guard<std::mutex> lock(done.mutex);
    for (double s : played) {
      auto it = done.frames.find(s);
      if (it == done.frames.end()) continue;
      if (it->second) {
        ++fused;
      } else {
        ++skipped;
        ROS_WARN("paced_player: frame set %.3f not fused: %s", s, done.reasons[s].c_str());
      }
    }
  }
  ROS_INFO("paced_player: frame sets %zu played, %d fused, %d skipped, %d lost, %d timed out; %.1f s (%.2f frame sets/s)",
           played.size(), fused, skipped, lost, timed_out, wall, played.size() / std::max(wall, 1e-9));
  if (!summary_file.empty()) {
    try {
      fm::cli::writeTextAtomically(summary_file, [&](std::ostream& f) {
        f << "played: " << played.size() << "\nfused: " << fused << "\nskipped: " << skipped
          << "\nlost: " << lost << "\ntimed_out: " << timed_out << "\nstopped_on_bad_input: " << (bad_input ? "true" : "false")
          << "\nstopped_after_s: " << (stopped_early ? stop_after : 0.0)
          << "\nwall_s: " << wall << "\n";
      });
    } catch (const std::exception& e) {
      ROS_ERROR("paced_player: summary not written: %s", e.what());
      bad_input = 1;
    }
  }
  // Hold: the clock goes on at wall-clock speed from the last stamp played
  // (clock or pose, whichever is later) and the last poses are published
  // again with each new clock, so that rviz started after the drive still
  // finds the frames. Every held stamp is later than any before it: tf2 drops
  // a pose whose stamp it already has (TF_REPEATED_DATA, logged each time).
  // After bad input the player exits (status 1) instead: vehicle.launch
  // marks it required, so the launch ends and the TSDF stage saves its map.
  if (hold && !bad_input && ros::ok()) {
    ROS_INFO("paced_player: drive over; holding the last pose of %zu frames (clock going on) until shut down",
             last_pose.size());
    const ros::Duration step(0.5);
    ros::Time held = std::max(last_clock, last_tf_stamp);
    while (ros::ok()) {
      ros::WallDuration(step.toSec()).sleep();
      if (!ros::ok()) break;
      held += step;
      rosgraph_msgs::Clock clock;
      clock.clock = held;
      clock_pub.publish(clock);
      if (!last_pose.empty() && pubs.count("/tf")) {
        tf2_msgs::TFMessage msg;
        for (auto& [child, t] : last_pose) {
          t.header.stamp = held;
          msg.transforms.push_back(t);
        }
        pubs["/tf"].publish(msg);
      }
    }
  }
  spinner.stop();
  return bad_input ? 1 : 0;
}
