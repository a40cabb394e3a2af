#include "fisheye_mapping/core/tsdf/tsdf_config.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "fisheye_mapping/core/common/params.h"

namespace fisheye_mapping {

TsdfIntegratorKind parseTsdfIntegratorKind(const std::string& name) {
  if (name == "cpu") return TsdfIntegratorKind::kCpu;
  if (name == "opencl") return TsdfIntegratorKind::kOpenCl;
  throw std::invalid_argument("TsdfConfig.integrator must be 'cpu' or 'opencl', got '" + name + "'");
}

const char* toString(TsdfIntegratorKind kind) {
  switch (kind) {
    case TsdfIntegratorKind::kCpu:
      return "cpu";
    case TsdfIntegratorKind::kOpenCl:
      return "opencl";
  }
  return "?";
}

void TsdfConfig::validate() const {
  auto positive = [](const char* name, double v) {
    if (!(v > 0.0) || !std::isfinite(v)) {
      std::ostringstream msg;
      msg << "TsdfConfig." << name << " must be positive, got " << v;
      throw std::invalid_argument(msg.str());
    }
  };
  positive("voxel_size", voxel_size);
  positive("truncation_voxels", truncation_voxels);
  positive("max_weight", max_weight);
  positive("local_map_size.x", local_map_size.x());
  positive("local_map_size.y", local_map_size.y());
  positive("local_map_size.z", local_map_size.z());
  if (!local_map_offset.allFinite()) throw std::invalid_argument("TsdfConfig.local_map_offset must be finite");
  if (min_observations < 1) throw std::invalid_argument("TsdfConfig.min_observations must be >= 1");
  if (!(max_range >= 0.0)) throw std::invalid_argument("TsdfConfig.max_range must be >= 0 (0: no limit)");
  if (threads < 0) throw std::invalid_argument("TsdfConfig.threads must be >= 0");
  if (integrator != TsdfIntegratorKind::kCpu && integrator != TsdfIntegratorKind::kOpenCl)
    throw std::invalid_argument("TsdfConfig.integrator: not an integrator (" + std::to_string(int(integrator)) + ")");
}

TsdfConfig TsdfConfig::fromParams(const ParamSource& p, TsdfConfig base) {
  TsdfConfig c = std::move(base);
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
  if (std::string v; p.get("integrator", v)) c.integrator = parseTsdfIntegratorKind(v);
  p.get("threads", c.threads);
  p.get("opencl_device", c.opencl_device);
  c.validate();
  return c;
}

}  // namespace fisheye_mapping
