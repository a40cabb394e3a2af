// Block store of the TSDF map (paper Sec. III-C; voxblox's Layer plus
// InfiniTAM's swapping): voxel blocks of 8^3 voxels in a spatial hash, the
// local-map window (the blocks inside a box around the vehicle are active,
// the others are swapped out to host memory or to one file per block in
// swap_directory, and swapped back in when the box returns), allocation of
// the blocks a frame touches, and the set of blocks changed since the last
// mesh update. It knows nothing of cameras or integration (tsdf_integrator.h)
// nor of map files (tsdf_io.h).
//
// Nothing fused is lost by swapping, unless a swap file is deleted or
// damaged behind the store's back: that block is then dropped ("lost"),
// counted and reported once through the swap-error callback, and the store
// goes on without it. A swap file that cannot be written keeps its block in
// RAM (counted, reported).
//
// Frames: block indices are in the world frame; block b covers
// [b * blockSize(), (b + 1) * blockSize()) metres on each axis.
//
// Thread-safety: not thread-safe. The const methods do no I/O and change
// nothing, so they may run concurrently with each other (and only with each
// other); every non-const method needs exclusive access.
#ifndef FISHEYE_MAPPING_CORE_TSDF_BLOCK_STORE_H_
#define FISHEYE_MAPPING_CORE_TSDF_BLOCK_STORE_H_

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "fisheye_mapping/core/tsdf/tsdf_config.h"
#include "fisheye_mapping/core/camera/camera_model_shared.h"  // before tsdf_shared.h
#include "fisheye_mapping/core/tsdf/tsdf_shared.h"

namespace fisheye_mapping {

using BlockIndex = Eigen::Vector3i;

struct BlockIndexHash {
  size_t operator()(const BlockIndex& b) const {
    return (static_cast<size_t>(b.x()) * 73856093u) ^ (static_cast<size_t>(b.y()) * 19349669u) ^
           (static_cast<size_t>(b.z()) * 83492791u);
  }
};

struct VoxelBlock {
  std::array<FmVoxel, FM_BLOCK_VOXELS> voxels{};  // x fastest: i + 8 j + 64 k
  // Each voxel's intensity (tsdf_shared.h: 1..255, 0 = none yet), same order.
  std::array<unsigned char, FM_BLOCK_VOXELS> grey{};
  static int linear(int i, int j, int k) { return i + FM_BLOCK_SIDE * (j + FM_BLOCK_SIDE * k); }
};

using BlockSet = std::unordered_set<BlockIndex, BlockIndexHash>;
using BlockMap = std::unordered_map<BlockIndex, std::unique_ptr<VoxelBlock>, BlockIndexHash>;
// Blocks handed to an integrator: index and the active block's storage.
using BlockWork = std::vector<std::pair<BlockIndex, VoxelBlock*>>;

// CRC-32 (IEEE 802.3, zlib's crc32): crc32("123456789") == 0xCBF43926.
// Chain by passing the previous value as `crc`. Thread-safe.
uint32_t crc32(const void* data, size_t size, uint32_t crc = 0);

class BlockStore {
 public:
  // Creates config.swap_directory if set. The config is not validated here
  // (TsdfMap does that). Swap files left at destruction stay on disk.
  explicit BlockStore(const TsdfConfig& config);
  ~BlockStore();
  BlockStore(const BlockStore&) = delete;
  BlockStore& operator=(const BlockStore&) = delete;

  const TsdfConfig& config() const { return config_; }

  // --- Local-map window --------------------------------------------------
  // Places the box at vehicle_W + local_map_offset (world frame, metres)
  // without swapping anything (allocation then only activates blocks inside).
  void setLocalCenter(const Eigen::Vector3d& vehicle_W);
  // setLocalCenter, then swaps out the active blocks outside the box and back
  // in the swapped blocks inside it (those whose file is unreadable are lost).
  // Returns the number of blocks swapped out.
  size_t moveLocalMap(const Eigen::Vector3d& vehicle_W);
  // True when the block's centre lies in the box (always before the box is
  // first placed).
  bool insideLocalMap(const BlockIndex& block) const;

  // --- Allocation --------------------------------------------------------
  // Makes every block of `touched` active: active ones as they are, swapped
  // ones swapped in, the others allocated empty (a swapped block whose file
  // is unreadable is lost and allocated anew). Returns them with their
  // storage, valid until the next non-const call. Counts into *allocated and
  // *swapped_in (added to, not reset).
  BlockWork allocate(const BlockSet& touched, size_t* allocated, size_t* swapped_in);

  // --- Access --------------------------------------------------------------
  // A block that is active, swapped in host memory, or in the read cache;
  // nullptr otherwise (also for a disk-swapped block not read yet). No I/O.
  const VoxelBlock* find(const BlockIndex& index) const;
  // As find(), and a disk-swapped block is read into the read cache (freed by
  // dropReadCache() or when it is swapped in). A disk-swapped block whose file
  // cannot be read (missing, short, checksum) is lost: nullptr. Never throws
  // for swap I/O. The pointer stays valid until the next non-const call other
  // than fetch().
  const VoxelBlock* fetch(const BlockIndex& index);
  // As fetch(), but a disk-swapped block not in the read cache is read into
  // *scratch instead of the cache (for one pass over the whole map).
  const VoxelBlock* fetchInto(const BlockIndex& index, VoxelBlock* scratch);
  // Frees the copies of disk-swapped blocks that fetch() read.
  void dropReadCache() { read_cache_.clear(); }

  bool isActive(const BlockIndex& index) const { return active_.count(index) > 0; }
  size_t numActiveBlocks() const { return active_.size(); }
  size_t numSwappedBlocks() const { return swapped_.size(); }
  size_t numBlocks() const { return active_.size() + swapped_.size(); }
  // Memory held by active blocks (the bounded part), bytes.
  size_t activeMemoryBytes() const { return active_.size() * sizeof(VoxelBlock); }
  // Memory held by every block in RAM: active, swapped to host memory, and
  // read back from swap files (read cache), bytes.
  size_t memoryBytes() const;
  // Active blocks first, then swapped ones (hash order within each).
  std::vector<BlockIndex> allBlocks() const;
  // The active blocks (hash order).
  std::vector<BlockIndex> activeBlocks() const;

  // --- Changed blocks (for incremental meshing) -----------------------------
  void markChanged(const BlockIndex& index) { changed_.insert(index); }
  // Blocks whose voxels changed (or that were lost or loaded) since the last
  // call.
  BlockSet takeChangedBlocks();

  // --- Whole contents -------------------------------------------------------
  // Replaces everything by `blocks` (all marked changed); those outside the
  // local box are swapped out at once.
  void replaceAll(BlockMap blocks);
  // Removes every block (and the swap files of disk-swapped ones).
  void clear();

  // --- Swap I/O faults ----------------------------------------------------
  // `lost`: true for a lost block (once per block), false for a failed write
  // (each time the block leaves the local map again).
  using SwapErrorCallback = std::function<void(bool lost, const std::string& message)>;
  // Default: one line on stderr per event.
  void setSwapErrorCallback(SwapErrorCallback cb) { swap_error_cb_ = std::move(cb); }
  size_t numLostBlocks() const { return lost_blocks_; }
  size_t numSwapWriteFailures() const { return swap_write_failures_; }

 private:
  void swapOut(const BlockIndex& index);
  // nullptr when absent, or when its swap file is unreadable (then lost).
  std::unique_ptr<VoxelBlock> takeSwapped(const BlockIndex& index);
  std::string swapPath(const BlockIndex& index) const;
  // Reads a disk-swapped block; false with the reason when it cannot.
  bool readSwapFile(const BlockIndex& index, VoxelBlock* out, std::string* why) const;
  void markLost(const BlockIndex& index, const std::string& why);
  void reportSwapError(bool lost, const std::string& message) const;

  TsdfConfig config_;
  Eigen::Vector3d local_center_ = Eigen::Vector3d::Zero();
  bool has_local_center_ = false;
  BlockMap active_;
  // Swapped-out blocks: in memory, or (swap_directory set) nullptr + a file.
  BlockMap swapped_;
  // Copies of disk-swapped blocks read by fetch().
  BlockMap read_cache_;
  BlockSet changed_;
  size_t lost_blocks_ = 0;
  size_t swap_write_failures_ = 0;
  SwapErrorCallback swap_error_cb_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_BLOCK_STORE_H_
