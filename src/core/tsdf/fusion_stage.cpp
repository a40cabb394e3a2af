#include "fisheye_mapping/core/tsdf/fusion_stage.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

namespace fisheye_mapping {

namespace {
constexpr size_t kGreysKept = 24;  // the depth stage is slower than the camera; held depth comes seconds late
constexpr std::int64_t kGreyMatchNs = 1000000;  // a grey image is the depth frame's within 1 ms
constexpr std::int64_t kCarveWithinNs = 2000000000;  // carve regions apply to frames within 2 s
}  // namespace

TsdfFusionStage::TsdfFusionStage(const TsdfConfig& config, const TsdfStageOptions& options, Log log)
    : live_(config),
      options_(options),
      log_(log),
      map_(config),
      mesher_(config.min_observations),
      session_(options.map_file, std::move(log)),
      timeline_(1, options.time_reset_threshold) {
  options_.occupancy.validate();
  // Without a log, the map's own report (stderr) stays.
  if (log_) map_.setSwapErrorCallback([this](bool lost, const std::string& message) { swapError(lost, message); });
  if (session_.start(map_, options.reload_map_on_start)) resetMesh();
}

bool TsdfFusionStage::checkTimeReset(std::int64_t stamp_ns, std::string* reason) {
  const StreamTimeline::Event ev = timeline_.observe(0, stamp_ns);
  if (ev.kind != StreamTimeline::Kind::kReset) return false;
  *reason = ev.reason;
  last_stamp_ns_ = 0;
  last_T_W_C_.reset();
  recent_.clear();
  if (options_.clear_map_on_time_reset) {
    map_.clear();
    resetMesh();
    session_.changed();
  }
  return true;
}

TsdfFusionStage::Admission TsdfFusionStage::admit(std::int64_t stamp_ns) {
  Admission a;
  if (checkTimeReset(stamp_ns, &a.reason)) {
    a.verdict = Verdict::kTimeReset;
  } else if (last_stamp_ns_ != 0 && stamp_ns < last_stamp_ns_) {
    a.verdict = Verdict::kOutOfOrder;
    a.reason = "stamp " + std::to_string((last_stamp_ns_ - stamp_ns) * 1e-9) + " s older than the last fused frame";
  }
  return a;
}

float TsdfFusionStage::observationWeight(const Eigen::Isometry3d& T_W_C) const {
  const TsdfConfig& c = map_.config();
  if (!(c.observation_travel > 0.0) || !last_T_W_C_) return 1.0f;
  const double travel = (T_W_C.translation() - last_T_W_C_->translation()).norm();
  const double turn_deg =
      Eigen::AngleAxisd(last_T_W_C_->linear().transpose() * T_W_C.linear()).angle() * 180.0 / M_PI;
  const double w = std::max(travel / c.observation_travel, turn_deg / c.observation_turn);
  return static_cast<float>(std::clamp(w, double(kMinObservationWeight), 1.0));
}

TsdfFusionStage::Fused TsdfFusionStage::fuse(const cv::Mat& depth, const CameraModel& camera,
                                             const Eigen::Isometry3d& T_W_C, const Eigen::Isometry3d& T_W_B,
                                             std::int64_t stamp_ns) {
  Fused out;
  const cv::Mat grey = greyFor(stamp_ns, camera, &out.intensity_note);
  std::vector<Eigen::AlignedBox3d> carve;
  if (!carve_.empty() && std::llabs(stamp_ns - carve_stamp_ns_) <= kCarveWithinNs) carve = carve_;
  out.observation_weight = observationWeight(T_W_C);
  out.stats = map_.integrate(depth, camera, T_W_C, T_W_B.translation(), carve, grey, out.observation_weight);
  if (out.stats.blocks_lost && log_) {
    log_(true, "frame " + std::to_string(stamp_ns * 1e-9) + ": " + std::to_string(out.stats.blocks_lost) +
                   " swapped blocks could not be read back and are lost (" + std::to_string(map_.numLostBlocks()) +
                   " so far)");
  }
  out.with_intensity = !grey.empty();
  frames_with_intensity_ += out.with_intensity;
  blocks_carved_ += out.stats.blocks_carved;
  observations_ += out.observation_weight;
  last_T_W_B_ = T_W_B;
  last_T_W_C_ = T_W_C;
  last_stamp_ns_ = stamp_ns;
  ++frames_fused_;
  recent_.push_back({stamp_ns, T_W_C, T_W_B, out.observation_weight});
  while (recent_.size() > kRecentFramesKept) recent_.pop_front();
  session_.changed();
  return out;
}

cv::Mat TsdfFusionStage::greyFor(std::int64_t stamp_ns, const CameraModel& camera, std::string* note) const {
  for (auto it = greys_.rbegin(); it != greys_.rend(); ++it) {
    if (std::llabs(it->stamp_ns - stamp_ns) > kGreyMatchNs) continue;
    if (it->image.cols != camera.width() || it->image.rows != camera.height()) {
      *note = "intensity image is " + std::to_string(it->image.cols) + "x" + std::to_string(it->image.rows) +
              ", the depth camera " + std::to_string(camera.width()) + "x" + std::to_string(camera.height()) +
              ": fused without intensity";
      return cv::Mat();
    }
    return it->image;
  }
  return cv::Mat();
}

std::optional<TsdfFusionStage::Fused> TsdfFusionStage::fuseHeld(const cv::Mat& depth, const CameraModel& camera,
                                                                std::int64_t stamp_ns) {
  auto it = std::find_if(recent_.rbegin(), recent_.rend(), [&](const Recent& r) { return r.stamp_ns == stamp_ns; });
  if (it == recent_.rend()) return std::nullopt;
  Fused out;
  const cv::Mat grey = greyFor(stamp_ns, camera, &out.intensity_note);
  std::vector<Eigen::AlignedBox3d> carve;
  if (!carve_.empty() && std::llabs(stamp_ns - carve_stamp_ns_) <= kCarveWithinNs) carve = carve_;
  out.observation_weight = it->observation_weight;
  out.stats = map_.integrate(depth, camera, it->T_W_C, it->T_W_B.translation(), carve, grey, out.observation_weight);
  out.with_intensity = !grey.empty();
  blocks_carved_ += out.stats.blocks_carved;
  ++held_frames_fused_;
  session_.changed();
  return out;
}

void TsdfFusionStage::swapError(bool lost, const std::string& message) {
  if (lost) return log_(true, message);  // once per block: it is gone afterwards
  const auto now = std::chrono::steady_clock::now();
  if (last_swap_log_ != std::chrono::steady_clock::time_point{} && now - last_swap_log_ < std::chrono::seconds(5)) return;
  last_swap_log_ = now;
  log_(true, message + " (" + std::to_string(map_.numSwapWriteFailures()) + " swap writes failed so far)");
}

void TsdfFusionStage::addGrey(std::int64_t stamp_ns, const cv::Mat& grey) {
  greys_.push_back({stamp_ns, grey});
  while (greys_.size() > kGreysKept) greys_.pop_front();
}

void TsdfFusionStage::setCarve(std::vector<Eigen::AlignedBox3d> regions, std::int64_t stamp_ns) {
  carve_ = std::move(regions);
  carve_stamp_ns_ = stamp_ns;
}

std::vector<BlockIndex> TsdfFusionStage::reconfigure(const TsdfConfig& next) {
  std::vector<BlockIndex> changed;
  map_.setMaxRange(next.max_range);  // checked first: throws before anything changed
  if (next.min_observations != live_.min_observations) {
    mesher_.setMinObservations(next.min_observations);
    changed = mesher_.rebuild(map_);
    cloud_stale_ = true;
  }
  live_.max_range = next.max_range;
  live_.min_observations = next.min_observations;
  return changed;
}

std::vector<BlockIndex> TsdfFusionStage::saveMesh(const std::string& path) {
  std::vector<BlockIndex> changed = mesher_.update(map_);
  MeshExportOptions options;
  options.coloring = live_.colour;
  mesher_.saveMeshPly(path, options);
  return changed;
}

std::vector<BlockIndex> TsdfFusionStage::saveCloud(const std::string& path) {
  std::vector<BlockIndex> changed = mesher_.update(map_);
  mesher_.saveCloudPcd(path);
  return changed;
}

void TsdfFusionStage::loadMap(const std::string& path) {
  map_.load(path);
  session_.changed();
  resetMesh();
}

void TsdfFusionStage::clear() {
  map_.clear();
  resetMesh();
  last_stamp_ns_ = 0;
  last_T_W_C_.reset();
  recent_.clear();
  timeline_.reset();
  session_.changed();
}

std::optional<OccupancyGrid> TsdfFusionStage::occupancy(double* base_z) {
  if (!last_T_W_B_) return std::nullopt;
  OccupancyGrid grid = computeOccupancyGrid(map_, last_T_W_B_->translation(), options_.occupancy, live_.min_observations);
  occupancy_cells_ = {grid.occupied, grid.free, grid.unknown};
  if (base_z) *base_z = last_T_W_B_->translation().z();
  return grid;
}

void TsdfFusionStage::resetMesh() {
  mesher_.clear();
  mesh_reset_ = true;
  cloud_stale_ = true;
}

std::vector<std::pair<std::string, std::string>> TsdfFusionStage::report(std::vector<std::string>* warnings) const {
  const size_t lost = map_.numLostBlocks(), write_failures = map_.numSwapWriteFailures();
  if (lost) warnings->push_back("swapped blocks lost");
  if (write_failures) warnings->push_back("swap writes failed (blocks kept in RAM)");
  if (session_.savesFailed()) warnings->push_back("saves failed");
  auto num = [](double v) {
    std::string s = std::to_string(v);
    s.erase(s.find_last_not_of('0') + 1);
    if (!s.empty() && s.back() == '.') s.pop_back();
    return s;
  };
  std::vector<std::pair<std::string, std::string>> r = {
      {"frames fused", std::to_string(frames_fused_)},
      {"lost swapped blocks", std::to_string(lost)},
      {"swap write failures", std::to_string(write_failures)},
      {"blocks", std::to_string(map_.numBlocks())},
      {"active blocks", std::to_string(map_.numActiveBlocks())},
      {"saves to save_map_on_shutdown", std::to_string(session_.savesOk())},
      {"failed saves", std::to_string(session_.savesFailed())},
      {"max_range (m)", num(live_.max_range)},
      {"min_observations", std::to_string(live_.min_observations)},
      {"frames fused with intensity", std::to_string(frames_with_intensity_)},
      {"blocks fused in front of the surface (free_space_carving)", std::to_string(blocks_carved_)},
      {"observations fused (frames weighted by travel, observation_travel)", num(std::round(observations_ * 10) / 10)},
      {"occupancy cells occupied / free / unknown", std::to_string(occupancy_cells_[0]) + " / " +
                                                        std::to_string(occupancy_cells_[1]) + " / " +
                                                        std::to_string(occupancy_cells_[2])},
  };
  // The mesh as last built (built while someone looks at it, or for an export).
  size_t triangles = 0, points = 0, mesh_bytes = 0;
  for (const auto& kv : mesher_.blocks()) {
    const BlockOutput& o = kv.second;
    triangles += o.triangles.size() / 3;
    points += o.surface_points.size();
    mesh_bytes += o.triangles.capacity() * sizeof(Eigen::Vector3f) + o.triangle_grey.capacity() +
                  o.surface_points.capacity() * sizeof(Eigen::Vector3f) + o.surface_grey.capacity();
  }
  r.emplace_back("mesh triangles", std::to_string(triangles));
  r.emplace_back("surface points", std::to_string(points));
  // What the map itself holds: its voxel blocks in RAM and the mesh's vertices
  // (scripts/checks/soak tells a growing map from a leak with them).
  r.emplace_back("voxel memory (MB)", num(std::round(map_.memoryBytes() / 1048576.0 * 10) / 10));
  r.emplace_back("mesh memory (MB)", num(std::round(mesh_bytes / 1048576.0 * 10) / 10));
  if (const std::string e = session_.lastError(); !e.empty()) r.emplace_back("last save error", e);
  return r;
}

}  // namespace fisheye_mapping
