#include "fisheye_mapping/ros/node_options.h"

namespace fisheye_mapping {

namespace {
using R = ParamRange;
constexpr auto kRun = ParamChange::Runtime;
}  // namespace

const ParamTable<RigSourceOptions>& RigSourceOptions::params() {
  using C = RigSourceOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("rig source");
    t.choice("rig_source", {"camchain", "camera_info"}, [](const C& c) { return c.rig_source; },
             [](C& c, const std::string& v) { c.rig_source = v; },
             "camchain: the rig from ~camchain and ~mount; camera_info: from CameraInfo messages and tf")
        .text("camchain", [](C& c) -> std::string& { return c.camchain; },
              "Kalibr camchain YAML (rig_source camchain)")
        .text("mount", [](C& c) -> std::string& { return c.mount; },
              "Mount YAML with T_base_cam0 (rig_source camchain)");
    return t;
  }();
  return t;
}

const ParamTable<TimeResetOptions>& TimeResetOptions::params() {
  using C = TimeResetOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("time reset");
    t.number("time_reset_threshold", [](C& c) -> double& { return c.time_reset_threshold; }, R::atLeast(0), "s",
             "Time a stream may step back before it is a time reset (a bag replayed); 0: never");
    return t;
  }();
  return t;
}

const ParamTable<SaveOptions>& SaveOptions::params() {
  using C = SaveOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("saves");
    t.text("save_directory", [](C& c) -> std::string& { return c.save_directory; },
           "Folder the save services and the automatic saves write into (created when missing; relative: against "
           "$ROS_HOME, ~/.ros when unset). A relative save path is taken inside it; an absolute one outside it, "
           "or one leading out of it through '..' or a link, is refused")
        .flag("allow_any_save_path", [](C& c) -> bool& { return c.allow_any_save_path; },
              "UNSAFE: let save requests write to absolute paths outside save_directory (any client on the ROS "
              "network could then overwrite any file the node may write); links, FIFOs and devices at the target "
              "are still refused or replaced, never followed");
    return t;
  }();
  return t;
}

const ParamTable<DiagnosticOptions>& DiagnosticOptions::params() {
  using C = DiagnosticOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("diagnostics");
    t.number("diagnostic_window", [](C& c) -> double& { return c.diagnostic_window; }, R::above(0), "s",
             "Window of the rates on /diagnostics")
        .number("diagnostic_expected_period", [](C& c) -> double& { return c.diagnostic_expected_period; },
                R::above(0), "s", "Expected time between inputs; the input is stalled after 3 of them")
        .text("hardware_id", [](C& c) -> std::string& { return c.hardware_id; },
              "Hardware id on /diagnostics; empty: the node's namespace");
    return t;
  }();
  return t;
}

const ParamTable<FrameSyncNodeOptions>& FrameSyncNodeOptions::params() {
  using C = FrameSyncNodeOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("sync node");
    t.include(RigSourceOptions::params(), [](C& c) -> RigSourceOptions& { return c.rig; })
        .text("base_frame", [](C& c) -> std::string& { return c.base_frame; },
              "rig_source camera_info: the tf frame the cameras are mounted on")
        .text("image_transport", [](C& c) -> std::string& { return c.image_transport; },
              "image_transport of the camera images (raw, compressed, ...)")
        .names("camera_info_topics", [](C& c) -> std::vector<std::string>& { return c.camera_info_topics; },
               "rig_source camera_info: one CameraInfo topic per camera; empty: camera_info next to each image topic")
        .include(DiagnosticOptions::params(), [](C& c) -> DiagnosticOptions& { return c.diagnostics; });
    return t;
  }();
  return t;
}

const ParamTable<DepthNodeOptions>& DepthNodeOptions::params() {
  using C = DepthNodeOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("depth node");
    t.include(RigSourceOptions::params(), [](C& c) -> RigSourceOptions& { return c.rig; })
        .text("base_frame", [](C& c) -> std::string& { return c.base_frame; },
              "The vehicle frame: the cameras' mounts (rig_source camera_info) and the poses looked up in "
              "world_frame")
        .text("world_frame", [](C& c) -> std::string& { return c.world_frame; },
              "Fixed frame of the vehicle's poses (tf world_frame -> base_frame at each frame set's stamp): the "
              "self-calibration corrects the translations from the motion between frame sets; without the "
              "transform only the rotations")
        .flag("publish_uniqueness", [](C& c) -> bool& { return c.publish_uniqueness; },
              "Also publish depth/uniqueness (best / second-best cost)")
        .number("input_queue", [](C& c) -> int& { return c.input_queue; }, R::between(1, 16), "",
                "Frame sets that may wait while the sweep works: 1 (live) drops a waiting set when a newer one "
                "comes (counted as busy); a paced player with N frame sets in flight needs N (vehicle.launch "
                "sets it)")
        .text("self_calibration_file", [](C& c) -> std::string& { return c.self_calibration_file; },
              "Self-calibrated camchain written by save_calibration and on shutdown (its mount beside it as "
              "<name>_mount.yaml; the old ones kept as .1; relative: inside save_directory; empty: no save on "
              "shutdown)")
        .include(SaveOptions::params(), [](C& c) -> SaveOptions& { return c.save; })
        .include(TimeResetOptions::params(), [](C& c) -> TimeResetOptions& { return c.time_reset; })
        .include(DiagnosticOptions::params(), [](C& c) -> DiagnosticOptions& { return c.diagnostics; });
    return t;
  }();
  return t;
}

const ParamTable<DetectorNodeOptions>& DetectorNodeOptions::params() {
  using C = DetectorNodeOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("detector node");
    t.text("image_transport", [](C& c) -> std::string& { return c.image_transport; },
           "image_transport of the input images")
        .include(DiagnosticOptions::params(), [](C& c) -> DiagnosticOptions& { return c.diagnostics; });
    return t;
  }();
  return t;
}

const ParamTable<DepthMaskNodeOptions>& DepthMaskNodeOptions::params() {
  using C = DepthMaskNodeOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("depth_mask node");
    t.text("image_transport", [](C& c) -> std::string& { return c.image_transport; },
           "image_transport of the depth images")
        .text("world_frame", [](C& c) -> std::string& { return c.world_frame; },
              "Fixed frame the vehicles are tracked in (tf from it to the depth's frame)")
        .include(DiagnosticOptions::params(), [](C& c) -> DiagnosticOptions& { return c.diagnostics; });
    return t;
  }();
  return t;
}

const ParamTable<TsdfNodeOptions>& TsdfNodeOptions::params() {
  using C = TsdfNodeOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("tsdf node");
    t.include(RigSourceOptions::params(), [](C& c) -> RigSourceOptions& { return c.rig; })
        .text("world_frame", [](C& c) -> std::string& { return c.world_frame; },
              "Fixed frame of the map (tf parent of base_frame)")
        .text("base_frame", [](C& c) -> std::string& { return c.base_frame; },
              "The vehicle's frame: the local map box follows it")
        .number("publish_period", [](C& c) -> double& { return c.publish_period; }, R::above(0), "s",
                "Time between mesh / cloud updates", kRun)
        .number("queue_size", [](C& c) -> int& { return c.queue_size; }, R::atLeast(1), "",
                "Depth frames waiting for their pose")
        .text("save_map_on_shutdown", [](C& c) -> std::string& { return c.save_map_on_shutdown; },
              "Map file written on shutdown (SIGINT, SIGTERM, unload) and by autosave; relative: inside "
              "save_directory (an absolute path must lie inside it too); empty: no save")
        .flag("reload_map_on_start", [](C& c) -> bool& { return c.reload_map_on_start; },
              "Start from save_map_on_shutdown (or its .1) when it holds a valid map")
        .number("autosave_period", [](C& c) -> double& { return c.autosave_period; }, R::atLeast(0), "s",
                "Time between saves to save_map_on_shutdown while the map changes; 0: off")
        .include(SaveOptions::params(), [](C& c) -> SaveOptions& { return c.save; })
        .flag("clear_map_on_time_reset", [](C& c) -> bool& { return c.clear_map_on_time_reset; },
              "A time reset clears the map (else it is kept)")
        .flag("intensity", [](C& c) -> bool& { return c.intensity; },
              "Subscribe `image` (the reference camera's images, remapped in vehicle.launch) and fuse their grey "
              "into the voxels (the mesh's intensity colour); false: no image traffic, no intensity")
        .number("occupancy_period", [](C& c) -> double& { return c.occupancy_period; }, R::atLeast(0), "s",
                "Time between tsdf/occupancy grids (nav_msgs/OccupancyGrid around the vehicle); 0: none")
        .include(OccupancyGridConfig::params(), [](C& c) -> OccupancyGridConfig& { return c.occupancy; })
        .include(TimeResetOptions::params(), [](C& c) -> TimeResetOptions& { return c.time_reset; })
        .include(DiagnosticOptions::params(), [](C& c) -> DiagnosticOptions& { return c.diagnostics; });
    return t;
  }();
  return t;
}

const ParamTable<RigTfNodeOptions>& RigTfNodeOptions::params() {
  using C = RigTfNodeOptions;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("rig_tf node");
    t.text("camchain", [](C& c) -> std::string& { return c.camchain; }, "Kalibr camchain YAML")
        .text("mount", [](C& c) -> std::string& { return c.mount; }, "Mount YAML with T_base_cam0")
        .include(DiagnosticOptions::params(), [](C& c) -> DiagnosticOptions& { return c.diagnostics; });
    return t;
  }();
  return t;
}

}  // namespace fisheye_mapping
