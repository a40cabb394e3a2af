#include "fisheye_mapping/core/common/params.h"

#include <stdexcept>

#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fisheye_mapping {

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
