// offline_mapper: the mapping pipeline over a rosbag without roscore, as fast
// as the machine allows: frame sets grouped by the core FrameSetSync (the sync
// stage's config: exact stamps by default, or approximate), then the core
// FrameSetMapper (depth stage, detector or the drive's ground-truth boxes,
// masking, TSDF fusion) with poses from the bag's /tf. The same core stage
// objects, configs and parameter names as the nodelets of vehicle.launch, and
// the same default detector (nanodet); this file only reads the bag and writes
// the results. Images are sensor_msgs/Image or sensor_msgs/CompressedImage
// (decoded to grey), on the camchain's rostopic of each camera, the `sync`
// section's image_topics of --config, or --topic CAM=TOPIC.
//
// Writes DIR/mesh.ply, DIR/cloud.pcd, DIR/cloud_all.pcd (every voxel with a
// surface, i.e. without the minimum-observation filter), DIR/map.fmtsdf (the
// TSDF map, as the nodelet's save_map: map_tool, occupancy_eval), DIR/timings.md (ms
// per stage), DIR/timings.csv (one row per frame set) and, with a detector,
// DIR/vehicles.csv (each detected vehicle: moving, parked or undecided, its
// speed and track, and whether the drive's true boxes say it moves), each under a
// temporary name renamed over the old file once complete, and prints the files
// it wrote. Exit status: 0; 1 when the run failed or a map file could not be
// written (e.g. --frames 1: nothing observed often enough for a mesh; the
// earlier file of that name stays); 2 on bad options or input paths.
// Options: see kUsage.
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2/buffer_core.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>

#include <algorithm>
#include <deque>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <numeric>
#include <optional>
#include <string>
#include <filesystem>
#include <set>
#include <sstream>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/mapping/frame_set_mapper.h"
#include "fisheye_mapping/core/detection/detector_registry.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/bag_reading.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/param_registry.h"

namespace fm = fisheye_mapping;
namespace cli = fm::cli;

namespace {

using Clock = std::chrono::steady_clock;

const char* kUsage =
    "usage: offline_mapper --bag B --camchain F --mount F --out DIR [--config vehicle.yaml]\n"
    "       [--detector nanodet|finetuned|darknet|ground_truth|none|MODEL.yaml] [--depth sweep|gt]\n"
    "       [--topic CAM=TOPIC]... [--sync exact|approximate] [--sync-tolerance SECONDS]\n"
    "       [--frames N] [--every K] [--world map] [--config-dir DIR] [--save-depth DIR] [--quiet]\n"
    "  --bag B            the drive: camera images (raw or compressed), /tf, and for the\n"
    "                     oracles /<ref>/detections_gt and /<ref>/depth_gt\n"
    "  --camchain F, --mount F  the rig (Kalibr camchain and mount)\n"
    "  --out DIR          mesh.ply, cloud.pcd, cloud_all.pcd, map.fmtsdf, timings.md, timings.csv,\n"
    "                     vehicles.csv (with a detector: each vehicle's motion decision)\n"
    "  --config YAML      sections sync, depth, detector, depth_mask, tsdf over the\n"
    "                     stage defaults (as vehicle.launch's config:=)\n"
    "  --detector D       a name of the detector registry (as vehicle.launch's detector:=;\n"
    "                     detector_model --list): nanodet (default), finetuned (the cache's\n"
    "                     models/finetuned/nanodet-fisheye.yaml, made by\n"
    "                     scripts/tools/train_vehicle_detector), darknet (yolov3-tiny), ...; a\n"
    "                     model YAML, ground_truth (the oracle: the drive's true boxes)\n"
    "                     or none (nothing masked)\n"
    "  --depth SRC        sweep (default): plane-sweep depth; gt: the bag's ground-truth\n"
    "                     depth of the reference camera (the evaluation's reference map;\n"
    "                     with --detector ground_truth or none)\n"
    "  --topic CAM=TOPIC  read camera CAM's images from TOPIC (repeatable; default: the\n"
    "                     config's sync/image_topics, else the camchain's rostopic)\n"
    "  --sync POLICY      exact: images of one frame set have equal stamps; approximate:\n"
    "                     within --sync-tolerance (default: the config's sync/policy, exact)\n"
    "  --sync-tolerance S seconds, approximate policy, in [0, 1] (default: the config's\n"
    "                     sync/max_interval, 0.005)\n"
    "  --frames N         map at most N frame sets, N in [1, 10000000] (default: all)\n"
    "  --every K          map every K-th frame set, K in [1, 1000000] (default 1)\n"
    "  --world FRAME      the fixed frame of the poses (default map)\n"
    "  --config-dir DIR   the stage default files (default: the package's config/)\n"
    "  --save-depth DIR   write each mapped frame set's masked depth as DIR/<stamp ns>.tiff\n"
    "  --quiet            no progress bar\n"
    "  Outputs are written under temporary names and renamed once complete: a failed\n"
    "  run leaves the files of an earlier run in --out as they were. Exit status: 0;\n"
    "  1 when the run failed or a map file was not written; 2 on bad options.\n";

YAML::Node loadYaml(const std::string& path) {
  try {
    return YAML::LoadFile(path);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

// Every section of the --config file is a stage (a node of vehicle.launch)
// and each of its keys a parameter that node declares; std::invalid_argument
// names the file, the section and the key otherwise.
void requireKnownConfig(const YAML::Node& config, const std::string& path) {
  if (!config || config.IsNull()) return;  // no --config (or an empty file)
  if (!config.IsMap()) throw std::invalid_argument(path + ": expected a map of stage sections");
  for (const auto& kv : config) {
    const std::string section = kv.first.as<std::string>();
    const fm::NodeParamSet* set = nullptr;
    try {
      set = &fm::nodeParamSet(section);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(path + ": " + e.what());
    }
    if (kv.second.IsNull()) continue;
    if (!kv.second.IsMap()) throw std::invalid_argument(path + ": section '" + section + "' is not a map");
    set->requireKnown(fm::yamlKeys(kv.second), path);
  }
}

// Stage defaults overlaid with the stage's section of the --config file (both
// checked for unknown names).
YAML::Node stageParams(const std::string& defaults_file, const YAML::Node& config, const std::string& section) {
  YAML::Node merged = defaults_file.empty() ? YAML::Node(YAML::NodeType::Map) : loadYaml(defaults_file);
  if (!defaults_file.empty()) fm::nodeParamSet(section).requireKnown(fm::yamlKeys(merged), defaults_file);
  if (config && config[section] && config[section].IsMap())
    for (const auto& kv : config[section]) merged[kv.first.as<std::string>()] = kv.second;
  return merged;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// --topic CAM=TOPIC, checked: both parts present.
std::pair<std::string, std::string> parseTopicOption(const std::string& text) {
  const size_t eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size())
    throw cli::UsageError("--topic needs CAM=TOPIC (e.g. cam0=/cam0/image_raw/compressed), got '" + text + "'");
  return {text.substr(0, eq), text.substr(eq + 1)};
}

// "exact" or "approximate (0.005 s)", for timings.md.
std::string syncText(fm::SyncPolicy policy, double max_interval) {
  return policy == fm::SyncPolicy::Exact ? "exact" : "approximate (" + cli::numberText(max_interval) + " s)";
}

// --sync exact|approximate.
fm::SyncPolicy parseSyncOption(const std::string& text) {
  try {
    return fm::parseSyncPolicy(text);
  } catch (const std::invalid_argument&) {
    throw cli::UsageError("--sync must be exact or approximate, got '" + text + "'");
  }
}

// The image topic of each camera, in camera order: --topic, else the sync
// config's image_topics, else the camchain's rostopic, else /<cam>/image_raw.
// Throws UsageError for a --topic camera the rig lacks or two cameras on one
// topic.
std::vector<std::string> imageTopics(const fm::Rig& rig, const std::vector<std::string>& config_topics,
                                     const std::map<std::string, std::string>& overrides) {
  if (!config_topics.empty() && config_topics.size() != rig.cameras.size())
    throw std::runtime_error("sync/image_topics of --config has " + std::to_string(config_topics.size()) +
                             " topics for " + std::to_string(rig.cameras.size()) + " cameras");
  std::vector<std::string> topics;
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    const fm::RigCamera& cam = rig.cameras[c];
    topics.push_back(!config_topics.empty() ? config_topics[c]
                     : cam.rostopic.empty() ? "/" + cam.name + "/image_raw"
                                            : cam.rostopic);
  }
  for (const auto& [name, topic] : overrides) {
    const int c = rig.indexOf(name);
    if (c < 0) throw cli::UsageError("--topic: no camera '" + name + "' in the rig");
    topics[c] = topic;
  }
  for (size_t c = 0; c < topics.size(); ++c)
    for (size_t d = 0; d < c; ++d)
      if (topics[c] == topics[d])
        throw cli::UsageError("cameras " + rig.cameras[d].name + " and " + rig.cameras[c].name + " both read " +
                              topics[c] + " (give each its own with --topic)");
  return topics;
}

}  // namespace

int main(int argc, char** argv) {
  cli::rerunWithPassiveOpenMpWait(argv);
  std::string bag_path, camchain, mount, out, config_path, detector = "nanodet", world = "map", depth_src = "sweep";
  std::string save_depth, model_yaml;
  std::string config_dir = FM_CONFIG_DIR;
  std::map<std::string, std::string> topic_overrides;
  std::optional<fm::SyncPolicy> sync_policy;
  std::optional<double> sync_tolerance;
  int max_frames = 0, every = 1;
  bool quiet = false;
  const int rc = cli::parseCommandLine("offline_mapper", kUsage, [&] {
    cli::forEachOption(argc, argv, 1, [&](const std::string& a, const cli::NextValue& next) {
      if (a == "--bag") bag_path = next();
      else if (a == "--camchain") camchain = next();
      else if (a == "--mount") mount = next();
      else if (a == "--out") out = next();
      else if (a == "--config") config_path = next();
      else if (a == "--config-dir") config_dir = next();
      else if (a == "--detector") detector = next();
      else if (a == "--frames") max_frames = static_cast<int>(cli::parseInt(a, next(), 1, 10000000));
      else if (a == "--every") every = static_cast<int>(cli::parseInt(a, next(), 1, 1000000));
      else if (a == "--world") world = next();
      else if (a == "--depth") depth_src = next();
      else if (a == "--save-depth") save_depth = next();
      else if (a == "--topic") topic_overrides.insert(parseTopicOption(next()));
      else if (a == "--sync") sync_policy = parseSyncOption(next());
      else if (a == "--sync-tolerance") sync_tolerance = cli::parseDouble(a, next(), 0.0, 1.0);
      else if (a == "--quiet") quiet = true;
      else return false;
      return true;
    });
    if (bag_path.empty() || camchain.empty() || mount.empty() || out.empty())
      throw cli::UsageError("--bag, --camchain, --mount and --out are required");
    if (depth_src != "sweep" && depth_src != "gt") throw cli::UsageError("--depth must be sweep or gt, got '" + depth_src + "'");
    if (world.empty()) throw cli::UsageError("--world needs a frame name");
    cli::requireInputFile("--bag", bag_path);
    cli::requireInputFile("--camchain", camchain);
    cli::requireInputFile("--mount", mount);
    if (!config_path.empty()) cli::requireInputFile("--config", config_path);
    std::error_code ec;
    if (!std::filesystem::is_directory(config_dir, ec)) throw cli::UsageError("--config-dir: " + config_dir + " is not a folder");
    // The model of a detector name: the detector registry's (as vehicle.launch's).
    if (detector != "none" && detector != "ground_truth") {
      try {
        model_yaml = fm::detectorModelPath(detector, config_dir);
      } catch (const std::invalid_argument& e) {  // an unknown name
        throw cli::UsageError("--detector: " + std::string(e.what()) + ", ground_truth or none");
      } catch (const std::runtime_error& e) {  // its file is missing
        throw cli::UsageError("--detector " + std::string(e.what()));
      }
    }
    cli::prepareOutputDir("--out", out);
    if (!save_depth.empty()) cli::prepareOutputDir("--save-depth", save_depth);
  });
  if (rc >= 0) return rc;
  try {
    const fm::Rig rig = fm::loadKalibrRig(camchain, mount);
    const YAML::Node config = config_path.empty() ? YAML::Node() : loadYaml(config_path);
    requireKnownConfig(config, config_path);
    const fm::YamlParams sweep_p(stageParams(config_dir + "/depth.yaml", config, "depth"), "depth");
    const fm::YamlParams tsdf_p(stageParams(config_dir + "/tsdf.yaml", config, "tsdf"), "tsdf");
    const fm::YamlParams mask_p(stageParams("", config, "depth_mask"), "depth_mask");
    const fm::YamlParams det_p(stageParams("", config, "detector"), "detector");
    const fm::FrameSetMapperConfig mapper_cfg = fm::FrameSetMapperConfig::fromParams(sweep_p, det_p, mask_p, tsdf_p);
    // The sync stage's config (the `sync` section of --config), then the options.
    fm::FrameSyncConfig sync_cfg = fm::FrameSyncConfig::fromParams(fm::YamlParams(stageParams("", config, "sync"), "sync"));
    if (sync_policy) sync_cfg.policy = *sync_policy;
    if (sync_tolerance) sync_cfg.max_interval = *sync_tolerance;
    sync_cfg.validate();
    const std::vector<std::string> configured_topics = imageTopics(rig, sync_cfg.image_topics, topic_overrides);
    std::unique_ptr<fm::Detector> det;
    if (detector != "none" && detector != "ground_truth") {
      // The detector stage's config (thresholds, DNN device of the `detector`
      // section) with the model chosen by --detector, as the nodelet loads it.
      fm::DetectorStageConfig stage = mapper_cfg.detection;
      stage.model_config = model_yaml;
      det = std::make_unique<fm::Detector>(stage.loadModel(), stage.device());
    }
    const bool detecting = det != nullptr;
    fm::FrameSetMapper mapper(rig, mapper_cfg, std::move(det));
    const fm::TsdfConfig& tsdf_cfg = mapper_cfg.tsdf;
    fm::TsdfMesher mesher_all(1);  // no minimum-observation filter
    const int ref = mapper.reference();

    if (detecting && depth_src == "gt")
      throw std::runtime_error("--depth gt works with --detector ground_truth or none (no images are read)");
    rosbag::Bag bag;
    fm::openBagForReading(bag, bag_path);  // a bag cut short: the rosbag reindex command
    // Pass 1: poses and ground-truth boxes.
    tf2::BufferCore tf(ros::Duration(1e6));
    std::map<uint64_t, fm::Detection2DArray::ConstPtr> gt_boxes;
    const std::string gt_topic = "/" + rig.cameras[ref].name + "/detections_gt";
    const std::string gt_depth_topic = "/" + rig.cameras[ref].name + "/depth_gt";
    size_t tf_msgs = 0;
    for (const rosbag::MessageInstance& m : rosbag::View(bag, rosbag::TopicQuery({"/tf", "/tf_static", gt_topic}))) {
      if (auto t = m.instantiate<tf2_msgs::TFMessage>()) {
        const bool is_static = m.getTopic() == "/tf_static";
        for (const auto& tr : t->transforms) tf.setTransform(tr, "bag", is_static);
        ++tf_msgs;
      } else if (auto d = m.instantiate<fm::Detection2DArray>()) {
        gt_boxes[d->header.stamp.toNSec()] = d;
      }
    }
    if (tf_msgs == 0) throw std::runtime_error(bag_path + " has no /tf: the vehicle poses are missing");
    if (detector == "ground_truth" && gt_boxes.empty())
      throw std::runtime_error(bag_path + " has no " + gt_topic + " (ground-truth boxes); use --detector none or a model");

    // Pass 2: frame sets. A camera topic the bag lacks is read from
    // <topic>/compressed when the bag has that (image_transport's name).
    const std::vector<std::string> camera_topics = fm::imageTopicsInBag(bag, configured_topics);
    std::vector<std::string> topics = camera_topics;
    std::map<std::string, int> cam_of;
    for (size_t c = 0; c < topics.size(); ++c) cam_of[topics[c]] = int(c);
    if (depth_src == "gt") {  // ground-truth depth stands in for the sweep; the reference image gives the intensity
      topics = {gt_depth_topic, camera_topics[ref]};
      cam_of = {{gt_depth_topic, 0}, {camera_topics[ref], 1}};
    }
    rosbag::View images(bag, rosbag::TopicQuery(topics));
    if (images.size() == 0) throw std::runtime_error(bag_path + " has none of the topics " + topics[0] + " ...");
    size_t total_sets = images.size() / (depth_src == "gt" ? 2 : rig.cameras.size()) / every;
    if (max_frames > 0) total_sets = std::min<size_t>(total_sets, max_frames);
    // Ground-truth depth and the reference image: rendered together, exact stamps.
    const bool gt_depth = depth_src == "gt";
    fm::FrameSetSync<fm::BagImage> sync(gt_depth ? 2 : int(rig.cameras.size()),
                                    gt_depth ? fm::SyncPolicy::Exact : sync_cfg.policy, sync_cfg.max_interval,
                                    std::size_t(sync_cfg.queue_size), sync_cfg.time_reset_threshold);
    const int ref_slot = depth_src == "gt" ? 0 : ref;
    // timings.csv is written (checked) at the end.
    std::ostringstream csv;
    csv << "stamp,sweep_ms,detect_ms,mask_ms,fuse_ms,total_ms,valid_pixels,masked_pixels,blocks_fused,blocks_carved\n";
    // Each detected vehicle's motion decision, with the truth where the bag
    // has the moving vehicles' true boxes (IoU >= 0.3 with one: moving).
    std::ostringstream vehicles_csv;
    vehicles_csv << "stamp,x_min,y_min,x_max,y_max,score,motion,speed_mps,track,x,y,true_moving\n";
    std::ostringstream calib_csv;
    calib_csv << "stamp,camera,rotvec_ref_cam_x_deg,rotvec_ref_cam_y_deg,rotvec_ref_cam_z_deg,correction_deg,"
                 "residual_deg,inliers,level,status,t_ref_cam_x_m,t_ref_cam_y_m,t_ref_cam_z_m,translation_updates,"
                 "metric_matches,translation_status\n";
    std::vector<double> t_sweep, t_det, t_mask, t_fuse, t_total;
    size_t sets_seen = 0, processed = 0, submitted = 0, skipped_pose = 0, no_boxes = 0;
    // Complete frame sets not mapped: an image that does not decode, --every.
    size_t undecodable = 0, skipped_every = 0;
    bool stopped_early = false;  // --frames reached: the rest of the bag is not read
    std::set<std::string> not_images;  // topics with a message of another type (warned once)
    // A skipped frame set's warning; the first 20 of each reason, then a count at the end.
    std::map<std::string, int> warned;
    auto warnSkip = [&](const std::string& reason, const std::string& text) {
      if (++warned[reason] <= 20) std::fprintf(stderr, "\noffline_mapper: %s\n", text.c_str());
    };
    const auto run_start = Clock::now();
    std::deque<ros::Time> in_flight;  // stamps of the frame sets submitted and not yet back
    // One frame set's result: the self-calibration's state, the depth TIFF,
    // the timings and the progress line.
    auto handle = [&](fm::FrameSetResult r, const ros::Time& stamp) {
      if (!r.motion.empty()) {
        auto gt = gt_boxes.find(stamp.toNSec());
        std::vector<fm::Detection> truth;
        double gsx = 1.0, gsy = 1.0;
        if (gt != gt_boxes.end()) {
          fm::StampedDetections d = fm::fromDetectionArrayMsg(*gt->second);
          truth = std::move(d.detections);
          if (d.image_width > 0 && d.image_height > 0) {
            gsx = double(r.boxes.image_width) / d.image_width;
            gsy = double(r.boxes.image_height) / d.image_height;
          }
        }
        for (size_t i = 0; i < r.motion.size(); ++i) {
          const fm::Detection& b = r.boxes.boxes[i];
          int moving = gt == gt_boxes.end() ? -1 : 0;
          for (const fm::Detection& g : truth) {
            const double ix = std::max(0.0, std::min<double>(b.x_max, g.x_max * gsx) - std::max<double>(b.x_min, g.x_min * gsx));
            const double iy = std::max(0.0, std::min<double>(b.y_max, g.y_max * gsy) - std::max<double>(b.y_min, g.y_min * gsy));
            const double inter = ix * iy;
            const double uni = double(b.x_max - b.x_min) * (b.y_max - b.y_min) +
                               (g.x_max - g.x_min) * gsx * (g.y_max - g.y_min) * gsy - inter;
            if (uni > 0 && inter / uni >= 0.3) moving = 1;
          }
          const auto& m = r.motion[i];
          vehicles_csv << std::fixed << std::setprecision(3) << stamp.toSec() << "," << b.x_min << "," << b.y_min
                       << "," << b.x_max << "," << b.y_max << "," << b.score << "," << fm::toString(m.motion) << ","
                       << m.speed << "," << m.track << "," << m.position.x() << "," << m.position.y() << ","
                       << moving << "\n";
        }
      }
      if (r.depth.calibration_ms > 0) {
        // The self-calibration's state after this update: each supporting
        // camera's rotation relative to the reference, as used from now on.
        const fm::Rig& now = *r.calibrated_rig;
        const int cal_ref = mapper.reference();
        for (const auto& c : r.calibration) {
          if (c.reference) continue;
          const Eigen::Isometry3d T_ref_cam = now.cameras[cal_ref].T_base_cam.inverse() * now.cameras[c.camera].T_base_cam;
          const Eigen::AngleAxisd aa(T_ref_cam.linear());
          const Eigen::Vector3d w = aa.angle() * aa.axis() * 180.0 / M_PI;
          const Eigen::Vector3d t = T_ref_cam.translation();
          std::string status = c.status, t_status = c.translation_status;
          std::replace(status.begin(), status.end(), ',', ';');
          std::replace(t_status.begin(), t_status.end(), ',', ';');
          calib_csv << std::fixed << stamp.toSec() << "," << c.name << "," << w.x() << "," << w.y() << "," << w.z()
                    << "," << c.correction_deg << "," << c.residual_deg << "," << c.inliers << ","
                    << (c.warn ? "WARN" : "OK") << "," << status << "," << std::setprecision(6) << t.x() << ","
                    << t.y() << "," << t.z() << "," << c.translation_updates << "," << c.metric_matches << ","
                    << t_status << "\n";
        }
      }
      if (!save_depth.empty())
        fm::writeDepthTiff(save_depth + "/" + std::to_string(stamp.toNSec()) + ".tiff", r.depth.depth);
      const double sweep_ms = r.ms.depth_ms, det_ms = r.ms.detect_ms, mask_ms = r.ms.mask_ms, fuse_ms = r.ms.fuse_ms;
      const double total = r.ms.total_ms;
      const fm::IntegrationStats& st = r.fusion;
      const cv::Mat& mask = r.mask;
      t_sweep.push_back(sweep_ms), t_det.push_back(det_ms), t_mask.push_back(mask_ms), t_fuse.push_back(fuse_ms),
          t_total.push_back(total);
      csv << std::fixed << stamp.toSec() << "," << sweep_ms << "," << det_ms << "," << mask_ms << "," << fuse_ms << ","
          << total << "," << st.valid_pixels << "," << cv::countNonZero(mask) << "," << st.blocks_touched << ","
          << st.blocks_carved << "\n";
      ++processed;
      if (!quiet) {
        const double el = std::chrono::duration<double>(Clock::now() - run_start).count();
        const int bar = total_sets ? int(30.0 * processed / total_sets) : 0;
        std::fprintf(stderr, "\r[%-30s] %zu/%zu frame sets, %.2f s/set, ETA %.0f s   ", std::string(std::min(bar, 30), '#').c_str(),
                     processed, total_sets, el / processed,
                     total_sets > processed ? el / processed * (total_sets - processed) : 0.0);
      }
    };
    for (const rosbag::MessageInstance& m : images) {
      const std::optional<fm::BagImage> img = fm::BagImage::of(m);
      if (!img) {
        if (not_images.insert(m.getTopic()).second)
          std::fprintf(stderr, "\noffline_mapper: %s holds %s, not sensor_msgs/Image or CompressedImage: ignored\n",
                       m.getTopic().c_str(), m.getDataType().c_str());
        continue;
      }
      auto done = sync.add(cam_of[m.getTopic()], std::int64_t(img->header().stamp.toNSec()), *img);
      for (auto& set : done) {
        if (sets_seen++ % every != 0) {
          ++skipped_every;
          continue;
        }
        if (max_frames > 0 && int(submitted) >= max_frames) {
          stopped_early = true;
          break;
        }
        const ros::Time stamp = set[ref_slot].header().stamp;
        Eigen::Isometry3d T_W_B;
        try {
          T_W_B = tf2::transformToEigen(tf.lookupTransform(world, rig.base_frame, stamp));
        } catch (const std::exception& e) {
          ++skipped_pose;
          if (!quiet) std::fprintf(stderr, "\nframe set %.3f skipped: no pose (%s)\n", stamp.toSec(), e.what());
          continue;
        }
        // Decoded before anything is submitted: an image that does not decode
        // (damaged, a JPEG cut short) skips its frame set, and the drive goes on.
        std::vector<cv::Mat> images;
        cv::Mat depth_gt, grey_gt;
        try {
          if (depth_src == "gt") {
            if (!set[0].raw) throw std::runtime_error(gt_depth_topic + " must hold sensor_msgs/Image (32FC1)");
            depth_gt = fm::toDepth(*set[0].raw, gt_depth_topic);
            grey_gt = set[1].greyImage(topics[1]);
          } else {
            for (size_t c = 0; c < set.size(); ++c) images.push_back(set[c].sweepImage(topics[c]));
          }
        } catch (const std::exception& e) {
          ++undecodable;
          char at[64];
          std::snprintf(at, sizeof at, "%.3f", stamp.toSec());
          warnSkip("undecodable", std::string("frame set ") + at + " skipped: undecodable image: " + e.what());
          continue;
        }
        std::optional<fm::ImageBoxes> boxes;
        if (!detecting && detector == "ground_truth") {
          auto it = gt_boxes.find(stamp.toNSec());
          if (it == gt_boxes.end()) {
            ++no_boxes;
          } else {
            fm::StampedDetections d = fm::fromDetectionArrayMsg(*it->second);
            boxes = fm::ImageBoxes{std::move(d.detections), d.image_width, d.image_height};
          }
        }
        ++submitted;
        if (depth_src == "gt") {
          handle(mapper.processDepth(depth_gt, T_W_B, boxes, grey_gt), stamp);
        } else {
          // Pipelined: this set's depth while the previous one is masked and
          // fused (and this one's detection runs); its result comes back with
          // the next set's submit, the last with flush().
          in_flight.push_back(stamp);
          std::optional<fm::FrameSetResult> previous = mapper.submit(images, T_W_B, boxes, stamp.toSec());
          if (previous) {
            handle(std::move(*previous), in_flight.front());
            in_flight.pop_front();
          }
        }
      }
      if (max_frames > 0 && int(submitted) >= max_frames) {
        stopped_early = true;
        break;
      }
    }
    if (!stopped_early) sync.finish();  // the sets still open at the bag's end: incomplete
    for (const auto& [reason, n] : warned)
      if (n > 20) std::fprintf(stderr, "\noffline_mapper: %d more frame sets skipped (%s) not listed\n", n - 20, reason.c_str());
    if (std::optional<fm::FrameSetResult> last = mapper.flush()) handle(std::move(*last), in_flight.front());
    if (!quiet) std::fprintf(stderr, "\n");
    // Every frame set of the bag accounted for: mapped, or dropped by reason.
    const auto& s = sync.stats();
    const unsigned long sets_total = (unsigned long)s.sets();
    const std::string accounted =
        std::string(stopped_early ? "of the first " : "of the ") + std::to_string(sets_total) +
        " frame sets" + (stopped_early ? " read (stopped at --frames)" : " in the bag") + ": " +
        std::to_string(processed) + " mapped, " + std::to_string(sets_total - processed) + " not: " +
        std::to_string(s.sets_backwards) + " stamps backwards, " + std::to_string(s.sets_duplicate) +
        " duplicate stamp, " + std::to_string(s.dropped_incomplete) + " incomplete, " + std::to_string(undecodable) +
        " undecodable image, " + std::to_string(skipped_pose) + " without a pose, " + std::to_string(s.sets_stale) +
        " old timeline, " + std::to_string(skipped_every) + " skipped by --every";
    if (processed == 0) throw std::runtime_error("no complete frame set with a pose in " + bag_path + " (" + accounted + ")");
    const double wall = std::chrono::duration<double>(Clock::now() - run_start).count();
    mapper.finish();                   // the frame sets since the last mesh update
    mesher_all.rebuild(mapper.map());  // every block of both stores, after the last frame
    const fm::TsdfMesher& mesher = mapper.mesher();
    // Each file is written beside its target, checked (fsync, size, close)
    // and renamed over the old one only once complete (core/common/
    // safe_write.h): a failed save keeps what an earlier run wrote.
    std::vector<std::string> written, not_written;
    for (const auto& [what, save] : std::vector<std::pair<std::string, std::function<void(const std::string&)>>>{
             {"mesh.ply", [&](const std::string& p) {
                if (mesher.numTriangles() == 0)
                  throw std::runtime_error("the map has no triangle yet (nothing observed " +
                                           std::to_string(tsdf_cfg.min_observations) + " times)");
                mesher.saveMeshPly(p);
              }},
             {"cloud.pcd", [&](const std::string& p) { mesher.saveCloudPcd(p); }},
             {"cloud_all.pcd", [&](const std::string& p) { mesher_all.saveCloudPcd(p); }},
             {"map.fmtsdf", [&](const std::string& p) { mapper.map().save(p); }}}) {
      try {
        save(out + "/" + what);
        written.push_back(what);
      } catch (const std::exception& e) {  // e.g. nothing observed often enough: say so, keep the rest
        not_written.push_back(what);
        std::cerr << "offline_mapper: " << what << " not written: " << e.what() << "\n";
      }
    }
    std::ostringstream md;
    char buf[1024];
    md << "| stage | median ms | mean ms |\n|---|---:|---:|\n";
    auto row = [&](const char* name, const std::vector<double>& v) {
      std::snprintf(buf, sizeof(buf), "| %s | %.1f | %.1f |\n", name, median(v),
                    std::accumulate(v.begin(), v.end(), 0.0) / v.size());
      md << buf;
    };
    row(depth_src == "gt" ? "ground-truth depth (read)" : "plane-sweep depth", t_sweep);
    row(detecting ? "detection" : "ground-truth boxes", t_det);
    row("masking", t_mask);
    row("TSDF fusion + mesh update", t_fuse);
    row("total per frame set", t_total);
    std::snprintf(buf, sizeof(buf),
                  "\n%zu frame sets mapped in %.1f s (%.2f per second, end to end, reading the bag included); "
                  "%s; %zu without ground-truth boxes; "
                  "sync %s; sweep backend %s; map: %zu triangles, %zu cloud points.\n",
                  processed, wall, processed / wall, accounted.c_str(), no_boxes,
                  syncText(gt_depth ? fm::SyncPolicy::Exact : sync_cfg.policy, sync_cfg.max_interval).c_str(),
                  mapper.depthStage().backendName().c_str(), mesher.numTriangles(), mesher.surfaceCloud().size());
    md << buf;
    if (const fm::OnlineRigCalibrator* cal = mapper.depthStage().selfCalibration()) {
      // The online self-calibration (depth stage): its cost and each camera's state.
      const double sweep_total = std::accumulate(t_sweep.begin(), t_sweep.end(), 0.0);
      std::snprintf(buf, sizeof(buf),
                    "\nself-calibration: %d updates over %d frame sets, %.0f ms per update, %.1f ms per frame set "
                    "on average (%.1f %% of the depth stage's time; per update %.0f ms finding the matches, %.0f ms "
                    "tracking the metric matches, %.0f ms the fits and checks)%s%s\n\n",
                    cal->updates(), cal->frameSets(), cal->updates() ? cal->totalMs() / cal->updates() : 0.0,
                    cal->frameSets() ? cal->totalMs() / cal->frameSets() : 0.0,
                    sweep_total > 0 ? 100.0 * cal->totalMs() / sweep_total : 0.0,
                    cal->updates() ? cal->totalMatchMs() / cal->updates() : 0.0,
                    cal->updates() ? cal->totalMetricMs() / cal->updates() : 0.0,
                    cal->updates() ? (cal->totalMs() - cal->totalMatchMs() - cal->totalMetricMs()) / cal->updates()
                                   : 0.0,
                    cal->startError().empty() ? "" : "; ", cal->startError().c_str());
      md << buf;
      md << "| camera | correction deg | rotation vector deg (camera frame) | residual deg | inliers | updates | "
            "refused | restarts | status |\n|---|---:|---|---:|---:|---:|---:|---:|---|\n";
      for (const auto& c : cal->state()) {
        if (c.reference) continue;
        std::snprintf(buf, sizeof(buf), "| %s | %.3f | [%.3f, %.3f, %.3f] | %.3f | %d | %d | %d | %d | %s%s |\n",
                      c.name.c_str(), c.correction_deg, c.correction_rotvec_deg.x(), c.correction_rotvec_deg.y(),
                      c.correction_rotvec_deg.z(), c.residual_deg, c.inliers, c.updates, c.refused, c.restarts,
                      c.warn ? "WARN: " : "", c.status.c_str());
        md << buf;
      }
      cli::writeTextAtomically(out + "/self_calibration.csv", [&](std::ostream& f) { f << calib_csv.str(); });
      written.push_back("self_calibration.csv");
      if (cal->changed()) {
        try {
          mapper.depthStage().saveCalibration(out + "/self_calibrated_camchain.yaml");
          written.push_back("self_calibrated_camchain.yaml");
          written.push_back("self_calibrated_camchain_mount.yaml");
        } catch (const std::exception& e) {
          not_written.push_back("self_calibrated_camchain.yaml");
          std::cerr << "offline_mapper: " << e.what() << "\n";
        }
      }
    }
    cli::writeTextAtomically(out + "/timings.csv", [&](std::ostream& f) { f << csv.str(); });
    written.push_back("timings.csv");
    cli::writeTextAtomically(out + "/timings.md", [&](std::ostream& f) { f << md.str(); });
    written.push_back("timings.md");
    if (detecting) {
      cli::writeTextAtomically(out + "/vehicles.csv", [&](std::ostream& f) { f << vehicles_csv.str(); });
      written.push_back("vehicles.csv");
    }
    std::cout << md.str();
    std::cout << "wrote " << out << "/";
    for (size_t k = 0; k < written.size(); ++k) std::cout << (k ? ", " : "") << written[k];
    std::cout << "\n";
    if (!not_written.empty()) {
      std::cout << "not written (earlier files of that name left as they were): ";
      for (size_t k = 0; k < not_written.size(); ++k) std::cout << (k ? ", " : "") << not_written[k];
      std::cout << "\n";
      return 1;
    }
  } catch (const cli::UsageError& e) {  // an option that does not fit the rig (--topic)
    std::cerr << "offline_mapper: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "\noffline_mapper: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
