// plane_sweep_depth: offline plane-sweep depth through the core depth stage
// (DepthStage: the nodelet's views, self-masks and online rotation
// self-calibration) (rosrun fisheye_mapping plane_sweep_depth ...).
//
// Images mode:
//   plane_sweep_depth --camchain F --mount F --reference cam0
//                     --image cam0=a.png --image cam1=b.png ... [--mask cam0=m.png]
//                     --out PREFIX [--config YAML] [--set key=value ...]
//   writes PREFIX_depth.tiff (32-bit float, range along the ray, NaN invalid),
//   PREFIX_depth.png (colour-coded inverse depth) and PREFIX_cost.tiff; with a
//   self-calibration correction, PREFIX_self_calibrated_camchain.yaml (+ _mount).
// Bag mode:
//   plane_sweep_depth --camchain F --mount F --reference cam0 --bag drive.bag
//                     --out DIR [--topic camN=/topic ...] [--max-sets N] [--sync exact|approximate]
//   groups the rig's image topics (the camchain's rostopic, or --topic; raw or
//   <topic>/compressed) into frame sets with the core FrameSetSync (the sync
//   nodelet's) and writes DIR/depth_<stamp>.tiff per frame set, and
//   DIR/self_calibrated_camchain.yaml (+ _mount) when the self-calibration
//   corrected the rig.
#include <chrono>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <set>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Image.h>
#include <yaml-cpp/yaml.h>

#include "cli.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/depth/depth_stage.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/bag_reading.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/param_registry.h"

namespace fm = fisheye_mapping;

namespace {

const char* kUsage =
    "usage: plane_sweep_depth --camchain F --mount F [--reference cam0] [--config YAML] [--set key=value]...\n"
    "         [--mask CAM=FILE ...] (--image CAM=FILE ... --out PREFIX\n"
    "          | --bag FILE --out DIR [--topic CAM=TOPIC ...] [--max-sets N] [--sync exact|approximate]\n"
    "            [--sync-tolerance S])\n"
    "  --camchain F, --mount F  the rig (Kalibr camchain and mount), the calibration as given\n"
    "  --reference CAM      the camera whose depth is computed (default: the config's reference_camera, cam0)\n"
    "  --config YAML        depth-stage parameters (as config/depth.yaml: the sweep, support_cameras,\n"
    "                       self_masks, self_calibration_*)\n"
    "  --set KEY=VALUE      overrides one parameter (repeatable)\n"
    "  --image CAM=FILE     one camera's image (images mode; one per camera)\n"
    "  --mask CAM=FILE      one camera's self-mask (0 where it sees the car; as self_masks)\n"
    "  --out PREFIX|DIR     images mode: PREFIX_depth.tiff, PREFIX_depth.png, PREFIX_cost.tiff;\n"
    "                       bag mode: DIR/depth_<stamp>.tiff per frame set;\n"
    "                       both: the self-calibrated camchain when the rig was corrected\n"
    "                       (PREFIX_self_calibrated_camchain.yaml, DIR/self_calibrated_camchain.yaml)\n"
    "  --bag FILE           bag mode: the images grouped into frame sets as the sync nodelet groups them\n"
    "  --topic CAM=TOPIC    bag mode: the camera's image topic (default: the camchain's rostopic, else\n"
    "                       /CAM/image_raw; <topic>/compressed is read when the bag has only that)\n"
    "  --max-sets N         bag mode: at most N frame sets (default: all)\n"
    "  --sync POLICY        bag mode: exact (default) or approximate stamps\n"
    "  --sync-tolerance S   bag mode: largest stamp spread of an approximate set (default 0.005 s)\n"
    "  The online rotation self-calibration is on, as in the nodelet (self_calibration; off:\n"
    "  --set self_calibration=false): the supporting cameras' rotations are corrected from the first\n"
    "  frame set on (self_calibration_first_set), and the depth is swept with the corrected rig.\n"
    "  Depth is 32-bit float TIFF: metres of range along each pixel's ray, NaN invalid.\n";

// The depth stage's configuration of a YAML file (the names of
// config/depth.yaml) with --set overrides, read by the same core
// function as the nodelet's.
fm::DepthStageConfig readConfig(const std::string& path, const std::vector<std::pair<std::string, std::string>>& sets) {
  YAML::Node y(YAML::NodeType::Map);
  if (!path.empty()) {
    try {
      y = YAML::LoadFile(path);
    } catch (const YAML::Exception& e) {
      throw std::runtime_error(path + ": " + e.what());
    }
    if (!y.IsMap()) throw std::runtime_error(path + ": expected a map of parameters");
  }
  for (const auto& [k, v] : sets) y[k] = YAML::Load(v);
  const fm::YamlParams yaml(y, path.empty() ? "--set" : path);
  // Every name the depth nodelet declares is known (the same file configures
  // it); anything else is an error naming the key and the known ones.
  fm::nodeParamSet("depth").requireKnown(fm::yamlKeys(y), path.empty() ? "--set" : path);
  return fm::DepthStageConfig::fromParams(yaml);
}

void writeOutputs(const std::string& prefix, const fm::DepthResult& r, const fm::PlaneSweepConfig& c) {
  fm::writeDepthTiff(prefix + "_depth.tiff", r.depth);
  fm::writeDepthTiff(prefix + "_cost.tiff", r.cost);
  fm::writeImageFile(prefix + "_depth.png", fm::colorizeDepth(r.depth, c.near, c.far));
}

// The self-calibration's state, one line per supporting camera, and the
// corrected camchain written to `camchain` when the rig was corrected.
void reportCalibration(const fm::DepthStage& stage, const std::string& camchain) {
  const fm::OnlineRigCalibrator* cal = stage.selfCalibration();
  if (!cal) return;
  for (const auto& c : cal->state()) {
    if (c.reference) continue;
    std::cout << "self-calibration " << c.name << ": correction " << std::fixed << std::setprecision(3)
              << c.correction_deg << " deg, " << (c.warn ? "WARN " : "") << c.status << "\n";
  }
  if (!cal->lastNote().empty()) std::cout << "self-calibration: " << cal->lastNote() << "\n";
  if (cal->changed()) {
    stage.saveCalibration(camchain);
    std::cout << "self-calibration: wrote " << camchain << " and " << fm::OnlineRigCalibrator::savedMountPath(camchain)
              << "\n";
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::map<std::string, std::string> one;
  std::vector<std::pair<std::string, std::string>> images, masks, topics, sets;
  std::optional<fm::SyncPolicy> sync_policy;
  std::optional<double> sync_tolerance;
  const int rc = fm::cli::parseCommandLine("plane_sweep_depth", kUsage, [&] {
    fm::cli::forEachOption(argc, argv, 1, [&](const std::string& k, const fm::cli::NextValue& next) {
      static const std::set<std::string> kSingle = {"--camchain", "--mount", "--out", "--bag", "--reference", "--config"};
      if (k == "--image") images.push_back(fm::cli::parseNameValue(k, next()));
      else if (k == "--mask") masks.push_back(fm::cli::parseNameValue(k, next()));
      else if (k == "--topic") topics.push_back(fm::cli::parseNameValue(k, next()));
      else if (k == "--set") sets.push_back(fm::cli::parseNameValue(k, next()));
      else if (k == "--max-sets") one["max-sets"] = std::to_string(fm::cli::parseInt(k, next(), 1, 100000000));
      else if (k == "--sync-tolerance") sync_tolerance = fm::cli::parseDouble(k, next(), 0.0, 1.0);
      else if (k == "--sync") {
        const std::string v = next();
        try {
          sync_policy = fm::parseSyncPolicy(v);
        } catch (const std::invalid_argument&) {
          throw fm::cli::UsageError("--sync must be exact or approximate, got '" + v + "'");
        }
      } else if (kSingle.count(k)) one[k.substr(2)] = next();
      else return false;
      return true;
    });
    for (const char* req : {"camchain", "mount", "out"}) {
      if (!one.count(req)) throw fm::cli::UsageError(std::string("--") + req + " is required");
    }
    if (images.empty() == !one.count("bag"))
      throw fm::cli::UsageError("give either --image CAM=FILE ... or --bag FILE");
    // One image (and one mask) per camera: a repeated camera is a mistake, not a choice.
    for (const auto* list : {&images, &masks}) {
      std::set<std::string> seen;
      for (const auto& [cam, path] : *list)
        if (!seen.insert(cam).second)
          throw fm::cli::UsageError(std::string(list == &images ? "--image" : "--mask") + " " + cam +
                                    "= given twice (one per camera)");
    }
  });
  if (rc >= 0) return rc;
  try {
    const fm::Rig rig = fm::loadKalibrRig(one["camchain"], one["mount"]);
    fm::DepthStageConfig config = readConfig(one.count("config") ? one["config"] : "", sets);
    if (one.count("reference")) config.reference_camera = rig.camera(one["reference"]).name;
    for (const auto& [cam, path] : masks) {
      const std::string name = rig.camera(cam).name;
      // Read here first: its errors name the option (the stage reads it again).
      fm::readImageFile(path, cv::IMREAD_GRAYSCALE, "--mask " + cam + ":");
      config.self_masks[name] = path;
    }
    config.validate();
    fm::DepthStage stage(rig, config);
    const std::string ref_name = rig.cameras[stage.reference()].name;
    std::cerr << "plane_sweep_depth: " << stage.backendName() << ", reference " << ref_name << ", self-calibration "
              << (stage.selfCalibration() ? "on" : "off") << "\n";

    if (!images.empty()) {
      std::vector<cv::Mat> img(rig.cameras.size());
      for (const auto& [cam, path] : images) {
        const int i = rig.indexOf(rig.camera(cam).name);
        // A regular file that decodes completely (a JPEG cut short is an error, not grey pixels).
        img[i] = fm::readImageFile(path, cv::IMREAD_UNCHANGED, "--image " + cam + ":");
        fm::checkImageSize(rig.cameras[i], img[i].cols, img[i].rows);
      }
      if (img[stage.reference()].empty()) throw std::runtime_error("no --image for the reference camera " + ref_name);
      const fm::DepthResult r = stage.compute(img);
      for (const auto& d : r.dropped_views) std::cerr << "plane_sweep_depth: dropped " << d << "\n";
      for (const auto& w : r.warnings) std::cerr << "plane_sweep_depth: warning: " << w << "\n";
      writeOutputs(one["out"], r, stage.sweepConfig());
      std::cout << "depth: " << cv::countNonZero(r.depth == r.depth) << " valid pixels of " << r.depth.total() << ", "
                << std::fixed << std::setprecision(1) << r.total_ms << " ms; wrote " << one["out"]
                << "_depth.tiff, _depth.png, _cost.tiff\n";
      reportCalibration(stage, one["out"] + "_self_calibrated_camchain.yaml");
      return 0;
    }

    // Bag mode: each camera's topic (--topic, else the camchain's rostopic,
    // else /<cam>/image_raw; <topic>/compressed when the bag has only that).
    std::vector<std::string> cam_topics;
    for (const auto& cam : rig.cameras) cam_topics.push_back(cam.rostopic.empty() ? "/" + cam.name + "/image_raw" : cam.rostopic);
    for (const auto& [cam, topic] : topics) cam_topics[rig.indexOf(rig.camera(cam).name)] = topic;
    for (size_t c = 0; c < cam_topics.size(); ++c)
      for (size_t d = 0; d < c; ++d)
        if (cam_topics[c] == cam_topics[d])
          throw fm::cli::UsageError("cameras " + rig.cameras[d].name + " and " + rig.cameras[c].name + " both read " +
                                    cam_topics[c] + " (give each its own with --topic)");
    rosbag::Bag bag;
    fm::openBagForReading(bag, one["bag"]);  // a bag cut short: the rosbag reindex command
    cam_topics = fm::imageTopicsInBag(bag, cam_topics);
    std::map<std::string, int> topic_cam;
    for (size_t c = 0; c < cam_topics.size(); ++c) topic_cam[cam_topics[c]] = int(c);
    rosbag::View view(bag, rosbag::TopicQuery(cam_topics));
    const size_t total_msgs = view.size();
    if (total_msgs == 0) throw std::runtime_error(one["bag"] + ": none of the rig's image topics is in the bag");
    const std::string out = one["out"];
    std::filesystem::create_directories(out);
    const int max_sets = one.count("max-sets") ? std::stoi(one["max-sets"]) : -1;
    fm::FrameSyncConfig sync_cfg;
    if (sync_policy) sync_cfg.policy = *sync_policy;
    if (sync_tolerance) sync_cfg.max_interval = *sync_tolerance;
    sync_cfg.validate();
    fm::FrameSetSync<fm::BagImage> sync(int(rig.cameras.size()), sync_cfg.policy, sync_cfg.max_interval,
                                        std::size_t(sync_cfg.queue_size), sync_cfg.time_reset_threshold);
    size_t seen = 0, done = 0, undecodable = 0;
    bool stopped = false;
    std::set<std::string> not_images, told;
    const auto t0 = std::chrono::steady_clock::now();
    for (const rosbag::MessageInstance& m : view) {
      ++seen;
      const std::optional<fm::BagImage> msg = fm::BagImage::of(m);
      if (!msg) {
        if (not_images.insert(m.getTopic()).second)
          std::cerr << "\nplane_sweep_depth: " << m.getTopic() << " holds " << m.getDataType()
                    << ", not sensor_msgs/Image or CompressedImage: ignored\n";
        continue;
      }
      for (auto& set : sync.add(topic_cam[m.getTopic()], std::int64_t(msg->header().stamp.toNSec()), *msg)) {
        const ros::Time stamp = set[stage.reference()].header().stamp;
        std::vector<cv::Mat> imgs;
        try {
          for (size_t c = 0; c < set.size(); ++c) imgs.push_back(set[c].sweepImage(cam_topics[c]));
        } catch (const std::exception& e) {
          ++undecodable;
          std::cerr << "\nplane_sweep_depth: frame set " << stamp << " skipped: undecodable image: " << e.what() << "\n";
          continue;
        }
        const fm::DepthResult r = stage.compute(imgs);
        // Each dropped view and warning once (they repeat from set to set).
        for (const auto& d : r.dropped_views)
          if (told.insert("dropped " + d).second) std::cerr << "\nplane_sweep_depth: dropped " << d << "\n";
        for (const auto& w : r.warnings)
          if (told.insert("warning: " + w).second) std::cerr << "\nplane_sweep_depth: warning: " << w << "\n";
        std::ostringstream name;
        name << out << "/depth_" << stamp.sec << "." << std::setw(9) << std::setfill('0') << stamp.nsec;
        fm::writeDepthTiff(name.str() + ".tiff", r.depth);
        ++done;
        const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::cerr << "\r[" << std::setw(3) << 100 * seen / total_msgs << "%] " << done << " depth maps, " << std::fixed
                  << std::setprecision(2) << done / s << " sets/s" << std::flush;
        if (max_sets > 0 && int(done) >= max_sets) {
          stopped = true;
          break;
        }
      }
      if (stopped) break;
    }
    if (!stopped) sync.finish();
    std::cerr << "\n";
    const auto& st = sync.stats();
    std::cout << done << " depth maps written to " << out;
    if (stopped) std::cout << " (--max-sets reached)";
    else
      std::cout << " (of the " << st.sets() << " frame sets in the bag: " << st.dropped_incomplete << " incomplete, "
                << st.sets_backwards << " stamps backwards, " << st.sets_duplicate << " duplicate stamp, "
                << st.sets_stale << " old timeline, " << undecodable << " undecodable image)";
    std::cout << "\n";
    reportCalibration(stage, out + "/self_calibrated_camchain.yaml");
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "plane_sweep_depth: " << e.what() << "\n";
    return 1;
  }
}
