// The nodelets' own options (what is no core stage's configuration: where
// the rig comes from, frames, transports, the TSDF map's persistence, time
// resets), declared once each like the stages' parameters (ParamTable): read
// and range-checked from the private parameters, listed in
// docs/parameters.md, and the names a nodelet accepts besides its stage's.
// Plain data; no ROS types.
#ifndef FISHEYE_MAPPING_ROS_NODE_OPTIONS_H_
#define FISHEYE_MAPPING_ROS_NODE_OPTIONS_H_

#include <string>
#include <vector>

#include "fisheye_mapping/core/common/param_table.h"
#include "fisheye_mapping/core/tsdf/occupancy_grid.h"

namespace fisheye_mapping {

// Where a stage's rig comes from: `camchain` (the files ~camchain, ~mount)
// or `camera_info` (CameraInfo messages + tf).
struct RigSourceOptions {
  std::string rig_source = "camchain";
  std::string camchain;  // Kalibr camchain YAML (rig_source camchain)
  std::string mount;     // mount YAML with T_base_cam0 (rig_source camchain)
  bool fromCameraInfo() const { return rig_source == "camera_info"; }
  static const ParamTable<RigSourceOptions>& params();
};

// The time a stream may step back before the stage treats it as a time reset
// (a bag replayed, a simulation restarted); 0: never. One meaning in every
// stage: sync, depth, mask and TSDF.
struct TimeResetOptions {
  double time_reset_threshold = 1.0;  // s
  static const ParamTable<TimeResetOptions>& params();
};

// Where a stage's save services and automatic saves may write (the TSDF's
// maps, meshes and clouds, the depth stage's self-calibration): inside
// save_directory only (core/common/safe_write.h, confineSavePath).
struct SaveOptions {
  std::string save_directory = "fisheye_mapping";  // relative: against $ROS_HOME
  bool allow_any_save_path = false;                // UNSAFE: clients may write any file the node can
  static const ParamTable<SaveOptions>& params();
};

// Diagnostics (StageMonitor) of every stage.
struct DiagnosticOptions {
  double diagnostic_window = 10.0;          // s of the rate window
  double diagnostic_expected_period = 1.0;  // s between inputs; stalled after 3 of them
  std::string hardware_id;                  // empty: the node's namespace
  static const ParamTable<DiagnosticOptions>& params();
};

// fisheye_mapping/Sync (its stage: FrameSyncConfig).
struct FrameSyncNodeOptions {
  RigSourceOptions rig;
  std::string base_frame = "base_link";  // rig_source camera_info: tf parent of the cameras
  std::string image_transport = "raw";
  std::vector<std::string> camera_info_topics;  // empty: next to each image topic
  DiagnosticOptions diagnostics;
  static const ParamTable<FrameSyncNodeOptions>& params();
};

// fisheye_mapping/Depth (its stage: DepthStageConfig).
struct DepthNodeOptions {
  RigSourceOptions rig;
  std::string base_frame = "base_link";
  // The vehicle's poses (tf world_frame -> base_frame at each frame set's
  // stamp) let the self-calibration correct the translations.
  std::string world_frame = "map";
  bool publish_uniqueness = false;
  // Frame sets that may wait while the sweep works (LatestWorker's mailbox):
  // 1, live: the newest wins; a paced player with N frame sets in flight: N.
  int input_queue = 1;
  // Where save_calibration (empty request) and the save on shutdown write the
  // self-calibrated camchain (relative: inside save.save_directory); empty: no
  // save on shutdown.
  std::string self_calibration_file = "self_calibrated_camchain.yaml";
  SaveOptions save;
  TimeResetOptions time_reset;
  DiagnosticOptions diagnostics;
  static const ParamTable<DepthNodeOptions>& params();
};

// fisheye_mapping/Detector (its stage: DetectorStageConfig).
struct DetectorNodeOptions {
  std::string image_transport = "raw";
  DiagnosticOptions diagnostics;
  static const ParamTable<DetectorNodeOptions>& params();
};

// fisheye_mapping/DepthMask (its stage: DepthMaskConfig, which holds its
// time_reset_threshold).
struct DepthMaskNodeOptions {
  std::string image_transport = "raw";
  std::string world_frame = "map";  // vehicles are tracked in it (tf world_frame -> depth frame)
  DiagnosticOptions diagnostics;
  static const ParamTable<DepthMaskNodeOptions>& params();
};

// fisheye_mapping/Tsdf (its stage: TsdfConfig).
struct TsdfNodeOptions {
  RigSourceOptions rig;
  std::string world_frame = "map";
  std::string base_frame = "base_link";
  double publish_period = 1.0;  // s between mesh / cloud updates (run time)
  int queue_size = 10;
  std::string save_map_on_shutdown;  // empty: no save; relative: inside save.save_directory
  bool reload_map_on_start = false;
  double autosave_period = 0.0;  // s; 0: off
  SaveOptions save;
  bool clear_map_on_time_reset = false;
  bool intensity = true;  // subscribe `image` (the reference camera) for the map's intensity
  OccupancyGridConfig occupancy;
  double occupancy_period = 1.0;  // s between tsdf/occupancy grids; 0: none
  TimeResetOptions time_reset;
  DiagnosticOptions diagnostics;
  static const ParamTable<TsdfNodeOptions>& params();
};

// fisheye_mapping/RigTf.
struct RigTfNodeOptions {
  std::string camchain;
  std::string mount;
  DiagnosticOptions diagnostics;
  static const ParamTable<RigTfNodeOptions>& params();
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_NODE_OPTIONS_H_
