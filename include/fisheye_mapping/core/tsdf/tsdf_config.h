// Configuration of the TSDF map (paper Sec. III-C): voxel size and
// truncation, the local-map box, swapping, the integration backend and its
// threads. Plain data; validate() checks it, fromParams() reads it from the
// parameter names of config/tsdf.yaml.
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_CONFIG_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_CONFIG_H_

#include <string>

#include <Eigen/Core>

#include "fisheye_mapping/core/camera/camera_model_shared.h"  // before tsdf_shared.h
#include "fisheye_mapping/core/tsdf/tsdf_shared.h"

namespace fisheye_mapping {

class ParamSource;  // fisheye_mapping/core/common/params.h
template <class Config>
class ParamTable;  // fisheye_mapping/core/common/param_table.h

// Voxel integration backend (see tsdf_integrator.h).
enum class TsdfIntegratorKind {
  kCpu,     // "cpu": OpenMP loop over the blocks (TsdfIntegratorCpu)
  kOpenCl,  // "opencl": the same per-voxel function as a kernel (TsdfIntegratorCl)
};

// "cpu" or "opencl"; throws std::invalid_argument naming the bad value.
TsdfIntegratorKind parseTsdfIntegratorKind(const std::string& name);
// "cpu" or "opencl".
const char* toString(TsdfIntegratorKind kind);

// Per-vertex colour of the mesh (rviz markers and exports).
enum class MeshColoring {
  kIntensity,  // the grey of the images fused into the voxels (vertices without one: the height ramp)
  kHeight,     // world z through a blue (low) -> red (high) hue ramp
  kNormal,     // the unit normal n as (n + 1) / 2 in red, green, blue
  kNone,       // no colour properties (exports only; markers are then grey)
};

// "intensity" | "height" | "normal" | "none"; throws std::invalid_argument
// naming the bad value.
MeshColoring parseMeshColoring(const std::string& name);
const char* toString(MeshColoring coloring);

// The map's geometry: the ranges of the parameters below and of a map file's
// header (TsdfMap::readHeader refuses a file outside them, so map_tool and the
// nodelet agree on what a valid map is).
constexpr double kMaxVoxelSize = 10.0;          ///< m: voxel_size in (0, 10]
constexpr double kMaxTruncationVoxels = 1000.0;  ///< truncation_voxels in (0, 1000]
constexpr double kMaxMapWeight = 1e6;           ///< max_weight in (0, 1e6]
constexpr float kMinObservationWeight = 0.01f;  ///< a frame's least observation weight (observation_travel)
// The least weight a voxel needs to pass the observation rule: min_observations,
// except that 1 (no filter) keeps every voxel observed at all, whatever the
// frames' observation weights (observation_travel makes them fractional).
inline float minObservationWeight(int min_observations) {
  return min_observations <= 1 ? 1e-30f : static_cast<float>(min_observations);
}

struct TsdfConfig {
  double voxel_size = 0.05;        // metres
  double truncation_voxels = 4.0;  // mu = truncation_voxels * voxel_size
  float max_weight = 100.0f;       // cap of the per-voxel observation count
  int min_observations = 3;        // outputs keep voxels observed at least this often
  // Colour of the mesh (rviz markers, PLY export); parameter `colour`.
  MeshColoring colour = MeshColoring::kIntensity;
  double max_range = 0.0;          // depth beyond this many metres is not fused (0: no limit)
  // Every active block a depth frame sees in front of its measured surface is
  // fused too, not only those near it: what earlier frames fused there by
  // mistake (unrepeatable depth, a vehicle the mask missed) is averaged away
  // by the free space seen through it (TsdfMap::integrate). Off: on the
  // evaluation's drives it does not pay (docs/tsdf.md#free-space-carving).
  bool free_space_carving = false;
  // A frame counts as an observation in proportion to how far its camera
  // moved since the previous frame: weight min(1, max(travel /
  // observation_travel, turn / observation_turn)), at least
  // kMinObservationWeight, towards each voxel's average and its observation
  // count (min_observations). Neighbouring frames from nearly the same place
  // repeat the same depth errors, so the observation rule then means the
  // same at any frame rate, and a vehicle standing still adds no
  // observations. 0: every frame counts 1 (TsdfFusionStage).
  double observation_travel = 0.0;  // metres
  double observation_turn = 10.0;   // degrees
  // Active box around the vehicle (world axes): centre = vehicle + offset.
  Eigen::Vector3d local_map_size = Eigen::Vector3d(60.0, 60.0, 3.0);
  Eigen::Vector3d local_map_offset = Eigen::Vector3d(0.0, 0.0, 1.0);
  std::string swap_directory;  // empty: swapped blocks stay in host memory
  // Threads of the map's parallel loops (allocation, CPU integration), as an
  // OpenMP num_threads clause on those loops only; 0: the OpenMP default
  // (OMP_NUM_THREADS, else all cores). The process-wide OpenMP setting is
  // never changed.
  int threads = 0;
  // Voxel integration: kCpu (OpenMP loop) or kOpenCl (same function as a
  // kernel, on opencl_device; see OpenClContext for the syntax); parameter
  // `integrator`: "cpu" | "opencl", parsed once by fromParams().
  TsdfIntegratorKind integrator = TsdfIntegratorKind::kCpu;
  std::string opencl_device;

  double truncation() const { return truncation_voxels * voxel_size; }  // mu, metres
  double blockSize() const { return FM_BLOCK_SIDE * voxel_size; }       // metres
  // Throws std::invalid_argument naming the parameter (params().check).
  void validate() const;
  // The declaration of every parameter (name, range, description, whether it
  // may change while running); docs/parameters.md is generated from it.
  static const ParamTable<TsdfConfig>& params();

  // The parameter names of config/tsdf.yaml over `base` (the
  // defaults above when not given); validated (std::invalid_argument naming
  // the field or parameter). Over a running config, a source holding only some
  // names (a dynamic_reconfigure update) changes just those.
  static TsdfConfig fromParams(const ParamSource& p, TsdfConfig base);
  static TsdfConfig fromParams(const ParamSource& p) { return fromParams(p, TsdfConfig()); }
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_CONFIG_H_
