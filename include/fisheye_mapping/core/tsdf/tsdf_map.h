// TSDF map of fisheye depth (paper Sec. III-C): voxel blocks of 8^3 voxels in
// a spatial hash, allocated along each valid pixel's ray within the truncation
// band, integrated with the fisheye camera model, and kept as a local map: the
// blocks inside a box around the vehicle are active, the others are swapped out
// to a store in host memory (or on disk) and swapped back when needed. Nothing
// fused is lost by swapping, unless a swap file is deleted or damaged behind
// the map's back: that block is then dropped ("lost"), counted and reported
// once through the swap-error callback, and the map goes on without it. A swap
// file that cannot be written keeps its block in RAM (counted, reported).
//
// Not thread-safe: call from one thread (integration itself uses all cores).
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_MAP_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_MAP_H_

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/camera_model.h"
#include "fisheye_mapping/core/tsdf/tsdf_shared.h"

namespace fisheye_mapping {

struct TsdfConfig {
  double voxel_size = 0.05;        // metres
  double truncation_voxels = 4.0;  // mu = truncation_voxels * voxel_size
  float max_weight = 100.0f;       // cap of the per-voxel observation count
  int min_observations = 3;        // outputs keep voxels observed at least this often
  double max_range = 0.0;          // depth beyond this many metres is not fused (0: no limit)
  // Active box around the vehicle (world axes): centre = vehicle + offset.
  Eigen::Vector3d local_map_size = Eigen::Vector3d(60.0, 60.0, 3.0);
  Eigen::Vector3d local_map_offset = Eigen::Vector3d(0.0, 0.0, 1.0);
  std::string swap_directory;  // empty: swapped blocks stay in host memory
  int threads = 0;             // 0: all cores
  // Voxel integration: "cpu" (OpenMP loop) or "opencl" (same function as a
  // kernel, on opencl_device; see OpenClContext for the syntax).
  std::string integrator = "cpu";
  std::string opencl_device;

  double truncation() const { return truncation_voxels * voxel_size; }
  double blockSize() const { return FM_BLOCK_SIDE * voxel_size; }
  // Throws std::invalid_argument naming the field.
  void validate() const;
};

using BlockIndex = Eigen::Vector3i;

struct BlockIndexHash {
  size_t operator()(const BlockIndex& b) const {
    return (static_cast<size_t>(b.x()) * 73856093u) ^ (static_cast<size_t>(b.y()) * 19349669u) ^
           (static_cast<size_t>(b.z()) * 83492791u);
  }
};

struct VoxelBlock {
  std::array<FmVoxel, FM_BLOCK_VOXELS> voxels{};  // x fastest: i + 8 j + 64 k
  static int linear(int i, int j, int k) { return i + FM_BLOCK_SIDE * (j + FM_BLOCK_SIDE * k); }
};

using BlockSet = std::unordered_set<BlockIndex, BlockIndexHash>;

struct IntegrationStats {
  size_t valid_pixels = 0;
  size_t blocks_touched = 0;    // blocks the frame's rays crossed (inside the local box)
  size_t blocks_allocated = 0;  // new blocks
  size_t blocks_swapped_in = 0;
  size_t blocks_swapped_out = 0;
  double allocation_ms = 0;   // rays -> touched blocks, allocation, swap-in
  double integration_ms = 0;  // voxel updates
  double local_map_ms = 0;    // swap-out / swap-in as the box moves
  size_t blocks_lost = 0;     // swapped blocks whose file could not be read back (dropped)
};

// Map file (see tsdf_io.cpp for the layout). Version 2 (written now) carries
// max_weight, a CRC32 of the header and one per block; version 1 (no
// checksums) is still read.
struct MapFileInfo {
  uint32_t version = 0;
  double voxel_size = 0, truncation_voxels = 0;
  float max_weight = 0;  // 0: not stored (version 1)
  uint64_t num_blocks = 0;
  uint64_t file_size = 0;
};

struct MapSaveOptions {
  // Keep an existing file at the path as <path>.1 (replacing an older .1).
  bool keep_previous = false;
  // Refuse (throw, nothing written) to replace a file holding blocks (or one
  // that is not a readable map) by a map with no blocks.
  bool refuse_empty_overwrite = false;
};

// CRC-32 (IEEE 802.3, zlib's crc32): crc32("123456789") == 0xCBF43926.
// Chain by passing the previous value as `crc`.
uint32_t crc32(const void* data, size_t size, uint32_t crc = 0);

class TsdfMap {
 public:
  explicit TsdfMap(const TsdfConfig& config = TsdfConfig());
  ~TsdfMap();

  const TsdfConfig& config() const { return config_; }

  // Fuses one depth map: CV_32FC1, the camera's resolution, metres of range
  // along each pixel's ray, NaN (or <= 0, or inf) where invalid. T_W_C is the
  // camera pose in the world; vehicle_W the vehicle position, which places the
  // local map (blocks leaving it are swapped out after the update). Throws
  // std::invalid_argument (map untouched) for a wrong encoding or size, or a
  // non-finite pose.
  IntegrationStats integrate(const cv::Mat& depth, const CameraModel& camera,
                             const Eigen::Isometry3d& T_W_C, const Eigen::Vector3d& vehicle_W);

  // Moves the local map to the vehicle: active blocks outside the new box are
  // swapped out, stored blocks inside it swapped back in. Returns the number of
  // blocks swapped out.
  size_t moveLocalMap(const Eigen::Vector3d& vehicle_W);
  bool insideLocalMap(const BlockIndex& block) const;

  // Voxel at a global voxel index from either store, or nullptr.
  const FmVoxel* voxel(const Eigen::Vector3i& global_voxel) const;
  // Block from either store (a swapped block on disk is read into a cache
  // owned by the map), or nullptr. A disk-swapped block whose file cannot be
  // read (missing, short, checksum) is dropped from the map and reported as
  // lost; nullptr then. Never throws for swap I/O.
  const VoxelBlock* block(const BlockIndex& index) const;
  bool isActive(const BlockIndex& index) const { return active_.count(index) > 0; }
  // Frees the copies of disk-swapped blocks that block() read.
  void dropSwapCache() const { disk_cache_.clear(); }

  size_t numActiveBlocks() const { return active_.size(); }
  size_t numSwappedBlocks() const { return swapped_.size(); }
  size_t numBlocks() const { return active_.size() + swapped_.size(); }
  // Memory held by active blocks (the bounded part).
  size_t activeMemoryBytes() const { return active_.size() * sizeof(VoxelBlock); }
  std::vector<BlockIndex> allBlocks() const;

  // Blocks whose voxels changed since the last call (for incremental meshing).
  BlockSet takeChangedBlocks();

  // Swap I/O faults. Lost blocks: swapped blocks whose file could not be read
  // back, dropped from the map (each reported once, with its path). Swap write
  // failures: blocks kept in RAM because their file could not be written.
  // `lost`: true for a lost block (once per block), false for a failed write
  // (each time the block leaves the local map again).
  using SwapErrorCallback = std::function<void(bool lost, const std::string& message)>;
  // Default: one line on stderr per event.
  void setSwapErrorCallback(SwapErrorCallback cb) { swap_error_cb_ = std::move(cb); }
  size_t numLostBlocks() const { return lost_blocks_; }
  size_t numSwapWriteFailures() const { return swap_write_failures_; }

  // Whole map (both stores) to a binary file (format version 2) and back,
  // bit-identical. save writes <path>.tmp, syncs it and renames it over path;
  // on any failure (path a directory, unwritable, disk full) it throws
  // std::runtime_error naming the path and leaves no .tmp behind.
  void save(const std::string& path, const MapSaveOptions& options = MapSaveOptions()) const;
  // Replaces the map's contents with the file's, only once the whole file is
  // read and valid: header (and its CRC), block count against the file size,
  // each block's CRC, every voxel finite with |tsdf| <= 1 and 0 <= weight <=
  // max_weight (the file's; the config's for version 1), block indices within
  // 1e5 m of the origin, no duplicate blocks; the file's voxel size and
  // truncation must match the config. Throws std::runtime_error naming the
  // file (and the block) otherwise; the map is then unchanged.
  void load(const std::string& path);
  // The header of a map file (std::runtime_error if it is none).
  static MapFileInfo readHeader(const std::string& path);
  void clear();

  Eigen::Vector3d voxelCenter(const Eigen::Vector3i& global_voxel) const {
    return (global_voxel.cast<double>() + Eigen::Vector3d::Constant(0.5)) * config_.voxel_size;
  }

 private:
  struct RayTable;
  void integrateCpu(const std::vector<std::pair<BlockIndex, VoxelBlock*>>& work, const float* depth,
                    const FmCameraT<float>& cam, const float T_C_W[12], std::vector<char>* changed) const;
  const RayTable& raysFor(const CameraModel& camera);
  void swapOut(const BlockIndex& index);
  // nullptr when absent, or when its swap file is unreadable (then lost).
  std::unique_ptr<VoxelBlock> takeSwapped(const BlockIndex& index);
  std::string swapPath(const BlockIndex& index) const;
  // Reads a disk-swapped block; false with the reason when it cannot.
  bool readSwapFile(const BlockIndex& index, VoxelBlock* out, std::string* why) const;
  void markLost(const BlockIndex& index, const std::string& why) const;
  void reportSwapError(bool lost, const std::string& message) const;

  TsdfConfig config_;
  Eigen::Vector3d local_center_ = Eigen::Vector3d::Zero();
  bool has_local_center_ = false;
  std::unordered_map<BlockIndex, std::unique_ptr<VoxelBlock>, BlockIndexHash> active_;
  // Swapped-out blocks: in memory, or (swap_directory set) nullptr + a file.
  // Mutable: a block whose file turns out unreadable is dropped, even by a
  // const read.
  mutable std::unordered_map<BlockIndex, std::unique_ptr<VoxelBlock>, BlockIndexHash> swapped_;
  mutable std::unordered_map<BlockIndex, std::unique_ptr<VoxelBlock>, BlockIndexHash> disk_cache_;
  mutable BlockSet changed_;
  mutable size_t lost_blocks_ = 0;
  size_t swap_write_failures_ = 0;
  SwapErrorCallback swap_error_cb_;
  std::vector<std::unique_ptr<RayTable>> ray_tables_;
  std::unique_ptr<class TsdfIntegratorCl> opencl_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_MAP_H_
