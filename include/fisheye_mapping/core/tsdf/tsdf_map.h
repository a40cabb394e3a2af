// TSDF map of fisheye depth (paper Sec. III-C): a facade over the three parts
// (voxblox / InfiniTAM ITMLib style), kept for the callers of one object:
//   BlockStore      (block_store.h): voxel blocks of 8^3 voxels in a spatial
//                   hash, allocation, the local-map window and swapping of
//                   the blocks outside it to host memory or disk;
//   TsdfIntegrator  (tsdf_integrator.h): the voxel update, on the CPU
//                   (OpenMP) or with OpenCL, chosen by TsdfConfig::integrator;
//   map files       (tsdf_io.h): save / load / readHeader.
// integrate() adds what joins them: the blocks each valid pixel's ray crosses
// within the truncation band (the rays of each camera computed once), which
// the store allocates and the integrator fuses with the fisheye camera model.
//
// Units and frames: metres; the world frame (W) for poses, block indices and
// voxel centres; depth is range along each pixel's ray.
//
// Thread-safety: not thread-safe; call every method from one thread at a time
// (integration itself runs TsdfConfig::threads threads: 0 = the OpenMP
// default). The const methods that read swapped blocks (block, voxel) are
// const for existing callers only: see block().
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_MAP_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_MAP_H_

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/camera_model.h"
#include "fisheye_mapping/core/tsdf/block_store.h"
#include "fisheye_mapping/core/tsdf/tsdf_config.h"
#include "fisheye_mapping/core/tsdf/tsdf_integrator.h"
#include "fisheye_mapping/core/tsdf/tsdf_io.h"
#include "fisheye_mapping/core/tsdf/tsdf_shared.h"

namespace fisheye_mapping {

struct IntegrationStats {
  size_t valid_pixels = 0;
  size_t blocks_touched = 0;    // blocks the frame fused (inside the local box), carved ones included
  size_t blocks_carved = 0;     // of them, active blocks seen in front of the surface (free_space_carving)
  size_t blocks_allocated = 0;  // new blocks
  size_t blocks_swapped_in = 0;
  size_t blocks_swapped_out = 0;
  double allocation_ms = 0;   // rays -> touched blocks, allocation, swap-in
  double integration_ms = 0;  // voxel updates
  double local_map_ms = 0;    // swap-out / swap-in as the box moves
  size_t blocks_lost = 0;     // swapped blocks whose file could not be read back (dropped)
};

class TsdfMap {
 public:
  // Validates the config (std::invalid_argument naming the field), creates
  // the swap directory if set, and makes the integrator (OpenClError when
  // "opencl" finds no device).
  explicit TsdfMap(const TsdfConfig& config = TsdfConfig());
  ~TsdfMap();
  TsdfMap(const TsdfMap&) = delete;
  TsdfMap& operator=(const TsdfMap&) = delete;

  const TsdfConfig& config() const { return config_; }
  // The only setting that may change on a live map (dynamic_reconfigure): it
  // affects what later frames fuse, not what the map stores.
  void setMaxRange(double max_range) {
    if (!(max_range >= 0.0)) throw std::invalid_argument("TsdfConfig.max_range must be >= 0 (0: no limit)");
    config_.max_range = max_range;
  }

  // Fuses one depth map: CV_32FC1, the camera's resolution, metres of range
  // along each pixel's ray, NaN (or <= 0, or inf) where invalid. T_W_C is the
  // camera pose in the world; vehicle_W the vehicle position (world, metres),
  // which places the local map (blocks leaving it are swapped out after the
  // update). `carve`: world regions whose blocks in memory are fused too,
  // though no ray ends near them: their voxels in front of what the depth
  // sees now are carved free (a parked car that drove off leaves no ghost;
  // VehicleMotionTracker::ghostRegions). `grey`: the image the depth was
  // computed for (CV_8UC1, the camera's size), averaged into the intensity
  // of the voxels near the surface (tsdf_shared.h); empty: no intensity.
  // With free_space_carving, the active blocks whose centre the camera sees
  // in front of the measured surface (beyond the centre by more than the
  // truncation plus half the block's diagonal) are fused too, whether or not
  // a ray ends near them: their voxels take the free-space update, so that
  // what no later frame confirms is carved away.
  // `observation_weight` in (0, 1]: how much this frame counts, towards each
  // voxel's weighted average and towards its observation count (1: a full
  // observation; TsdfFusionStage lowers it for a camera that has hardly
  // moved since the previous frame, see TsdfConfig::observation_travel).
  // Throws std::invalid_argument (map untouched) for a wrong encoding or
  // size of either image, a non-finite pose, or an observation weight
  // outside (0, 1].
  IntegrationStats integrate(const cv::Mat& depth, const CameraModel& camera,
                             const Eigen::Isometry3d& T_W_C, const Eigen::Vector3d& vehicle_W,
                             const std::vector<Eigen::AlignedBox3d>& carve = {}, const cv::Mat& grey = cv::Mat(),
                             float observation_weight = 1.0f);

  // Moves the local map to the vehicle (world, metres): active blocks outside
  // the new box are swapped out, stored blocks inside it swapped back in.
  // Returns the number of blocks swapped out.
  size_t moveLocalMap(const Eigen::Vector3d& vehicle_W) { return store_->moveLocalMap(vehicle_W); }
  bool insideLocalMap(const BlockIndex& block) const { return store_->insideLocalMap(block); }

  // Block from either store (a swapped block on disk is read into the
  // store's read cache), or nullptr. A disk-swapped block whose file cannot
  // be read (missing, short, checksum) is dropped from the map and reported
  // as lost; nullptr then. Never throws for swap I/O. Valid until the next
  // call of a non-const method other than block()/voxel().
  const VoxelBlock* block(const BlockIndex& index) { return store_->fetch(index); }
  // The same for callers holding a const map: logically const only, since
  // it may fill the store's read cache and drop a lost block like the
  // non-const overload (which new code should use; BlockStore::find() is the
  // truly const lookup, without I/O). Not safe to call concurrently.
  const VoxelBlock* block(const BlockIndex& index) const { return store_->fetch(index); }
  // Voxel at a global voxel index (voxel centre = (index + 0.5) * voxel_size,
  // world frame) from either store, or nullptr; as block().
  const FmVoxel* voxel(const Eigen::Vector3i& global_voxel);
  const FmVoxel* voxel(const Eigen::Vector3i& global_voxel) const;
  // The voxel's intensity (1..255; 0 = none yet), or -1 where voxel() gives
  // nullptr; as block().
  int grey(const Eigen::Vector3i& global_voxel);
  bool isActive(const BlockIndex& index) const { return store_->isActive(index); }
  // Frees the copies of disk-swapped blocks that block() read.
  void dropSwapCache() { store_->dropReadCache(); }

  size_t numActiveBlocks() const { return store_->numActiveBlocks(); }
  size_t memoryBytes() const { return store_->memoryBytes(); }
  size_t numSwappedBlocks() const { return store_->numSwappedBlocks(); }
  size_t numBlocks() const { return store_->numBlocks(); }
  // Memory held by active blocks (the bounded part), bytes.
  size_t activeMemoryBytes() const { return store_->activeMemoryBytes(); }
  std::vector<BlockIndex> allBlocks() const { return store_->allBlocks(); }

  // Blocks whose voxels changed since the last call (for incremental meshing).
  BlockSet takeChangedBlocks() { return store_->takeChangedBlocks(); }

  // Swap I/O faults (see BlockStore). Lost blocks: swapped blocks whose file
  // could not be read back, dropped from the map (each reported once, with
  // its path). Swap write failures: blocks kept in RAM because their file
  // could not be written.
  using SwapErrorCallback = BlockStore::SwapErrorCallback;
  // Default: one line on stderr per event. Called on the calling thread.
  void setSwapErrorCallback(SwapErrorCallback cb) { store_->setSwapErrorCallback(std::move(cb)); }
  size_t numLostBlocks() const { return store_->numLostBlocks(); }
  size_t numSwapWriteFailures() const { return store_->numSwapWriteFailures(); }

  // Whole map (both stores) to a binary file (format version 3, compressed;
  // MapSaveOptions::format_version 2 writes the older layout) and back,
  // bit-identical: saveMapFile / loadMapFile (tsdf_io.h). save writes
  // <path>.tmp, syncs it and renames it over path; on any failure (path a
  // directory, unwritable, disk full) it throws std::runtime_error naming the
  // path and leaves no .tmp behind. Non-const: a disk-swapped block whose file
  // turns out unreadable is dropped (lost) and not saved.
  void save(const std::string& path, const MapSaveOptions& options = MapSaveOptions()) {
    saveMapFile(*store_, path, options);
  }
  // Replaces the map's contents with the file's, only once the whole file is
  // read and valid (see loadMapFile); the file's voxel size and truncation
  // must match the config. Throws std::runtime_error naming the file (and the
  // block) otherwise; the map is then unchanged.
  void load(const std::string& path) { loadMapFile(*store_, path); }
  // The header of a map file (std::runtime_error if it is none). Thread-safe.
  static MapFileInfo readHeader(const std::string& path) { return readMapFileHeader(path); }
  // Removes every block (and the swap files of disk-swapped ones).
  void clear() { store_->clear(); }

  // Centre of a global voxel, world frame, metres.
  Eigen::Vector3d voxelCenter(const Eigen::Vector3i& global_voxel) const {
    return (global_voxel.cast<double>() + Eigen::Vector3d::Constant(0.5)) * config_.voxel_size;
  }

  // The parts.
  BlockStore& store() { return *store_; }
  const BlockStore& store() const { return *store_; }
  TsdfIntegrator& integrator() { return *integrator_; }

 private:
  struct RayTable;
  const RayTable& raysFor(const CameraModel& camera);

  TsdfConfig config_;
  std::unique_ptr<BlockStore> store_;
  std::unique_ptr<TsdfIntegrator> integrator_;
  std::vector<std::unique_ptr<RayTable>> ray_tables_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_MAP_H_
