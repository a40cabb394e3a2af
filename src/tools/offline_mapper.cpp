// offline_mapper: the mapping pipeline over a rosbag without roscore, as fast
// as the machine allows: frame sets grouped by exact stamp (core FrameSetSync),
// then the core FrameSetMapper (depth stage, detector or the drive's
// ground-truth boxes, masking, TSDF fusion) with poses from the bag's /tf. The
// same core stage objects, configs and parameter names as the nodelets of
// vehicle.launch; this file only reads the bag and writes the results.
//
//   offline_mapper --bag B --camchain F --mount F --out DIR
//                  [--config vehicle.yaml] [--detector none|ground_truth|nanodet|darknet|MODEL.yaml]
//                  [--frames N] [--every K] [--world map] [--depth sweep|gt] [--quiet]
//                  [--save-depth DIR]
//
// Writes DIR/mesh.ply, DIR/cloud.pcd, DIR/cloud_all.pcd (every voxel with a
// surface, i.e. without the minimum-observation filter), DIR/timings.md (ms
// per stage) and DIR/timings.csv (one row per frame set), each under a
// temporary name renamed over the old file once complete, and prints the files
// it wrote. Exit status: 0; 1 when the run failed or a map file could not be
// written (e.g. --frames 1: nothing observed often enough for a mesh; the
// earlier file of that name stays); 2 on bad options or input paths.
// --save-depth DIR writes each fused frame set's masked depth (what the depth
// mask nodelet publishes on depth_masked) as DIR/<stamp in ns>.tiff.
// --depth gt fuses the bag's ground-truth depth of the reference camera
// (/<ref>/depth_gt) instead of the plane sweep: the reference map of the
// evaluation (moving objects masked the same way). Parameters: the stage defaults of
// config/plane_sweep_depth.yaml and config/tsdf_fusion.yaml, then the
// `plane_sweep`, `depth_mask` and `tsdf` sections of --config.
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2/buffer_core.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <numeric>
#include <optional>
#include <string>
#include <filesystem>
#include <sstream>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/mapping/frame_set_mapper.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/conversions.h"

namespace fm = fisheye_mapping;
namespace cli = fm::cli;

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

void usage() {
  std::cerr << "usage: offline_mapper --bag B --camchain F --mount F --out DIR [--config vehicle.yaml]\n"
               "       [--detector none|ground_truth|nanodet|darknet|MODEL.yaml] [--frames N] [--every K]\n"
               "       [--world map] [--depth sweep|gt] [--config-dir DIR] [--save-depth DIR] [--quiet]\n"
               "  --frames N  map at most N frame sets, N in [1, 10000000] (default: all)\n"
               "  --every K   map every K-th frame set, K in [1, 1000000] (default 1)\n"
               "  Outputs are written under temporary names and renamed once complete: a failed\n"
               "  run leaves the files of an earlier run in --out as they were.\n";
}

YAML::Node loadYaml(const std::string& path) {
  try {
    return YAML::LoadFile(path);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

// Stage defaults overlaid with the stage's section of the --config file.
YAML::Node stageParams(const std::string& defaults_file, const YAML::Node& config, const std::string& section) {
  YAML::Node merged = defaults_file.empty() ? YAML::Node(YAML::NodeType::Map) : loadYaml(defaults_file);
  if (config && config[section] && config[section].IsMap())
    for (const auto& kv : config[section]) merged[kv.first.as<std::string>()] = kv.second;
  return merged;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  std::string bag_path, camchain, mount, out, config_path, detector = "ground_truth", world = "map", depth_src = "sweep";
  std::string save_depth;
  std::string config_dir = FM_CONFIG_DIR;
  int max_frames = 0, every = 1;
  bool quiet = false;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      auto next = [&]() -> std::string {
        if (i + 1 >= argc) throw cli::UsageError(a + " needs a value");
        return argv[++i];
      };
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
      else if (a == "--quiet") quiet = true;
      else if (a == "-h" || a == "--help") {
        usage();
        return 0;
      } else {
        throw cli::UsageError("unknown argument '" + a + "'");
      }
    }
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
    if (detector != "none" && detector != "ground_truth" && detector != "nanodet" && detector != "darknet")
      cli::requireInputFile("--detector", detector);
    cli::prepareOutputDir("--out", out);
    if (!save_depth.empty()) cli::prepareOutputDir("--save-depth", save_depth);
  } catch (const cli::UsageError& e) {
    std::cerr << "offline_mapper: " << e.what() << "\n";
    usage();
    return 2;
  }
  // Temporary outputs of this run; removed when it fails.
  std::vector<std::string> partials;
  try {
    const fm::Rig rig = fm::loadKalibrRig(camchain, mount);
    const YAML::Node config = config_path.empty() ? YAML::Node() : loadYaml(config_path);
    const fm::YamlParams sweep_p(stageParams(config_dir + "/plane_sweep_depth.yaml", config, "plane_sweep"), "plane_sweep");
    const fm::YamlParams tsdf_p(stageParams(config_dir + "/tsdf_fusion.yaml", config, "tsdf"), "tsdf");
    const fm::YamlParams mask_p(stageParams("", config, "depth_mask"), "depth_mask");
    const fm::YamlParams det_p(stageParams("", config, "detector"), "detector");
    const fm::FrameSetMapperConfig mapper_cfg = fm::FrameSetMapperConfig::fromParams(sweep_p, det_p, mask_p, tsdf_p);
    std::unique_ptr<fm::Detector> det;
    if (detector != "none" && detector != "ground_truth") {
      std::string yaml = detector;
      if (detector == "nanodet") yaml = config_dir + "/detector/nanodet.yaml";
      else if (detector == "darknet") yaml = config_dir + "/detector/yolov3-tiny.yaml";
      // The detector stage's config (thresholds, DNN device of the `detector`
      // section) with the model chosen by --detector, as the nodelet loads it.
      fm::DetectorStageConfig stage = mapper_cfg.detection;
      stage.model_config = yaml;
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
    try {
      bag.open(bag_path, rosbag::bagmode::Read);
    } catch (const std::exception& e) {
      throw std::runtime_error("cannot open bag " + bag_path + ": " + e.what());
    }
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

    // Pass 2: frame sets.
    std::vector<std::string> topics;
    std::map<std::string, int> cam_of;
    for (size_t c = 0; c < rig.cameras.size(); ++c) {
      const std::string t = rig.cameras[c].rostopic.empty() ? "/" + rig.cameras[c].name + "/image_raw" : rig.cameras[c].rostopic;
      topics.push_back(t);
      cam_of[t] = int(c);
    }
    if (depth_src == "gt") {  // ground-truth depth stands in for the whole frame set
      topics = {gt_depth_topic};
      cam_of = {{gt_depth_topic, 0}};
    }
    rosbag::View images(bag, rosbag::TopicQuery(topics));
    if (images.size() == 0) throw std::runtime_error(bag_path + " has none of the topics " + topics[0] + " ...");
    size_t total_sets = images.size() / (depth_src == "gt" ? 1 : rig.cameras.size()) / every;
    if (max_frames > 0) total_sets = std::min<size_t>(total_sets, max_frames);
    fm::FrameSetSync<sensor_msgs::Image::ConstPtr> sync(depth_src == "gt" ? 1 : int(rig.cameras.size()),
                                                        fm::SyncPolicy::Exact, 0.0, 10);
    const int ref_slot = depth_src == "gt" ? 0 : ref;
    // timings.csv is written under a temporary name and renamed at the end.
    const std::string csv_tmp = cli::partialName(out + "/timings.csv");
    partials.push_back(csv_tmp);
    std::ofstream csv(csv_tmp);
    if (!csv) throw std::runtime_error("cannot write " + csv_tmp);
    csv << "stamp,sweep_ms,detect_ms,mask_ms,fuse_ms,total_ms,valid_pixels,masked_pixels\n";
    std::vector<double> t_sweep, t_det, t_mask, t_fuse, t_total;
    size_t sets_seen = 0, processed = 0, skipped_pose = 0, no_boxes = 0;
    const auto run_start = Clock::now();
    for (const rosbag::MessageInstance& m : images) {
      auto img = m.instantiate<sensor_msgs::Image>();
      if (!img) continue;
      auto done = sync.add(cam_of[m.getTopic()], std::int64_t(img->header.stamp.toNSec()), img);
      for (auto& set : done) {
        if (sets_seen++ % every != 0) continue;
        if (max_frames > 0 && int(processed) >= max_frames) break;
        const auto t0 = Clock::now();
        const ros::Time stamp = set[ref_slot]->header.stamp;
        Eigen::Isometry3d T_W_B;
        try {
          T_W_B = tf2::transformToEigen(tf.lookupTransform(world, rig.base_frame, stamp));
        } catch (const std::exception& e) {
          ++skipped_pose;
          if (!quiet) std::fprintf(stderr, "\nframe set %.3f skipped: no pose (%s)\n", stamp.toSec(), e.what());
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
        fm::FrameSetResult r;
        if (depth_src == "gt") {
          r = mapper.processDepth(fm::toDepth(*set[0], gt_depth_topic), T_W_B, boxes);
        } else {
          std::vector<cv::Mat> images;
          // Decoded as the depth nodelet decodes them (ros/conversions.h).
          for (size_t c = 0; c < set.size(); ++c)
            images.push_back(fm::toCvImageShare(set[c], fm::ImageTarget::kSweep, rig.cameras[c].name));
          r = mapper.process(images, T_W_B, boxes);
        }
        if (!save_depth.empty())
          fm::writeDepthTiff(save_depth + "/" + std::to_string(stamp.toNSec()) + ".tiff", r.depth.depth);
        const double sweep_ms = r.ms.depth_ms, det_ms = r.ms.detect_ms, mask_ms = r.ms.mask_ms, fuse_ms = r.ms.fuse_ms;
        const double total = msSince(t0);
        const fm::IntegrationStats& st = r.fusion;
        const cv::Mat& mask = r.mask;
        t_sweep.push_back(sweep_ms), t_det.push_back(det_ms), t_mask.push_back(mask_ms), t_fuse.push_back(fuse_ms),
            t_total.push_back(total);
        csv << std::fixed << stamp.toSec() << "," << sweep_ms << "," << det_ms << "," << mask_ms << "," << fuse_ms << ","
            << total << "," << st.valid_pixels << "," << cv::countNonZero(mask) << "\n";
        ++processed;
        if (!quiet) {
          const double el = std::chrono::duration<double>(Clock::now() - run_start).count();
          const int bar = total_sets ? int(30.0 * processed / total_sets) : 0;
          std::fprintf(stderr, "\r[%-30s] %zu/%zu frame sets, %.2f s/set, ETA %.0f s   ", std::string(std::min(bar, 30), '#').c_str(),
                       processed, total_sets, el / processed,
                       total_sets > processed ? el / processed * (total_sets - processed) : 0.0);
        }
      }
      if (max_frames > 0 && int(processed) >= max_frames) break;
    }
    if (!quiet) std::fprintf(stderr, "\n");
    if (processed == 0) throw std::runtime_error("no complete frame set with a pose in " + bag_path);
    const double wall = std::chrono::duration<double>(Clock::now() - run_start).count();
    mapper.finish();                   // the frame sets since the last mesh update
    mesher_all.rebuild(mapper.map());  // every block of both stores, after the last frame
    const fm::TsdfMesher& mesher = mapper.mesher();
    // Each file is written under a temporary name and renamed over the old one
    // only once complete: a failed save keeps what an earlier run wrote.
    std::vector<std::string> written, not_written;
    for (const auto& [what, save] : std::vector<std::pair<std::string, std::function<void(const std::string&)>>>{
             {"mesh.ply", [&](const std::string& p) {
                if (mesher.numTriangles() == 0)
                  throw std::runtime_error("the map has no triangle yet (nothing observed " +
                                           std::to_string(tsdf_cfg.min_observations) + " times)");
                mesher.saveMeshPly(p);
              }},
             {"cloud.pcd", [&](const std::string& p) { mesher.saveCloudPcd(p); }},
             {"cloud_all.pcd", [&](const std::string& p) { mesher_all.saveCloudPcd(p); }}}) {
      try {
        cli::writeAtomically(out + "/" + what, save);
        written.push_back(what);
      } catch (const std::exception& e) {  // e.g. nothing observed often enough: say so, keep the rest
        not_written.push_back(what);
        std::cerr << "offline_mapper: " << what << " not written: " << e.what() << "\n";
      }
    }
    const auto& s = sync.stats();
    std::ostringstream md;
    char buf[512];
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
                  "%lu incomplete sets dropped, %zu without a pose, %zu without ground-truth boxes; "
                  "sweep backend %s; map: %zu triangles, %zu cloud points.\n",
                  processed, wall, processed / wall, (unsigned long)s.dropped_incomplete, skipped_pose, no_boxes,
                  mapper.depthStage().backendName().c_str(), mesher.numTriangles(), mesher.surfaceCloud().size());
    md << buf;
    csv.close();
    if (!csv) throw std::runtime_error("cannot write " + csv_tmp + " (disk full?)");
    if (std::rename(csv_tmp.c_str(), (out + "/timings.csv").c_str()) != 0)
      throw std::runtime_error("cannot rename " + csv_tmp + " to timings.csv");
    written.push_back("timings.csv");
    cli::writeTextAtomically(out + "/timings.md", [&](std::ostream& f) { f << md.str(); });
    written.push_back("timings.md");
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
  } catch (const std::exception& e) {
    for (const auto& p : partials) std::remove(p.c_str());
    std::cerr << "\noffline_mapper: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
