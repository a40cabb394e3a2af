// refine_rig: corrects the extrinsic rotations of a rig's support cameras
// relative to cam0 from image features of a logged drive (core refineRig: the
// same matcher and estimator as the depth stage's online self-calibration,
// pooled over the chosen frame sets). The depth stage does this by itself
// while driving; this tool is for a calibration to keep or inspect.
//
//   refine_rig --bag B --camchain F --mount F --out CORRECTED_CAMCHAIN.yaml
//              [--mount-out M.yaml] [--frames N] [--every K]
//              [--self-masks cam0=PNG,cam1=PNG,...] [--refine-translation]
//              [--min-inliers N]
//
// Frame sets: the images of every camera (its camchain rostopic, else
// /camN/image_raw) grouped by identical stamps; every K-th set, N of them
// (default 10). Prints a table of the angular epipolar residuals (degrees)
// before and after per camera. Exit status: 0 written; 1 error; 2 usage
// error, or nothing to write (too few matches, or no camera improved: then
// no file is written).
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Image.h>

#include <cstdio>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "cli.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/ros/bag_reading.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/core/camera/rig_refinement.h"

namespace fm = fisheye_mapping;

namespace {

const char* kUsage =
    "usage: refine_rig --bag B --camchain F --mount F --out CORRECTED_CAMCHAIN.yaml [--mount-out M.yaml]\n"
    "       [--frames N] [--every K] [--self-masks cam0=PNG,cam1=PNG,...]\n"
    "       [--refine-translation] [--min-inliers N]\n"
    "  --bag B                 the logged drive (images of every camera and their stamps)\n"
    "  --camchain F, --mount F the rig to correct (Kalibr camchain and mount)\n"
    "  --out FILE              the corrected camchain\n"
    "  --mount-out FILE        also write the mount that goes with the corrected camchain\n"
    "  --frames N              frame sets to use, 1 to 1000000 (default 10)\n"
    "  --every K               use every K-th frame set, 1 to 1000000 (default 1)\n"
    "  --self-masks LIST       NAME=PNG per camera: where the car body hides the scene\n"
    "  --refine-translation    refine the translations too (default: rotations only)\n"
    "  --min-inliers N         matches a camera needs, at least 5 (default 20)\n";

[[noreturn]] void usageError(const std::string& why) {
  std::cerr << "refine_rig: " << why << "\n" << kUsage;
  std::exit(2);
}

int positiveInt(const std::string& flag, const std::string& s) {
  size_t used = 0;
  long v = 0;
  try {
    v = std::stol(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || s.empty() || v < 1 || v > 1000000)
    throw fm::cli::UsageError(flag + " expects a positive integer, got '" + s + "'");
  return int(v);
}

}  // namespace

int main(int argc, char** argv) {
  std::string bag_path, camchain, mount, out, mount_out, masks_arg;
  int max_frames = 10, every = 1;
  fm::RigRefinementConfig cfg;
  const int rc = fm::cli::parseCommandLine("refine_rig", kUsage, [&] {
    fm::cli::forEachOption(argc, argv, 1, [&](const std::string& a, const fm::cli::NextValue& next) {
      if (a == "--bag") bag_path = next();
      else if (a == "--camchain") camchain = next();
      else if (a == "--mount") mount = next();
      else if (a == "--out") out = next();
      else if (a == "--mount-out") mount_out = next();
      else if (a == "--frames") max_frames = positiveInt(a, next());
      else if (a == "--every") every = positiveInt(a, next());
      else if (a == "--self-masks") masks_arg = next();
      else if (a == "--refine-translation") cfg.refine_translation = true;
      else if (a == "--min-inliers") cfg.min_inliers = positiveInt(a, next());
      else return false;
      return true;
    });
    if (bag_path.empty() || camchain.empty() || mount.empty() || out.empty())
      throw fm::cli::UsageError("--bag, --camchain, --mount and --out are required");
    if (cfg.min_inliers < 5) throw fm::cli::UsageError("--min-inliers must be >= 5");
  });
  if (rc >= 0) return rc;

  try {
    const fm::Rig rig = fm::loadKalibrRig(camchain, mount);
    const int n_cams = int(rig.cameras.size());
    const int ref = 0;
    if (n_cams < 2) throw std::runtime_error(camchain + ": a rig of one camera has nothing to refine");

    std::vector<cv::Mat> masks;
    if (!masks_arg.empty()) {
      masks.resize(n_cams);
      std::stringstream ss(masks_arg);
      std::string item;
      while (std::getline(ss, item, ',')) {
        const size_t eq = item.find('=');
        if (eq == std::string::npos || eq == 0 || eq + 1 == item.size())
          usageError("--self-masks expects NAME=PNG items separated by commas, got '" + item + "'");
        const std::string name = item.substr(0, eq), path = item.substr(eq + 1);
        const int c = rig.indexOf(name);
        if (c < 0) usageError("--self-masks: no camera '" + name + "' in " + camchain);
        masks[c] = cv::imread(path, cv::IMREAD_GRAYSCALE);
        if (masks[c].empty()) throw std::runtime_error("cannot read self-mask " + path);
      }
    }

    rosbag::Bag bag;
    fm::openBagForReading(bag, bag_path);  // a bag cut short: the rosbag reindex command
    std::vector<std::string> topics;
    std::map<std::string, int> cam_of;
    for (int c = 0; c < n_cams; ++c) {
      const std::string t =
          rig.cameras[c].rostopic.empty() ? "/cam" + std::to_string(c) + "/image_raw" : rig.cameras[c].rostopic;
      topics.push_back(t);
      cam_of[t] = c;
    }
    rosbag::View images(bag, rosbag::TopicQuery(topics));
    if (images.size() == 0) throw std::runtime_error(bag_path + " has none of the topics " + topics[0] + " ...");
    fm::FrameSetSync<sensor_msgs::Image::ConstPtr> sync(n_cams, fm::SyncPolicy::Exact, 0.0, 10);
    std::vector<std::vector<cv::Mat>> sets;
    size_t seen = 0;
    for (const rosbag::MessageInstance& m : images) {
      auto img = m.instantiate<sensor_msgs::Image>();
      if (!img) continue;
      for (auto& set : sync.add(cam_of[m.getTopic()], std::int64_t(img->header.stamp.toNSec()), img)) {
        if (seen++ % every != 0) continue;
        std::vector<cv::Mat> mats;
        for (int c = 0; c < n_cams; ++c) {
          mats.push_back(fm::toGrey(*set[c], topics[c]));  // throws naming the topic and the encoding
        }
        sets.push_back(std::move(mats));
      }
      if (int(sets.size()) >= max_frames) break;
    }
    if (sets.empty()) throw std::runtime_error("no complete frame set (all " + std::to_string(n_cams) + " cameras, one stamp) in " + bag_path);

    const fm::RigRefinementResult r = fm::refineRig(rig, ref, sets, masks, cfg);
    std::printf("%zu frame sets; residuals: RMS angular epipolar residual over the inliers, degrees\n", sets.size());
    std::printf("held out: truncated RMS residual of each half's fit on the other half's matches (the test of "
                "\"better\")\n");
    std::printf("%-8s %-16s %8s %8s %8s %12s %12s %12s %12s %12s  %s\n", "camera", "status", "matches", "candid.",
                "inliers", "rms before", "rms after", "held out bef", "held out aft", "correction",
                "axis (camera frame)");
    for (const auto& c : r.cameras) {
      if (c.status == fm::CameraRefinement::Status::kReference) {
        std::printf("%-8s %-16s\n", c.name.c_str(), "reference");
        continue;
      }
      std::printf("%-8s %-16s %8d %8d %8d %12.4f %12.4f %12.4f %12.4f %12.4f  [%.3f %.3f %.3f]", c.name.c_str(),
                  fm::toString(c.status), c.matches, c.candidates, c.inliers, c.rms_before_deg, c.rms_after_deg,
                  c.heldout_before_deg, c.heldout_after_deg, c.correction_deg, c.correction_axis.x(),
                  c.correction_axis.y(), c.correction_axis.z());
      if (cfg.refine_translation && c.status == fm::CameraRefinement::Status::kApplied)
        std::printf("  translation direction %.4f deg", c.translation_change_deg);
      if (!c.message.empty()) std::printf("  (%s)", c.message.c_str());
      std::printf("\n");
    }
    std::fflush(stdout);
    if (r.applied() == 0) {
      bool too_few = true;
      for (const auto& c : r.cameras)
        if (c.status == fm::CameraRefinement::Status::kNotImproved) too_few = false;
      std::cerr << "refine_rig: "
                << (too_few ? "too few feature matches in every camera (night, lens cap, a static car?)"
                            : "no camera's residual improved")
                << "; nothing written\n";
      return 2;
    }
    // Each file written beside its target, checked and renamed into place
    // (writeFileSafely); the mount only when asked for.
    const fm::KalibrRigText text = fm::kalibrRigText(r.rig);
    fm::writeFileSafely(out, text.camchain);
    if (!mount_out.empty()) fm::writeFileSafely(mount_out, text.mount);
    std::printf("corrected %d of %d cameras; wrote %s%s%s\n", r.applied(), n_cams - 1, out.c_str(),
                mount_out.empty() ? "" : " and ", mount_out.c_str());
  } catch (const std::exception& e) {
    std::cerr << "refine_rig: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
