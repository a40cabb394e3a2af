// depth_eval: evaluates the plane-sweep depth stage.
//
//   depth_eval synthetic --camchain F --mount F --out DIR [--preset urban|forest]
//              [--seed N] [--frames N] [--start S] [--step S] [--backend auto|native|opencl|cpu]
//              [--device D] [--max-range M]
//     Renders the rig on a synthetic drive (the same world as make_drive) and
//     compares depth with the exact rendered range of the reference camera
//     (cam0): full / half / multi-scale without filters (paper Fig. 3), each
//     filter added in turn (Fig. 5), 3 outer / 3 central / 5 cameras (Fig. 6).
//     Writes DIR/depth_frames.csv (one row per frame and configuration),
//     DIR/depth_summary.md and colour-coded PNGs of the first frame.
//
//   depth_eval vcharge --data DIR --camera left|right --out DIR
//     Motion stereo on the V-Charge fisheye sequence (PlaneSweepLib's test
//     data): frames 0-4 of one camera, frame 2 as reference. Writes our depth
//     (TIFF + colour PNG) and DIR/vcharge_<camera>_compare.png: reference
//     image | PlaneSweepLib's result | ours, for a visual check.
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "fisheye_mapping/core/depth_image.h"
#include "fisheye_mapping/core/plane_sweep.h"
#include "fisheye_mapping/core/rig.h"
#include "fisheye_mapping/core/synthetic_world.h"

namespace fm = fisheye_mapping;

namespace {

[[noreturn]] void usage(const std::string& msg) {
  std::cerr << "depth_eval: " << msg << "\n"
            << "usage: depth_eval synthetic --camchain F --mount F --out DIR [--preset urban|forest] [--seed N]\n"
            << "                  [--frames N] [--start S] [--step S] [--backend auto|native|opencl|cpu] [--device D]\n"
            << "                  [--max-range M]\n"
            << "       depth_eval vcharge --data DIR --camera left|right --out DIR [--device D]\n";
  std::exit(2);
}

std::map<std::string, std::string> parseArgs(int argc, char** argv, int first) {
  std::map<std::string, std::string> a;
  for (int i = first; i < argc; ++i) {
    const std::string k = argv[i];
    if (k.rfind("--", 0) != 0 || i + 1 >= argc) usage("bad argument '" + k + "'");
    a[k.substr(2)] = argv[++i];
  }
  return a;
}

std::string get(const std::map<std::string, std::string>& a, const std::string& k, const std::string& def = "") {
  auto it = a.find(k);
  if (it != a.end()) return it->second;
  if (def.empty()) usage("--" + k + " is required");
  return def;
}

struct Row {
  std::string config;
  int frame;
  fm::DepthErrorStats e;
  double ms;
};

int runSynthetic(const std::map<std::string, std::string>& a) {
  const fm::Rig rig = fm::loadKalibrRig(get(a, "camchain"), get(a, "mount"));
  const std::string out = get(a, "out");
  std::filesystem::create_directories(out);
  const int frames = std::stoi(get(a, "frames", "8"));
  const double start = std::stod(get(a, "start", "2.0")), step = std::stod(get(a, "step", "1.0"));
  const double max_range = std::stod(get(a, "max-range", "60"));
  fm::synth::WorldConfig wc;
  wc.preset = get(a, "preset", "urban");
  wc.seed = static_cast<uint32_t>(std::stoul(get(a, "seed", "1")));
  wc.route_length = wc.speed * (start + step * frames) + 80;
  const fm::synth::World world(wc);
  std::vector<std::vector<Eigen::Vector3f>> rays;
  for (const auto& c : rig.cameras) rays.push_back(fm::pixelRays(c.model));

  fm::PlaneSweepConfig base;
  base.backend = get(a, "backend", "auto");
  base.device = get(a, "device", "-");
  if (base.device == "-") base.device.clear();
  fm::DepthFilterConfig none;
  none.cost = none.uniqueness = none.consistency = false;
  auto configured = [&](const std::string& resolution, const fm::DepthFilterConfig& f) {
    fm::PlaneSweepConfig c = base;
    c.resolution = resolution;
    c.filters = f;
    return c;
  };
  fm::PlaneSweep full(configured("full", none)), half(configured("half", none)),
      multi(configured("multiscale", none)), filtered(configured("multiscale", base.filters));
  std::cerr << "depth_eval: backend " << multi.backendName() << "\n";
  const int ref = 0;
  const Eigen::Isometry3d T_base_ref = rig.cameras[ref].T_base_cam;
  // Fig. 6 camera sets: the reference plus its supporting cameras.
  const std::vector<std::pair<std::string, std::vector<int>>> sets = {
      {"3 outer cameras", {3, 4}}, {"3 central cameras", {1, 2}}, {"5 cameras", {1, 2, 3, 4}}};
  for (const auto& s : sets) {
    for (int c : s.second) {
      if (c >= static_cast<int>(rig.cameras.size())) usage("the rig needs 5 cameras for the camera-set comparison");
    }
  }

  std::vector<Row> rows;
  std::ofstream csv(out + "/depth_frames.csv");
  csv << "frame,time_s,config,median_m,mean_m,median_beyond_15m_m,coverage,ms\n";
  auto record = [&](int f, double t, const std::string& name, const cv::Mat& depth, const cv::Mat& truth, double ms) {
    Row r{name, f, fm::depthError(depth, truth, cv::Mat(), 15.0, max_range), ms};
    rows.push_back(r);
    csv << f << "," << t << ",\"" << name << "\"," << r.e.median << "," << r.e.mean << "," << r.e.median_far << ","
        << r.e.coverage() << "," << ms << "\n";
    std::cerr << "  frame " << f << "  " << std::left << std::setw(34) << name << std::right << " median "
              << std::fixed << std::setprecision(3) << r.e.median << " m  mean " << r.e.mean << " m  coverage "
              << r.e.coverage() << "  " << std::setprecision(1) << ms << " ms\n";
  };
  for (int f = 0; f < frames; ++f) {
    const double t = start + step * f;
    const Eigen::Isometry3d T_W_B = world.egoPose(t);
    std::vector<cv::Mat> images;
    cv::Mat truth;
    for (size_t c = 0; c < rig.cameras.size(); ++c) {
      auto frame = world.render(rig.cameras[c].model, rays[c], T_W_B * rig.cameras[c].T_base_cam, t,
                                (static_cast<uint64_t>(wc.seed) << 32) ^ (f * 64 + c));
      images.push_back(frame.image);
      if (static_cast<int>(c) == ref) truth = frame.depth;
    }
    auto views = [&](const std::vector<int>& ids) {
      std::vector<fm::SweepView> v;
      for (int i : ids) v.push_back(fm::rigSweepView(rig, i, ref, images[i]));
      return v;
    };
    const fm::SweepView ref_view = fm::rigSweepView(rig, ref, ref, images[ref]);
    const auto all = views({1, 2, 3, 4});
    const fm::DepthResult rf = full.compute(ref_view, all, &T_base_ref);
    const fm::DepthResult rh = half.compute(ref_view, all, &T_base_ref);
    const fm::DepthResult rm = multi.compute(ref_view, all, &T_base_ref);
    if (f == 0) {
      for (const auto& n : rm.used_views) std::cerr << "depth_eval: matching " << n << "\n";
      for (const auto& n : rm.dropped_views) std::cerr << "depth_eval: dropped " << n << "\n";
    }
    record(f, t, "full resolution", rf.raw_depth, truth, rf.total_ms);
    record(f, t, "half resolution", rh.raw_depth, truth, rh.total_ms);
    record(f, t, "multi-scale", rm.raw_depth, truth, rm.total_ms);
    // Fig. 5: filters added in turn on the same multi-scale sweep.
    fm::DepthFilterConfig fc = none;
    fc.cost = true;
    const cv::Mat d_cost = fm::applyDepthFilters(fc, rm.raw_depth, rm.cost, rm.uniqueness);
    fc.uniqueness = true;
    const cv::Mat d_uniq = fm::applyDepthFilters(fc, rm.raw_depth, rm.cost, rm.uniqueness);
    fc.consistency = true;
    const cv::Mat d_all = fm::applyDepthFilters(fc, rm.raw_depth, rm.cost, rm.uniqueness);
    record(f, t, "multi-scale + cost filter", d_cost, truth, rm.total_ms);
    record(f, t, "+ uniqueness filter", d_uniq, truth, rm.total_ms);
    record(f, t, "+ consistency filter", d_all, truth, rm.total_ms);
    // Fig. 6: camera sets, multi-scale with all filters.
    for (const auto& s : sets) {
      const fm::DepthResult r = filtered.compute(ref_view, views(s.second), &T_base_ref);
      record(f, t, s.first, r.depth, truth, r.total_ms);
    }
    if (f == 0) {
      const double near = base.near, far = base.far;
      cv::imwrite(out + "/frame0_reference.png", images[ref]);
      cv::imwrite(out + "/frame0_truth.png", fm::colorizeDepth(truth, near, far));
      cv::imwrite(out + "/frame0_full.png", fm::colorizeDepth(rf.raw_depth, near, far));
      cv::imwrite(out + "/frame0_half.png", fm::colorizeDepth(rh.raw_depth, near, far));
      cv::imwrite(out + "/frame0_multiscale.png", fm::colorizeDepth(rm.raw_depth, near, far));
      cv::imwrite(out + "/frame0_multiscale_filtered.png", fm::colorizeDepth(d_all, near, far));
    }
  }

  // Summary: means over frames of the per-frame figures.
  std::vector<std::string> order;
  std::map<std::string, std::vector<const Row*>> by;
  for (const auto& r : rows) {
    if (!by.count(r.config)) order.push_back(r.config);
    by[r.config].push_back(&r);
  }
  auto avg = [&](const std::string& c, auto field) {
    double s = 0;
    int n = 0;
    for (const Row* r : by[c]) {
      const double v = field(*r);
      if (std::isfinite(v)) s += v, ++n;
    }
    return n ? s / n : NAN;
  };
  std::ostringstream md;
  md << std::fixed;
  md << "| configuration | median error [m] | mean error [m] | median error beyond 15 m [m] | coverage | ms per frame |\n"
     << "|---|---:|---:|---:|---:|---:|\n";
  for (const auto& c : order) {
    md << "| " << c << " | " << std::setprecision(3) << avg(c, [](const Row& r) { return r.e.median; }) << " | "
       << avg(c, [](const Row& r) { return r.e.mean; }) << " | "
       << avg(c, [](const Row& r) { return r.e.median_far; }) << " | " << std::setprecision(3)
       << avg(c, [](const Row& r) { return r.e.coverage(); }) << " | " << std::setprecision(0)
       << avg(c, [](const Row& r) { return r.ms; }) << " |\n";
  }
  const double med_raw = avg("multi-scale", [](const Row& r) { return r.e.median; });
  const double mean_raw = avg("multi-scale", [](const Row& r) { return r.e.mean; });
  const double med_filt = avg("+ consistency filter", [](const Row& r) { return r.e.median; });
  const double mean_filt = avg("+ consistency filter", [](const Row& r) { return r.e.mean; });
  const double far_full = avg("full resolution", [](const Row& r) { return r.e.median_far; });
  const double far_half = avg("half resolution", [](const Row& r) { return r.e.median_far; });
  const double far_multi = avg("multi-scale", [](const Row& r) { return r.e.median_far; });
  auto verdict = [](bool ok) { return ok ? "met" : "NOT met"; };
  md << std::setprecision(1) << "\nChecks (issue minimums):\n"
     << "- filters cut the median error by " << 100 * (1 - med_filt / med_raw) << " % (minimum 40 %): "
     << verdict(med_filt <= 0.6 * med_raw) << "\n"
     << "- filters cut the mean error by " << 100 * (1 - mean_filt / mean_raw) << " % (minimum 60 %): "
     << verdict(mean_filt <= 0.4 * mean_raw) << "\n"
     << std::setprecision(3) << "- median error beyond 15 m: multi-scale " << far_multi << " m, full " << far_full
     << " m, half " << far_half << " m; within 10 % of full: " << verdict(far_multi <= 1.1 * far_full)
     << "; below half: " << verdict(far_multi < far_half) << "\n";
  md << "\n" << frames << " frames of the " << wc.preset << " preset (seed " << wc.seed << "), reference cam0, errors "
     << "over pixels with a true range up to " << max_range << " m; backend " << multi.backendName() << ".\n";
  std::ofstream(out + "/depth_summary.md") << md.str();
  std::cout << md.str();
  return 0;
}

// ---------------------------------------------------------------------------
Eigen::Isometry3d systemPose(const std::string& poses_path, long long time_us) {
  std::ifstream in(poses_path);
  if (!in) throw std::runtime_error(poses_path + ": cannot read");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    long long t;
    double yaw, pitch, roll, x, y, z;
    if (!(ss >> t >> yaw >> pitch >> roll >> x >> y >> z)) throw std::runtime_error(poses_path + ": bad line '" + line + "'");
    if (t != time_us) continue;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
    T.translation() = Eigen::Vector3d(x, y, z);
    return T;
  }
  throw std::runtime_error(poses_path + ": no pose at time " + std::to_string(time_us) + " us");
}

int runVcharge(const std::map<std::string, std::string>& a) {
  const std::string data = get(a, "data"), camera = get(a, "camera"), out = get(a, "out");
  const std::string dir = data + "/" + camera;
  std::filesystem::create_directories(out);
  std::ifstream list(dir + "/images.txt");
  if (!list) throw std::runtime_error(dir + "/images.txt: cannot read");
  std::vector<std::string> names;
  for (std::string n; std::getline(list, n) && names.size() < 5;) {
    if (!n.empty()) names.push_back(n);
  }
  if (names.size() < 5) throw std::runtime_error(dir + "/images.txt: fewer than 5 images");
  std::vector<cv::Mat> images;
  std::vector<Eigen::Isometry3d> T_W_C;
  fm::Rig rig;
  for (const auto& n : names) {
    cv::Mat im = cv::imread(dir + "/" + n, cv::IMREAD_UNCHANGED);
    if (im.empty()) throw std::runtime_error(dir + "/" + n + ": cannot read image");
    if (rig.cameras.empty()) rig = fm::loadPslCalibration(dir + "/calib.txt", im.cols, im.rows, camera);
    const long long t = std::stoll(n.substr(n.find_last_of('_') + 1));
    T_W_C.push_back(systemPose(dir + "/system_poses.txt", t) * rig.cameras[0].T_base_cam);
    images.push_back(im);
  }
  fm::PlaneSweepConfig config;
  config.device = get(a, "device", "-");
  if (config.device == "-") config.device.clear();
  config.ground_planes = 0;  // the system frame's ground is not known here
  config.near = 0.4;  // PlaneSweepLib's reference run: 0.4 m (the camera looks down at the road)
  config.far = 100.0;
  config.min_parallax_px = 0.0;  // ~0.2 m between frames: small but all we have
  config.aggregation = "best_k";  // frames before and after: one of them sees occluded points
  fm::PlaneSweep sweep(config);
  const int ref = 2;
  fm::SweepView rv{names[ref], rig.cameras[0].model, Eigen::Isometry3d::Identity(), images[ref], cv::Mat()};
  std::vector<fm::SweepView> supports;
  for (int i = 0; i < 5; ++i) {
    if (i == ref) continue;
    supports.push_back({names[i], rig.cameras[0].model, T_W_C[ref].inverse() * T_W_C[i], images[i], cv::Mat()});
  }
  const fm::DepthResult r = sweep.compute(rv, supports, nullptr);
  fm::writeDepthTiff(out + "/vcharge_" + camera + "_depth.tiff", r.depth);
  const cv::Mat ours = fm::colorizeDepth(r.depth, config.near, config.far);
  const cv::Mat ours_raw = fm::colorizeDepth(r.raw_depth, config.near, config.far);
  cv::imwrite(out + "/vcharge_" + camera + "_depth.png", ours);
  // Side by side: reference | PlaneSweepLib | ours unfiltered | ours filtered.
  std::vector<cv::Mat> tiles;
  cv::Mat refc;
  cv::cvtColor(images[ref].channels() == 1 ? images[ref] : images[ref], refc,
               images[ref].channels() == 1 ? cv::COLOR_GRAY2BGR : cv::COLOR_BGRA2BGR);
  tiles.push_back(refc);
  const std::string psl = data + "/reference_psl_zncc/" + camera + "/grayscaleZNCC/BestK/invDepthCol.png";
  cv::Mat pslimg = cv::imread(psl, cv::IMREAD_COLOR);
  if (!pslimg.empty()) {
    cv::resize(pslimg, pslimg, refc.size());
    tiles.push_back(pslimg);
  } else {
    std::cerr << "depth_eval: " << psl << " not found, comparison without it\n";
  }
  tiles.push_back(ours_raw);
  tiles.push_back(ours);
  cv::Mat row;
  cv::hconcat(tiles, row);
  cv::resize(row, row, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
  cv::imwrite(out + "/vcharge_" + camera + "_compare.png", row);
  std::cout << "vcharge " << camera << ": reference " << names[ref] << ", " << r.used_views.size()
            << " supporting frames, " << std::fixed << std::setprecision(1) << r.total_ms << " ms, "
            << cv::countNonZero(r.depth == r.depth) << " valid pixels after filtering ("
            << cv::countNonZero(r.raw_depth == r.raw_depth) << " before)\n"
            << "wrote " << out << "/vcharge_" << camera << "_compare.png (reference | PlaneSweepLib BestK | ours "
            << "unfiltered | ours filtered)\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) usage("missing mode");
  const std::string mode = argv[1];
  const auto a = parseArgs(argc, argv, 2);
  try {
    if (mode == "synthetic") return runSynthetic(a);
    if (mode == "vcharge") return runVcharge(a);
    usage("unknown mode '" + mode + "'");
  } catch (const std::exception& e) {
    std::cerr << "depth_eval: " << e.what() << "\n";
    return 1;
  }
}
