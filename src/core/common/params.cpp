#include "fisheye_mapping/core/common/params.h"

#include <stdexcept>

namespace fisheye_mapping {

PlaneSweepConfig planeSweepConfigFrom(const ParamSource& p) {
  PlaneSweepConfig c;
  p.get("fronto_planes", c.fronto_planes);
  p.get("near", c.near);
  p.get("far", c.far);
  p.get("ground_planes", c.ground_planes);
  p.get("ground_min", c.ground_min);
  p.get("ground_max", c.ground_max);
  p.get("window_full", c.window_full);
  p.get("window_half", c.window_half);
  p.get("aggregation", c.aggregation);
  p.get("best_k", c.best_k);
  p.get("subpixel", c.subpixel);
  p.get("resolution", c.resolution);
  p.get("crop_width", c.crop_width);
  p.get("crop_height", c.crop_height);
  p.get("min_parallax_px", c.min_parallax_px);
  p.get("min_parallax_ratio", c.min_parallax_ratio);
  p.get("min_overlap", c.min_overlap);
  p.get("backend", c.backend);
  p.get("device", c.device);
  DepthFilterConfig& f = c.filters;
  p.get("filter_texture", f.texture);
  p.get("min_texture_snr", f.min_texture_snr);
  p.get("min_noise_std", f.min_noise_std);
  p.get("filter_cost", f.cost);
  p.get("alpha_upper", f.alpha_upper);
  p.get("alpha_lower", f.alpha_lower);
  p.get("split_row", f.split_row);
  p.get("filter_uniqueness", f.uniqueness);
  p.get("max_ratio", f.max_ratio);
  p.get("filter_consistency", f.consistency);
  p.get("consistency_window", f.consistency_window);
  p.get("gamma", f.gamma);
  p.get("delta", f.delta);
  c.validate();
  return c;
}

TsdfConfig tsdfConfigFrom(const ParamSource& p) {
  TsdfConfig c;
  p.get("voxel_size", c.voxel_size);
  p.get("truncation_voxels", c.truncation_voxels);
  double max_weight = c.max_weight;
  p.get("max_weight", max_weight);
  c.max_weight = static_cast<float>(max_weight);
  p.get("min_observations", c.min_observations);
  p.get("max_range", c.max_range);
  std::vector<double> size{c.local_map_size.x(), c.local_map_size.y(), c.local_map_size.z()};
  std::vector<double> offset{c.local_map_offset.x(), c.local_map_offset.y(), c.local_map_offset.z()};
  p.get("local_map_size", size);
  p.get("local_map_offset", offset);
  if (size.size() != 3) throw std::invalid_argument("local_map_size needs 3 values");
  if (offset.size() != 3) throw std::invalid_argument("local_map_offset needs 3 values");
  c.local_map_size = Eigen::Vector3d(size[0], size[1], size[2]);
  c.local_map_offset = Eigen::Vector3d(offset[0], offset[1], offset[2]);
  p.get("swap_directory", c.swap_directory);
  p.get("integrator", c.integrator);
  p.get("opencl_device", c.opencl_device);
  c.validate();
  return c;
}

}  // namespace fisheye_mapping
