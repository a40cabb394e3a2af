#include "fisheye_mapping/ros/ros_params.h"

namespace fisheye_mapping {

Rig loadRigFromParams(const ros::NodeHandle& private_nh) {
  std::string camchain, mount;
  if (!private_nh.getParam("camchain", camchain) || camchain.empty()) {
    throw CalibrationError("parameter " + private_nh.resolveName("camchain") +
                           " (path of the Kalibr camchain YAML) is not set");
  }
  if (!private_nh.getParam("mount", mount) || mount.empty()) {
    throw CalibrationError("parameter " + private_nh.resolveName("mount") +
                           " (path of the mount YAML with T_base_cam0) is not set");
  }
  return loadKalibrRig(camchain, mount);
}

PlaneSweepConfig loadPlaneSweepConfig(const ros::NodeHandle& pnh) {
  PlaneSweepConfig c;
  pnh.param("fronto_planes", c.fronto_planes, c.fronto_planes);
  pnh.param("near", c.near, c.near);
  pnh.param("far", c.far, c.far);
  pnh.param("ground_planes", c.ground_planes, c.ground_planes);
  pnh.param("ground_min", c.ground_min, c.ground_min);
  pnh.param("ground_max", c.ground_max, c.ground_max);
  pnh.param("window_full", c.window_full, c.window_full);
  pnh.param("window_half", c.window_half, c.window_half);
  pnh.param("aggregation", c.aggregation, c.aggregation);
  pnh.param("best_k", c.best_k, c.best_k);
  pnh.param("subpixel", c.subpixel, c.subpixel);
  pnh.param("resolution", c.resolution, c.resolution);
  pnh.param("crop_width", c.crop_width, c.crop_width);
  pnh.param("crop_height", c.crop_height, c.crop_height);
  pnh.param("min_parallax_px", c.min_parallax_px, c.min_parallax_px);
  pnh.param("min_overlap", c.min_overlap, c.min_overlap);
  pnh.param("backend", c.backend, c.backend);
  pnh.param("device", c.device, c.device);
  DepthFilterConfig& f = c.filters;
  pnh.param("filter_cost", f.cost, f.cost);
  pnh.param("alpha_upper", f.alpha_upper, f.alpha_upper);
  pnh.param("alpha_lower", f.alpha_lower, f.alpha_lower);
  pnh.param("split_row", f.split_row, f.split_row);
  pnh.param("filter_uniqueness", f.uniqueness, f.uniqueness);
  pnh.param("max_ratio", f.max_ratio, f.max_ratio);
  pnh.param("filter_consistency", f.consistency, f.consistency);
  pnh.param("consistency_window", f.consistency_window, f.consistency_window);
  pnh.param("gamma", f.gamma, f.gamma);
  pnh.param("delta", f.delta, f.delta);
  c.validate();
  return c;
}

}  // namespace fisheye_mapping
