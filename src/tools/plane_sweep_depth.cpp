// plane_sweep_depth: offline plane-sweep depth with the same core as the
// nodelet (rosrun fisheye_mapping plane_sweep_depth ...).
//
// Images mode:
//   plane_sweep_depth --camchain F --mount F --reference cam0
//                     --image cam0=a.png --image cam1=b.png ... [--mask cam0=m.png]
//                     --out PREFIX [--config YAML] [--set key=value ...]
//   writes PREFIX_depth.tiff (32-bit float, range along the ray, NaN invalid),
//   PREFIX_depth.png (colour-coded inverse depth) and PREFIX_cost.tiff.
// Bag mode:
//   plane_sweep_depth --camchain F --mount F --reference cam0 --bag drive.bag
//                     --out DIR [--topic camN=/topic ...] [--max-sets N]
//   groups the rig's image topics (the camchain's rostopic, or --topic) by
//   exact stamp and writes DIR/depth_<stamp>.tiff per complete frame set.
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
#include "fisheye_mapping/ros/bag_reading.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/depth/depth_stage.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/param_registry.h"

namespace fm = fisheye_mapping;

namespace {

const char* kUsage =
    "usage: plane_sweep_depth --camchain F --mount F [--reference cam0] [--config YAML] [--set key=value]...\n"
    "         (--image CAM=FILE ... [--mask CAM=FILE ...] --out PREFIX\n"
    "          | --bag FILE --out DIR [--topic CAM=TOPIC ...] [--max-sets N])\n"
    "  --camchain F, --mount F  the rig (Kalibr camchain and mount)\n"
    "  --reference CAM      the camera whose depth is computed (default cam0)\n"
    "  --config YAML        plane-sweep parameters (as config/plane_sweep_depth.yaml)\n"
    "  --set KEY=VALUE      overrides one parameter (repeatable)\n"
    "  --image CAM=FILE     one camera's image (images mode; one per camera)\n"
    "  --mask CAM=FILE      one camera's self-mask (images mode)\n"
    "  --out PREFIX|DIR     images mode: PREFIX_depth.tiff, PREFIX_depth.png, PREFIX_cost.tiff;\n"
    "                       bag mode: DIR/depth_<stamp>.tiff per complete frame set\n"
    "  --bag FILE           bag mode: frame sets grouped by exact stamp\n"
    "  --topic CAM=TOPIC    bag mode: the camera's image topic (default: the camchain's rostopic)\n"
    "  --max-sets N         bag mode: at most N frame sets (default: all)\n"
    "  Depth is 32-bit float TIFF: metres of range along each pixel's ray, NaN invalid.\n";


std::pair<std::string, std::string> split(const std::string& kv, const std::string& what) {
  const size_t eq = kv.find('=');
  if (eq == std::string::npos || eq == 0) throw fm::cli::UsageError(what + " expects NAME=VALUE, got '" + kv + "'");
  return {kv.substr(0, eq), kv.substr(eq + 1)};
}

// The plane-sweep configuration of a YAML file (the names of
// config/plane_sweep_depth.yaml) with --set overrides, read by the same core
// function as the nodelet's.
fm::PlaneSweepConfig readConfig(const std::string& path, const std::vector<std::pair<std::string, std::string>>& sets) {
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
  fm::nodeParamSet("plane_sweep").requireKnown(fm::yamlKeys(y), path.empty() ? "--set" : path);
  const fm::PlaneSweepConfig config = fm::PlaneSweepConfig::fromParams(yaml);
  return config;
}

void writeOutputs(const std::string& prefix, const fm::DepthResult& r, const fm::PlaneSweepConfig& c) {
  fm::writeDepthTiff(prefix + "_depth.tiff", r.depth);
  fm::writeDepthTiff(prefix + "_cost.tiff", r.cost);
  fm::writeImageFile(prefix + "_depth.png", fm::colorizeDepth(r.depth, c.near, c.far));
}

}  // namespace

int main(int argc, char** argv) {
  std::map<std::string, std::string> one;
  std::vector<std::pair<std::string, std::string>> images, masks, topics, sets;
  const int rc = fm::cli::parseCommandLine("plane_sweep_depth", kUsage, [&] {
    fm::cli::forEachOption(argc, argv, 1, [&](const std::string& k, const fm::cli::NextValue& next) {
      static const std::set<std::string> kSingle = {"--camchain", "--mount", "--out", "--bag", "--reference", "--config"};
      if (k == "--image") images.push_back(split(next(), k));
      else if (k == "--mask") masks.push_back(split(next(), k));
      else if (k == "--topic") topics.push_back(split(next(), k));
      else if (k == "--set") sets.push_back(split(next(), k));
      else if (k == "--max-sets") one["max-sets"] = std::to_string(fm::cli::parseInt(k, next(), 1, 100000000));
      else if (kSingle.count(k)) one[k.substr(2)] = next();
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
    const std::string ref_name = one.count("reference") ? one["reference"] : "cam0";
    const int ref = rig.indexOf(rig.camera(ref_name).name);
    const fm::PlaneSweepConfig config = readConfig(one.count("config") ? one["config"] : "", sets);
    fm::PlaneSweep sweep(config);
    std::cerr << "plane_sweep_depth: " << sweep.backendName() << ", reference " << ref_name << "\n";
    const Eigen::Isometry3d T_base_ref = rig.cameras[ref].T_base_cam;

    if (!images.empty()) {
      std::vector<cv::Mat> img(rig.cameras.size()), mask(rig.cameras.size());
      for (const auto& [cam, path] : images) {
        const int i = rig.indexOf(rig.camera(cam).name);
        // A regular file that decodes completely (a JPEG cut short is an error, not grey pixels).
        img[i] = fm::readImageFile(path, cv::IMREAD_UNCHANGED, "--image " + cam + ":");
        fm::checkImageSize(rig.cameras[i], img[i].cols, img[i].rows);
      }
      for (const auto& [cam, path] : masks) {
        const int i = rig.indexOf(rig.camera(cam).name);
        mask[i] = fm::readImageFile(path, cv::IMREAD_GRAYSCALE, "--mask " + cam + ":");
      }
      if (img[ref].empty()) throw std::runtime_error("no --image for the reference camera " + ref_name);
      std::vector<fm::SweepView> views;
      for (size_t i = 0; i < rig.cameras.size(); ++i) {
        if (static_cast<int>(i) != ref && !img[i].empty()) views.push_back(fm::rigSweepView(rig, i, ref, img[i], mask[i]));
      }
      const fm::DepthResult r = sweep.compute(fm::rigSweepView(rig, ref, ref, img[ref], mask[ref]), views, &T_base_ref);
      for (const auto& d : r.dropped_views) std::cerr << "plane_sweep_depth: dropped " << d << "\n";
      for (const auto& w : r.warnings) std::cerr << "plane_sweep_depth: warning: " << w << "\n";
      writeOutputs(one["out"], r, config);
      std::cout << "depth: " << cv::countNonZero(r.depth == r.depth) << " valid pixels of " << r.depth.total() << ", "
                << std::fixed << std::setprecision(1) << r.total_ms << " ms; wrote " << one["out"]
                << "_depth.tiff, _depth.png, _cost.tiff\n";
      return 0;
    }

    // Bag mode.
    std::map<std::string, int> topic_cam;
    for (size_t i = 0; i < rig.cameras.size(); ++i) {
      if (!rig.cameras[i].rostopic.empty()) topic_cam[rig.cameras[i].rostopic] = static_cast<int>(i);
    }
    for (const auto& [cam, topic] : topics) {
      for (auto it = topic_cam.begin(); it != topic_cam.end();) it = it->second == rig.indexOf(cam) ? topic_cam.erase(it) : ++it;
      topic_cam[topic] = rig.indexOf(rig.camera(cam).name);
    }
    std::vector<std::string> topic_list;
    for (const auto& kv : topic_cam) topic_list.push_back(kv.first);
    rosbag::Bag bag;
    fm::openBagForReading(bag, one["bag"]);  // a bag cut short: the rosbag reindex command
    rosbag::View view(bag, rosbag::TopicQuery(topic_list));
    const size_t total_msgs = view.size();
    if (total_msgs == 0) throw std::runtime_error(one["bag"] + ": none of the rig's image topics is in the bag");
    const std::string out = one["out"];
    std::filesystem::create_directories(out);
    const int max_sets = one.count("max-sets") ? std::stoi(one["max-sets"]) : -1;
    std::map<ros::Time, std::vector<cv::Mat>> pending;
    size_t seen = 0, done = 0, incomplete = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (const rosbag::MessageInstance& m : view) {
      ++seen;
      auto msg = m.instantiate<sensor_msgs::Image>();
      if (!msg) continue;
      const int cam = topic_cam[m.getTopic()];
      auto& slot = pending[msg->header.stamp];
      slot.resize(rig.cameras.size());
      try {
        slot[cam] = fm::toCvImage(*msg, fm::ImageTarget::kSweep, m.getTopic());
      } catch (const std::exception& e) {
        std::cerr << "\nplane_sweep_depth: " << m.getTopic() << " at " << msg->header.stamp << ": " << e.what() << "\n";
      }
      bool complete = true;
      for (const auto& im : slot) complete = complete && !im.empty();
      if (!complete) continue;
      std::vector<fm::SweepView> views;
      for (size_t i = 0; i < rig.cameras.size(); ++i) {
        if (static_cast<int>(i) != ref) views.push_back(fm::rigSweepView(rig, i, ref, slot[i]));
      }
      const fm::DepthResult r = sweep.compute(fm::rigSweepView(rig, ref, ref, slot[ref]), views, &T_base_ref);
      std::ostringstream name;
      name << out << "/depth_" << msg->header.stamp.sec << "." << std::setw(9) << std::setfill('0') << msg->header.stamp.nsec;
      fm::writeDepthTiff(name.str() + ".tiff", r.depth);
      ++done;
      // Older incomplete sets will never complete (bags are in time order).
      for (auto it = pending.begin(); it != pending.end() && it->first <= msg->header.stamp;) {
        if (it->first < msg->header.stamp) ++incomplete;
        it = pending.erase(it);
      }
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::cerr << "\r[" << std::setw(3) << 100 * seen / total_msgs << "%] " << done << " depth maps, "
                << std::fixed << std::setprecision(2) << done / s << " sets/s" << std::flush;
      if (max_sets > 0 && static_cast<int>(done) >= max_sets) break;
    }
    std::cerr << "\n";
    std::cout << done << " depth maps written to " << out << " (" << incomplete + pending.size()
              << " incomplete frame sets skipped)\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "plane_sweep_depth: " << e.what() << "\n";
    return 1;
  }
}
