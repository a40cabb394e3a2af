#include "fisheye_mapping/core/tsdf/tsdf_config.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "fisheye_mapping/core/common/param_table.h"

namespace fisheye_mapping {

TsdfIntegratorKind parseTsdfIntegratorKind(const std::string& name) {
  if (name == "cpu") return TsdfIntegratorKind::kCpu;
  if (name == "opencl") return TsdfIntegratorKind::kOpenCl;
  throw std::invalid_argument("TsdfConfig.integrator must be 'cpu' or 'opencl', got '" + name + "'");
}

MeshColoring parseMeshColoring(const std::string& name) {
  if (name == "intensity") return MeshColoring::kIntensity;
  if (name == "height") return MeshColoring::kHeight;
  if (name == "normal") return MeshColoring::kNormal;
  if (name == "none") return MeshColoring::kNone;
  throw std::invalid_argument("colour '" + name + "' unknown: intensity, height, normal or none");
}

const char* toString(MeshColoring coloring) {
  switch (coloring) {
    case MeshColoring::kIntensity: return "intensity";
    case MeshColoring::kHeight: return "height";
    case MeshColoring::kNormal: return "normal";
    case MeshColoring::kNone: return "none";
  }
  return "?";
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

const ParamTable<TsdfConfig>& TsdfConfig::params() {
  using R = ParamRange;
  constexpr auto kRun = ParamChange::Runtime;
  static const ParamTable<TsdfConfig> t = [] {
    ParamTable<TsdfConfig> t("tsdf");
    t.number("voxel_size", [](TsdfConfig& c) -> double& { return c.voxel_size; }, R::aboveUpTo(0, kMaxVoxelSize), "m",
             "Voxel side (the map's geometry: stored in map files)")
        .number("truncation_voxels", [](TsdfConfig& c) -> double& { return c.truncation_voxels; }, R::aboveUpTo(0, kMaxTruncationVoxels),
                "voxels", "Truncation distance mu in voxels (mu = truncation_voxels x voxel_size)")
        .number("max_weight", [](TsdfConfig& c) -> float& { return c.max_weight; }, R::aboveUpTo(0, kMaxMapWeight), "",
                "Cap of the per-voxel observation count (written into map files)")
        .number("min_observations", [](TsdfConfig& c) -> int& { return c.min_observations; }, R::atLeast(1), "",
                "Mesh and cloud keep voxels observed at least this often (a change re-meshes the map)", kRun)
        .choice("colour", {"intensity", "height", "normal"}, [](const TsdfConfig& c) { return toString(c.colour); },
                [](TsdfConfig& c, const std::string& v) { c.colour = parseMeshColoring(v); },
                "Colour of the mesh (rviz markers, PLY export): intensity (the grey of the images fused into the "
                "voxels; vertices without one: height), height (blue low to red high), normal")
        .number("max_range", [](TsdfConfig& c) -> double& { return c.max_range; }, R::atLeast(0), "m",
                "Depth beyond this range is not fused; 0: no limit (applies to the next frame)", kRun)
        .flag("free_space_carving", [](TsdfConfig& c) -> bool& { return c.free_space_carving; },
              "Fuse every block of the map a depth frame sees in front of its surface, so that free space seen "
              "through earlier mistakes (unrepeatable depth, a missed vehicle) carves them away")
        .number("observation_travel", [](TsdfConfig& c) -> double& { return c.observation_travel; }, R::atLeast(0),
                "m",
                "A frame counts as min(1, camera travel since the previous frame / observation_travel) observations "
                "(or its turn / observation_turn, if more; at least 0.01), so that min_observations means the same "
                "at any frame rate and standing still adds nothing; 0: every frame counts 1")
        .number("observation_turn", [](TsdfConfig& c) -> double& { return c.observation_turn; }, R::above(0), "deg",
                "Camera turn since the previous frame that counts as a full observation (with observation_travel)")
        .numbers("local_map_size", 3, R::above(0), "m",
                 [](const TsdfConfig& c) {
                   return std::vector<double>{c.local_map_size.x(), c.local_map_size.y(), c.local_map_size.z()};
                 },
                 [](TsdfConfig& c, const std::vector<double>& v) { c.local_map_size = Eigen::Vector3d(v[0], v[1], v[2]); },
                 "Active box around the vehicle (map axes), x y z; blocks outside are swapped out")
        .numbers("local_map_offset", 3, R::any(), "m",
                 [](const TsdfConfig& c) {
                   return std::vector<double>{c.local_map_offset.x(), c.local_map_offset.y(), c.local_map_offset.z()};
                 },
                 [](TsdfConfig& c, const std::vector<double>& v) {
                   c.local_map_offset = Eigen::Vector3d(v[0], v[1], v[2]);
                 },
                 "Centre of the active box relative to the base frame's origin, x y z")
        .text("swap_directory", [](TsdfConfig& c) -> std::string& { return c.swap_directory; },
              "Folder for swapped-out blocks; empty: they stay in memory")
        .choice("integrator", {"cpu", "opencl"}, [](const TsdfConfig& c) { return toString(c.integrator); },
                [](TsdfConfig& c, const std::string& v) { c.integrator = parseTsdfIntegratorKind(v); },
                "Voxel integration: cpu (OpenMP loop, fastest on CPUs) or opencl (the same function as a kernel)")
        .number("threads", [](TsdfConfig& c) -> int& { return c.threads; }, R::atLeast(0), "",
                "Threads of the map's parallel loops; 0: the OpenMP default")
        .text("opencl_device", [](TsdfConfig& c) -> std::string& { return c.opencl_device; },
              "OpenCL device for integrator opencl: empty = first GPU, else a name substring or index");
    t.rule([](const TsdfConfig& c) {
      if (c.integrator != TsdfIntegratorKind::kCpu && c.integrator != TsdfIntegratorKind::kOpenCl)
        throw std::invalid_argument("integrator: not an integrator (" + std::to_string(int(c.integrator)) + ")");
    });
    return t;
  }();
  return t;
}

void TsdfConfig::validate() const { params().check(*this); }

TsdfConfig TsdfConfig::fromParams(const ParamSource& p, TsdfConfig base) { return params().read(p, std::move(base)); }

}  // namespace fisheye_mapping
