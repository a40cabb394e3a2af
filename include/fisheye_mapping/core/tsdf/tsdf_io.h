// TSDF map files: the blocks of a BlockStore (both the active and the swapped
// ones) to a binary file and back, bit-identical. Layout in tsdf_io.cpp.
// Version 4 (written now) stores per block only the voxels that hold
// something (weight > 0), with their intensity, zlib-compressed, with
// max_weight, a CRC32 of the header and one per block; version 3 (the same
// without intensities: they load as 0, none) and version 2 (every voxel, no
// intensity, the same checksums) are read, and written on request; version 1
// (no checksums) is still read.
// Depends on the store only (no integrator, no camera).
//
// Thread-safety: the functions taking a store need exclusive access to it;
// readMapFileHeader is thread-safe.
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_IO_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_IO_H_

#include <cstdint>
#include <string>

#include "fisheye_mapping/core/tsdf/block_store.h"

namespace fisheye_mapping {

struct MapFileInfo {
  uint32_t version = 0;
  double voxel_size = 0, truncation_voxels = 0;  // metres, voxels
  float max_weight = 0;  // 0: not stored (version 1)
  uint64_t num_blocks = 0;
  uint64_t file_size = 0;  // bytes
};

struct MapSaveOptions {
  // Keep an existing file at the path as <path>.1 (replacing an older .1).
  bool keep_previous = false;
  // Refuse (throw, nothing written) to replace a file holding blocks (or one
  // that is not a readable map) by a map with no blocks.
  bool refuse_empty_overwrite = false;
  // 4: compact and compressed, with the intensities (the default); 3: the
  // same without intensities, 2: every voxel of every block, no intensities
  // (for older readers). Others: refused (std::runtime_error).
  uint32_t format_version = 4;
};

// Writes every block of `store` (options.format_version, with the store config's
// voxel size, truncation and max_weight) through SafeFileWriter: a temporary
// file beside path (a link at path is replaced, never followed; a FIFO or a
// device there is refused), every write, the fsync, the size and the close
// checked, then renamed over path. Disk-swapped blocks are read one at a
// time (not cached); one whose swap file is unreadable is lost (dropped from
// the store, reported through its callback) and not saved. On any failure
// (path a directory or no regular file, unwritable, disk full) throws
// std::runtime_error naming the path and the OS error, and leaves no
// temporary behind; the store then keeps its blocks.
void saveMapFile(BlockStore& store, const std::string& path, const MapSaveOptions& options = MapSaveOptions());

// Replaces the store's contents with the file's (BlockStore::replaceAll),
// only once the whole file is read and valid: header (and its CRC), block
// count against the file size, each block's CRC, (version 3) each block's
// zlib stream and its voxel mask, every voxel finite with
// |tsdf| <= 1 and 0 <= weight <= max_weight (the file's; the config's for
// version 1), block indices within 1e5 m of the origin, no duplicate blocks;
// the file's voxel size and truncation must equal the store config's. Throws
// std::runtime_error naming the file (and the block) otherwise; the store is
// then unchanged.
void loadMapFile(BlockStore& store, const std::string& path);

// The header of a map file (std::runtime_error naming it if it is none).
MapFileInfo readMapFileHeader(const std::string& path);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_IO_H_
