// The TSDF stage without ROS: what the Tsdf nodelet runs between its
// topics, and what a tool or a test can run alone.
//   - The map (TsdfMap), its mesh (TsdfMesher) and its file (MapSession:
//     save on shutdown, the .1 backup, reload, autosave, change counting).
//   - Time: a depth stamp far older than the newest (a bag played again, a
//     clock reset; StreamTimeline) resets the time state and keeps the map,
//     or clears it with clear_map_on_time_reset; a stamp a little older than
//     the last fused frame is out of order and skipped.
//   - What is fused with a frame: the reference camera's grey image of its
//     stamp (within 1 ms; the map's intensity) and the carve regions of
//     parked vehicles that drove off (within 2 s of it).
//   - The obstacle grid around the vehicle's last fused pose; the run-time
//     settings (max_range, min_observations); the stage's diagnostics.
// Not thread-safe: the caller holds one lock around every call.
#ifndef FISHEYE_MAPPING_CORE_TSDF_FUSION_STAGE_H_
#define FISHEYE_MAPPING_CORE_TSDF_FUSION_STAGE_H_

#include <array>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/StdVector>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/common/stream_timeline.h"
#include "fisheye_mapping/core/tsdf/map_session.h"
#include "fisheye_mapping/core/tsdf/occupancy_grid.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"

namespace fisheye_mapping {

struct TsdfStageOptions {
  std::string map_file;  // absolute; empty: no persistence
  bool reload_map_on_start = false;
  bool clear_map_on_time_reset = false;
  double time_reset_threshold = 1.0;  // s; 0: never
  OccupancyGridConfig occupancy;
};

class TsdfFusionStage {
 public:
  using Log = MapSession::Log;

  // Builds the map (std::invalid_argument naming a bad setting) and, with
  // reload_map_on_start, resumes from the map file.
  TsdfFusionStage(const TsdfConfig& config, const TsdfStageOptions& options, Log log);

  // Before a frame's pose is looked up: kTimeReset (the time state was reset;
  // the pose would come from the old time line's tf) and kOutOfOrder skip it.
  enum class Verdict { kFuse, kTimeReset, kOutOfOrder };
  struct Admission {
    Verdict verdict = Verdict::kFuse;
    std::string reason;  // kTimeReset: what happened; kOutOfOrder: by how much
  };
  Admission admit(std::int64_t stamp_ns);
  // The time-reset check alone, for a frame that will not be fused (its pose
  // never came: a bag played again fails there first). True: reset.
  bool checkTimeReset(std::int64_t stamp_ns, std::string* reason);

  struct Fused {
    IntegrationStats stats;
    bool with_intensity = false;
    std::string intensity_note;  // why a grey image of the stamp was not used (else empty)
    float observation_weight = 1;  // how much the frame counted (TsdfConfig::observation_travel)
  };
  // The observation weight of a frame from camera pose T_W_C: 1 without
  // observation_travel or a previous frame, else min(1, max(travel /
  // observation_travel, turn / observation_turn)), at least
  // kMinObservationWeight, travel and turn since the previous fused frame.
  float observationWeight(const Eigen::Isometry3d& T_W_C) const;
  // Fuses one depth frame (TsdfMap::integrate; std::invalid_argument: map
  // untouched) with the grey image and carve regions of its stamp.
  Fused fuse(const cv::Mat& depth, const CameraModel& camera, const Eigen::Isometry3d& T_W_C,
             const Eigen::Isometry3d& T_W_B, std::int64_t stamp_ns);
  // Fuses held depth of an earlier fused frame (VehicleDepthHold: a vehicle
  // masked there while undecided, decided parked since) with that frame's
  // poses, observation weight, grey image and carve regions; the time state
  // and the frame counts stay as they are. nullopt, nothing fused, when no
  // frame of that stamp is among the last kRecentFramesKept fused (too old,
  // skipped, or before a time reset or clear).
  std::optional<Fused> fuseHeld(const cv::Mat& depth, const CameraModel& camera, std::int64_t stamp_ns);
  static constexpr size_t kRecentFramesKept = 64;
  size_t heldFramesFused() const { return held_frames_fused_; }
  // The reference camera's grey image (CV_8UC1; kept, the last 24).
  void addGrey(std::int64_t stamp_ns, const cv::Mat& grey);
  // The latest carve regions (world frame).
  void setCarve(std::vector<Eigen::AlignedBox3d> regions, std::int64_t stamp_ns);

  // The mesh: the blocks changed since the last call.
  std::vector<BlockIndex> updateMesh() { return mesher_.update(map_); }
  const TsdfMesher& mesher() const { return mesher_; }
  // True once after the map was cleared, loaded or reset: the viewer's mesh
  // is stale (delete it all) and the cloud must go out even if no block changed.
  bool takeMeshReset() { return std::exchange(mesh_reset_, false); }
  bool takeCloudStale() { return std::exchange(cloud_stale_, false); }

  // Run-time settings (max_range, min_observations; the rest needs a new
  // map). Returns the blocks whose mesh changed.
  std::vector<BlockIndex> reconfigure(const TsdfConfig& next);
  const TsdfConfig& config() const { return live_; }

  // The services. Saves write as MapSession / TsdfMesher say (verified; the
  // old file kept on failure); they throw std::runtime_error naming the path.
  // The exports bring the mesh up to date first: the blocks changed are returned.
  std::vector<BlockIndex> saveMesh(const std::string& path);
  std::vector<BlockIndex> saveCloud(const std::string& path);
  void saveMap(const std::string& path) { map_.save(path); }
  void loadMap(const std::string& path);  // read and checked whole before the live map is replaced
  void clear();                            // map, mesh and time state

  // The obstacle grid around the last fused vehicle pose, and that pose's z
  // (the grid lies at the vehicle's ground); nullopt before the first frame.
  std::optional<OccupancyGrid> occupancy(double* base_z);

  void autosave() { session_.autosave(map_); }
  void shutdown() { session_.shutdown(map_); }
  bool persistent() const { return session_.enabled(); }

  std::int64_t lastStamp() const { return last_stamp_ns_; }  // of the last fused frame; 0: none
  size_t framesFused() const { return frames_fused_; }
  TsdfMap& map() { return map_; }

  // Diagnostics: (name, value) pairs, and the warnings among them.
  std::vector<std::pair<std::string, std::string>> report(std::vector<std::string>* warnings) const;

 private:
  void resetMesh();
  void swapError(bool lost, const std::string& message);

  TsdfConfig live_;
  TsdfStageOptions options_;
  Log log_;
  TsdfMap map_;
  TsdfMesher mesher_;
  MapSession session_;
  StreamTimeline timeline_;
  std::int64_t last_stamp_ns_ = 0;
  struct Grey {
    std::int64_t stamp_ns;
    cv::Mat image;
  };
  std::deque<Grey> greys_;
  cv::Mat greyFor(std::int64_t stamp_ns, const CameraModel& camera, std::string* note) const;
  // The last fused frames (fuseHeld).
  struct Recent {
    std::int64_t stamp_ns;
    Eigen::Isometry3d T_W_C, T_W_B;
    float observation_weight;
  };
  std::deque<Recent, Eigen::aligned_allocator<Recent>> recent_;
  size_t held_frames_fused_ = 0;
  std::vector<Eigen::AlignedBox3d> carve_;
  std::int64_t carve_stamp_ns_ = 0;
  std::optional<Eigen::Isometry3d> last_T_W_B_;
  // The previous fused frame's camera pose (observation weights).
  std::optional<Eigen::Isometry3d> last_T_W_C_;
  double observations_ = 0;  // the fused frames' observation weights, summed
  size_t frames_fused_ = 0, frames_with_intensity_ = 0, blocks_carved_ = 0;
  std::array<size_t, 3> occupancy_cells_{};  // occupied / free / unknown of the last grid
  bool mesh_reset_ = false, cloud_stale_ = false;
  std::chrono::steady_clock::time_point last_swap_log_{};  // failed swap writes are logged every 5 s at most
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_FUSION_STAGE_H_
