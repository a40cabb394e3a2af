// tsdf_benchmark: times TSDF integration on street-like 1024x544 frames.
//
//   tsdf_benchmark --out DIR [--frames N] [--threads T]
//   tsdf_benchmark --drive METRES --out DIR   (memory of one drive, alone in its process)
//
// 1. Renders N pinhole frames (1024x544, fx 400) of an analytic street drive
//    and writes them to DIR (z-depth, float32, for Open3D: frame_NNN.bin and
//    poses.txt with the camera-to-world matrix per line), then integrates the
//    same frames (as range along the ray) into our map: ms per frame.
// 2. Our fisheye path on its own: the default rig's unified camera, same drive.
// 3. Memory: process peak RSS; with --drive, the resident memory after a drive
//    of that length with the local map swapping to disk (run it for a short
//    and a long drive, each in its own process).
// scripts/bench/benchmark_tsdf runs this and Open3D on the same frames.
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/core/sim/analytic_scene.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fm = fisheye_mapping;
using fm::analytic::Scene;

namespace {

Scene streetScene(double length) {
  Scene s;
  s.min_incidence_cos = 0.0;
  // Facades on both sides with varied setbacks, 12-20 m high.
  for (double x = -20; x < length + 60; x += 12) {
    const double k = std::fmod(x * 0.37, 1.0);
    s.boxes.push_back({Eigen::Vector3d(x, 6.5 + 1.5 * k, 0), Eigen::Vector3d(x + 11.5, 12 + 1.5 * k, 12 + 8 * k)});
    s.boxes.push_back({Eigen::Vector3d(x + 3, -12 - k, 0), Eigen::Vector3d(x + 14.5, -6.5 - 2 * k, 14 + 6 * k)});
    // Parked cars, poles and round trees.
    s.boxes.push_back({Eigen::Vector3d(x + 2, 4.0, 0), Eigen::Vector3d(x + 6.5, 5.8, 1.5)});
    s.boxes.push_back({Eigen::Vector3d(x + 9, -5.0, 0), Eigen::Vector3d(x + 9.2, -4.8, 6)});
    s.spheres.push_back({Eigen::Vector3d(x + 8, 5.5, 4.0), 1.6});
  }
  return s;
}

Eigen::Isometry3d cameraAt(double x) {
  return fm::analytic::lookAt(Eigen::Vector3d(x, 0.3 * std::sin(x * 0.05), 1.6),
                              Eigen::Vector3d(x + 20, 0.3 * std::sin(x * 0.05), 0.6));
}

double residentMiB() {
  std::ifstream f("/proc/self/statm");
  long pages_total = 0, pages_resident = 0;
  f >> pages_total >> pages_resident;
  return pages_resident * static_cast<double>(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

double peakMiB() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

struct Timing {
  double mean_ms = 0, median_ms = 0, allocation_ms = 0, integration_ms = 0;
  size_t valid_pixels = 0;
};

Timing timeIntegration(fm::TsdfMap& map, const fm::CameraModel& cam, const std::vector<cv::Mat>& frames,
                       const std::vector<Eigen::Isometry3d>& poses, const cv::Mat& grey = cv::Mat()) {
  std::vector<double> ms;
  Timing t;
  for (size_t i = 0; i < frames.size(); ++i) {
    const auto start = std::chrono::steady_clock::now();
    const auto stats = map.integrate(frames[i], cam, poses[i],
                                     Eigen::Vector3d(poses[i].translation().x(), poses[i].translation().y(), 0), {},
                                     grey);
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    t.valid_pixels += stats.valid_pixels;
    t.allocation_ms += stats.allocation_ms / frames.size();
    t.integration_ms += stats.integration_ms / frames.size();
  }
  t.valid_pixels /= frames.size();
  t.mean_ms = std::accumulate(ms.begin(), ms.end(), 0.0) / ms.size();
  std::sort(ms.begin(), ms.end());
  t.median_ms = ms[ms.size() / 2];
  return t;
}

}  // namespace

int main(int argc, char** argv) {
  std::string out;
  int n_frames = 30, threads = 0;
  double drive = 0;
  const char* usage =
      "usage: tsdf_benchmark --out DIR [--frames N] [--threads T]\n"
      "       tsdf_benchmark --drive METRES --out DIR\n"
      "  --out DIR       folder for the rendered frames (frame_NNN.bin, poses.txt); created\n"
      "  --frames N      frames of the street drive, 1 to 10000 (default 30)\n"
      "  --threads T     integration threads, 0 to 1024 (default 0: the OpenMP default)\n"
      "  --drive METRES  instead: resident memory after a drive of that length, up to 100000\n";
  const int rc = fm::cli::parseCommandLine("tsdf_benchmark", usage, [&] {
    fm::cli::forEachOption(argc, argv, 1, [&](const std::string& a, const fm::cli::NextValue& next) {
      if (a == "--out") out = next();
      else if (a == "--frames") n_frames = static_cast<int>(fm::cli::parseInt(a, next(), 1, 10000));
      else if (a == "--threads") threads = static_cast<int>(fm::cli::parseInt(a, next(), 0, 1024));
      else if (a == "--drive") drive = fm::cli::parseDouble(a, next(), 0, 100000);
      else return false;
      return true;
    });
    if (out.empty()) throw fm::cli::UsageError("--out is required");
    fm::cli::prepareOutputDir("--out", out);
  });
  if (rc >= 0) return rc;
  std::filesystem::create_directories(out);
  const double step = 1.0;  // metres between frames
  const Scene scene = streetScene(n_frames * step);

  fm::Intrinsics in;
  in.width = 1024, in.height = 544, in.fx = 400, in.fy = 400, in.cx = 511.5, in.cy = 271.5;
  const fm::CameraModel pinhole = fm::CameraModel::pinhole(in);
  const fm::CameraModel fisheye = fm::CameraModel::unified(
      [] { fm::Intrinsics f; f.width = 1024, f.height = 544, f.fx = 520, f.fy = 520, f.cx = 511.5, f.cy = 271.5; return f; }(),
      0.98, -0.02, 0.004, 2e-4, -1e-4);

  if (drive > 0) {
    // One drive at 2 m steps, fisheye frames, local map swapping to disk.
    fm::TsdfConfig c;
    c.threads = threads;
    c.swap_directory = out + "/swap";
    std::filesystem::remove_all(c.swap_directory);
    const Scene long_scene = streetScene(drive);
    fm::TsdfMap map(c);
    for (double x = 0; x <= drive; x += 2.0) {
      const Eigen::Isometry3d T = cameraAt(x);
      map.integrate(long_scene.render(fisheye, T), fisheye, T, Eigen::Vector3d(x, 0, 0));
    }
    std::printf("drive %.0f m: %zu blocks in all, %zu active (%.0f MiB), process resident %.0f MiB, peak %.0f MiB\n",
                drive, map.numBlocks(), map.numActiveBlocks(), map.activeMemoryBytes() / 1048576.0, residentMiB(),
                peakMiB());
    std::filesystem::remove_all(c.swap_directory);
    return 0;
  }

  // Pinhole frames: range images for us, z-depth files for Open3D.
  std::vector<cv::Mat> frames, fisheye_frames;
  std::vector<Eigen::Isometry3d> poses;
  // Every file through the checked writer (writeFileSafely).
  std::ostringstream pose_file;
  for (int i = 0; i < n_frames; ++i) {
    const Eigen::Isometry3d T = cameraAt(i * step);
    cv::Mat range = scene.render(pinhole, T);
    cv::Mat z(range.size(), CV_32FC1);
    for (int v = 0; v < range.rows; ++v) {
      for (int u = 0; u < range.cols; ++u) {
        Eigen::Vector3d ray;
        pinhole.unproject(Eigen::Vector2d(u, v), &ray);
        const float r = range.at<float>(v, u);
        z.at<float>(v, u) = std::isfinite(r) ? static_cast<float>(r * ray.z()) : 0.0f;
      }
    }
    char name[64];
    std::snprintf(name, sizeof(name), "/frame_%03d.bin", i);
    fm::writeFileSafely(out + name, std::string_view(reinterpret_cast<const char*>(z.ptr<float>()), z.total() * 4));
    const Eigen::Matrix4d M = T.matrix();
    for (int k = 0; k < 16; ++k) pose_file << M(k / 4, k % 4) << (k == 15 ? "\n" : " ");
    frames.push_back(range);
    poses.push_back(T);
    fisheye_frames.push_back(scene.render(fisheye, T));
  }
  fm::writeFileSafely(out + "/poses.txt", pose_file.str());
  std::ostringstream intrinsics;
  intrinsics << in.width << " " << in.height << " " << in.fx << " " << in.fy << " " << in.cx << " " << in.cy << "\n";
  fm::writeFileSafely(out + "/intrinsics.txt", intrinsics.str());

  fm::TsdfConfig cfg;  // 5 cm voxels, 0.2 m truncation
  cfg.threads = threads;
  {
    fm::TsdfMap map(cfg);
    const Timing t = timeIntegration(map, pinhole, frames, poses);
    std::printf("ours pinhole: %.1f ms/frame (median %.1f; allocation %.1f, integration %.1f), %zu valid pixels/frame, %zu blocks\n",
                t.mean_ms, t.median_ms, t.allocation_ms, t.integration_ms, t.valid_pixels, map.numBlocks());
    // The intensity channel (issue 30): the same frames with a grey image.
    cv::Mat grey(in.height, in.width, CV_8UC1);
    for (int v = 0; v < grey.rows; ++v)
      for (int u = 0; u < grey.cols; ++u) grey.at<uint8_t>(v, u) = static_cast<uint8_t>((u * 7 + v * 3) % 256);
    fm::TsdfMap with_grey(cfg);
    const Timing g = timeIntegration(with_grey, pinhole, frames, poses, grey);
    std::printf("ours pinhole with intensity: %.1f ms/frame (median %.1f; integration %.1f): %.2f x the time without; "
                "block %zu bytes (voxels %zu + intensity %zu: %.3f x)\n",
                g.mean_ms, g.median_ms, g.integration_ms, g.mean_ms / t.mean_ms, sizeof(fm::VoxelBlock),
                sizeof(fm::VoxelBlock::voxels), sizeof(fm::VoxelBlock::grey),
                double(sizeof(fm::VoxelBlock)) / sizeof(fm::VoxelBlock::voxels));
  }
  try {
    fm::TsdfConfig c = cfg;
    c.integrator = fm::TsdfIntegratorKind::kOpenCl;
    fm::TsdfMap map(c);
    const Timing t = timeIntegration(map, pinhole, frames, poses);
    std::printf("ours pinhole, OpenCL integrator: %.1f ms/frame (median %.1f)\n", t.mean_ms, t.median_ms);
  } catch (const std::exception& e) {
    std::printf("ours pinhole, OpenCL integrator: not run (%s)\n", e.what());
  }
  {
    fm::TsdfMap map(cfg);
    const Timing t = timeIntegration(map, fisheye, fisheye_frames, poses);
    std::printf("ours fisheye: %.1f ms/frame (median %.1f; allocation %.1f, integration %.1f), %zu valid pixels/frame, %zu blocks\n",
                t.mean_ms, t.median_ms, t.allocation_ms, t.integration_ms, t.valid_pixels, map.numBlocks());
  }
  frames.clear();
  fisheye_frames.clear();
  std::printf("ours peak RSS: %.0f MiB\n", peakMiB());
  return 0;
}
