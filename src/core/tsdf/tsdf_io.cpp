// TSDF map files: save (atomic, checksummed, compressed), load (validated
// before anything is replaced), readMapFileHeader. The CRC-32 is
// block_store.h's; compression is zlib's.
//
// Layout, little-endian (version 4, written now):
//   0  char[8]  "FMTSDF01"
//   8  uint32   version = 4
//  12  float64  voxel_size
//  20  float64  truncation_voxels
//  28  uint64   number of blocks N
//  36  float32  max_weight (the cap of the voxels' weights)
//  40  uint32   CRC-32 of bytes 0..39
//  44  N records: int32 x, y, z (block index); uint32 C; C bytes of a zlib
//      stream; uint32 CRC-32 of the record's first 16 + C bytes. The stream
//      inflates to a 64-byte mask (bit v % 8 of byte v / 8 set: voxel v is
//      stored; a voxel is stored unless all its 8 bytes are zero, i.e. in
//      practice when its weight is > 0), then the n stored voxels' float32
//      tsdf values, then their float32 weights, each array of n values
//      (voxel order, x fastest) stored byte-plane by byte-plane: byte 0 of
//      every value, then byte 1, ... (value s's byte k at k * n + s; the
//      exponent bytes then sit together and deflate well), then their n
//      uint8 intensities (VoxelBlock::grey; 0 = none). Voxels not stored are
//      {0, 0} with intensity 0 (a voxel is stored unless all of its 9 bytes
//      are zero).
// Version 3 (read; written on request): the same without the intensities
//   (they load as 0, none); a voxel is stored unless its 8 bytes are zero.
// Version 2 (read; written on request): the same header (version = 2), then N
//   records: int32 x, y, z; 512 x {float32 tsdf, float32 weight} (x fastest);
//   uint32 CRC-32 of the record's first 4108 bytes.
// Version 1 (read only): the first 36 bytes (version = 1), then N records of
// index + voxels without a CRC.
#include "fisheye_mapping/core/tsdf/tsdf_io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <vector>

#include <zlib.h>

#include "fisheye_mapping/core/common/safe_open.h"
#include "fisheye_mapping/core/tsdf/tsdf_config.h"
#include "fisheye_mapping/core/common/safe_write.h"

namespace fisheye_mapping {
namespace {

constexpr char kMagic[8] = {'F', 'M', 'T', 'S', 'D', 'F', '0', '1'};
constexpr size_t kHeaderV1 = 36;
constexpr size_t kHeaderV2 = 44;  // versions 2 and 3
constexpr size_t kPayload = 3 * sizeof(int32_t) + sizeof(VoxelBlock::voxels);  // 4108
constexpr size_t kRecordV1 = kPayload;
constexpr size_t kRecordV2 = kPayload + sizeof(uint32_t);
constexpr size_t kMaskBytes = FM_BLOCK_VOXELS / 8;                   // 64
constexpr size_t kRawV3 = kMaskBytes + sizeof(VoxelBlock::voxels);  // inflated size of a full block
constexpr size_t kRawV4 = kRawV3 + sizeof(VoxelBlock::grey);          // the same with intensities
constexpr size_t kHeadV3 = 3 * sizeof(int32_t) + sizeof(uint32_t);  // index, compressed size
// The smallest zlib stream (of nothing) is 8 bytes: a record has at least
// head + 8 + CRC bytes, which bounds the block count by the file size.
constexpr size_t kMinRecordV3 = kHeadV3 + 8 + sizeof(uint32_t);
// Block indices beyond this many metres from the origin are garbage.
constexpr double kMaxExtentM = 1e5;
constexpr float kTsdfSlack = 1e-4f;  // rounding of the running average
// zlib's level for map files: the default (6) is 4 % smaller than the
// fastest (1) on fused voxels and about 30 % slower (some 40 us a block).
constexpr int kMapCompressionLevel = Z_DEFAULT_COMPRESSION;

static_assert(sizeof(FmVoxel) == 8, "map files store 8-byte voxels");
static_assert(sizeof(VoxelBlock::voxels) == 4096, "map files store 512 voxels per block");

std::string indexText(const BlockIndex& b) {
  std::ostringstream s;
  s << "(" << b.x() << ", " << b.y() << ", " << b.z() << ")";
  return s.str();
}

std::string blockName(uint64_t ordinal, const BlockIndex& b) { return "block #" + std::to_string(ordinal) + " " + indexText(b); }

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw std::runtime_error(path + ": " + what);
}

template <typename T>
T readAt(const char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

// Parses and checks the header in `bytes` (at least kHeaderV1 long).
std::string formatHeaderNumber(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

MapFileInfo parseHeader(const std::string& path, const char* bytes, size_t available, uint64_t file_size) {
  MapFileInfo info;
  info.file_size = file_size;
  if (available < kHeaderV1 || std::memcmp(bytes, kMagic, sizeof(kMagic)) != 0) {
    fail(path, "not a fisheye_mapping TSDF map (bad header)");
  }
  info.version = readAt<uint32_t>(bytes + 8);
  info.voxel_size = readAt<double>(bytes + 12);
  info.truncation_voxels = readAt<double>(bytes + 20);
  info.num_blocks = readAt<uint64_t>(bytes + 28);
  if (info.version >= 2 && info.version <= 4) {
    if (available < kHeaderV2) fail(path, "not a fisheye_mapping TSDF map (bad header: too short)");
    info.max_weight = readAt<float>(bytes + 36);
    if (crc32(bytes, 40) != readAt<uint32_t>(bytes + 40)) {
      fail(path, "header checksum mismatch (the header is damaged)");
    }
    if (!(info.max_weight > 0.0f) || !std::isfinite(info.max_weight) || info.max_weight > kMaxMapWeight) {
      fail(path, "bad header: max_weight " + std::to_string(info.max_weight) + " (must lie in (0, " +
                     formatHeaderNumber(kMaxMapWeight) + "])");
    }
  } else if (info.version != 1) {
    fail(path, "not a fisheye_mapping TSDF map (bad header: unknown version " + std::to_string(info.version) + ")");
  }
  if (!(info.voxel_size > 0.0) || !std::isfinite(info.voxel_size) || !(info.truncation_voxels > 0.0) ||
      !std::isfinite(info.truncation_voxels)) {
    fail(path, "not a fisheye_mapping TSDF map (bad header: voxel size or truncation)");
  }
  // The ranges of the tsdf parameters (tsdf_config.h): what the nodelet accepts.
  if (info.voxel_size > kMaxVoxelSize)
    fail(path, "bad header: voxel_size " + formatHeaderNumber(info.voxel_size) + " m (must lie in (0, " +
                   formatHeaderNumber(kMaxVoxelSize) + "] m)");
  if (info.truncation_voxels > kMaxTruncationVoxels)
    fail(path, "bad header: truncation_voxels " + formatHeaderNumber(info.truncation_voxels) + " (must lie in (0, " +
                   formatHeaderNumber(kMaxTruncationVoxels) + "] voxels)");
  return info;
}

// Why replacing `path` by an empty map would destroy something; empty if it
// would not (no file, or a map without blocks).
std::string holdsData(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return "";
  try {
    const MapFileInfo info = readMapFileHeader(path);
    if (info.num_blocks == 0) return "";
    return "it holds a map of " + std::to_string(info.num_blocks) + " blocks";
  } catch (const std::exception& e) {
    return std::string("it is not a readable map (") + e.what() + ")";
  }
}

// What a loaded block is checked against, and the file it came from.
struct BlockCheck {
  std::string path;
  float max_weight;
  double block_size;
};

// Checks block #i of the file (index within reach of the origin, every voxel
// finite and in range); throws naming the block and the voxel.
void checkBlock(const BlockCheck& c, uint64_t i, const BlockIndex& b, const VoxelBlock& block) {
  for (int a = 0; a < 3; ++a) {
    const double extent = (std::abs(static_cast<double>(b[a])) + 1.0) * c.block_size;
    if (!(extent < kMaxExtentM)) {
      std::ostringstream msg;
      msg << blockName(i, b) << ": block index lies " << extent << " m from the origin (limit " << kMaxExtentM
          << " m): garbage index";
      fail(c.path, msg.str());
    }
  }
  for (int v = 0; v < FM_BLOCK_VOXELS; ++v) {
    const FmVoxel& vox = block.voxels[v];
    if (!(std::abs(vox.tsdf) <= 1.0f + kTsdfSlack) || !(vox.weight >= 0.0f) ||
        !(vox.weight <= c.max_weight * (1.0f + 1e-6f))) {
      std::ostringstream msg;
      msg << blockName(i, b) << ", voxel " << v << ": tsdf " << vox.tsdf << ", weight " << vox.weight
          << " (valid: finite, |tsdf| <= 1, 0 <= weight <= " << c.max_weight << ")";
      fail(c.path, msg.str());
    }
  }
}

// Adds a checked block to `loaded` unless it repeats an earlier one.
void addBlock(const BlockCheck& c, uint64_t i, const BlockIndex& b, std::unique_ptr<VoxelBlock> block,
              BlockMap* loaded, std::unordered_map<BlockIndex, uint64_t, BlockIndexHash>* ordinal) {
  checkBlock(c, i, b, *block);
  const auto [it, fresh] = ordinal->emplace(b, i);
  if (!fresh) fail(c.path, blockName(i, b) + ": duplicate of block #" + std::to_string(it->second));
  loaded->emplace(b, std::move(block));
}

// The blocks of a version 1 or 2 file (fixed-size records).
BlockMap readBlocksFixed(const MapFileInfo& info, const BlockCheck& c) {
  const std::string& path = c.path;
  const bool v2 = info.version == 2;
  const size_t header = v2 ? kHeaderV2 : kHeaderV1;
  const size_t record = v2 ? kRecordV2 : kRecordV1;
  // The block count against the file size, before allocating anything.
  const uint64_t room = info.file_size < header ? 0 : (info.file_size - header) / record;
  if (info.file_size < header || info.num_blocks > room) {
    std::ostringstream msg;
    msg << "truncated map file (block " << room << " of " << info.num_blocks << "): the header counts "
        << info.num_blocks << " blocks, the file has room for " << room;
    fail(path, msg.str());
  }
  if (info.file_size != header + info.num_blocks * record) {
    std::ostringstream msg;
    msg << "the header counts " << info.num_blocks << " blocks but the file holds " << (info.file_size - header)
        << " bytes of blocks (" << room << " blocks and " << (info.file_size - header) % record
        << " bytes): block count damaged or bytes appended";
    fail(path, msg.str());
  }
  std::ifstream f(path, std::ios::binary);
  f.seekg(static_cast<std::streamoff>(header));
  BlockMap loaded;
  std::unordered_map<BlockIndex, uint64_t, BlockIndexHash> ordinal;
  loaded.reserve(info.num_blocks);
  std::vector<char> buf(record);
  for (uint64_t i = 0; i < info.num_blocks; ++i) {
    f.read(buf.data(), static_cast<std::streamsize>(record));
    if (!f) {
      fail(path, "truncated map file (block " + std::to_string(i) + " of " + std::to_string(info.num_blocks) + ")");
    }
    const BlockIndex b(readAt<int32_t>(buf.data()), readAt<int32_t>(buf.data() + 4), readAt<int32_t>(buf.data() + 8));
    if (v2 && crc32(buf.data(), kPayload) != readAt<uint32_t>(buf.data() + kPayload)) {
      fail(path, blockName(i, b) + ": checksum mismatch (the block's bytes are damaged)");
    }
    auto block = std::make_unique<VoxelBlock>();
    std::memcpy(block->voxels.data(), buf.data() + 12, sizeof(block->voxels));
    addBlock(c, i, b, std::move(block), &loaded, &ordinal);
  }
  return loaded;
}

// Value s of n float32 values stored byte-plane by byte-plane at `planes`
// (layout at the top), and back.
void toPlanes(float value, unsigned char* planes, size_t n, size_t s) {
  unsigned char bytes[sizeof(float)];
  std::memcpy(bytes, &value, sizeof(float));
  for (size_t k = 0; k < sizeof(float); ++k) planes[k * n + s] = bytes[k];
}
float unplane(const unsigned char* planes, size_t n, size_t s) {
  unsigned char bytes[sizeof(float)];
  for (size_t k = 0; k < sizeof(float); ++k) bytes[k] = planes[k * n + s];
  float value;
  std::memcpy(&value, bytes, sizeof(float));
  return value;
}

// zlib's status as words.
std::string zlibError(int rc) {
  switch (rc) {
    case Z_DATA_ERROR: return "damaged or incomplete deflate data";
    case Z_BUF_ERROR: return "inflates to more than a block's bytes";
    case Z_MEM_ERROR: return "out of memory";
    default: return std::string("zlib error ") + std::to_string(rc);
  }
}

// Inflates block #i's payload (`packed`, n bytes) into `block`; throws naming
// the block when the stream is damaged or does not match its mask.
void inflateBlock(const BlockCheck& c, uint64_t i, const BlockIndex& b, const unsigned char* packed, uLong n,
                  VoxelBlock* block, uint32_t version) {
  std::array<unsigned char, kRawV4> raw;
  const bool grey = version >= 4;
  const size_t per_voxel = sizeof(FmVoxel) + (grey ? 1 : 0);
  uLongf raw_len = grey ? kRawV4 : kRawV3;
  uLong used = n;
  const int rc = uncompress2(raw.data(), &raw_len, packed, &used);
  const std::string name =
      blockName(i, b) + ": corrupt compressed voxels (format version " + std::to_string(version) + "): ";
  if (rc != Z_OK) fail(c.path, name + zlibError(rc));
  if (used != n) fail(c.path, name + std::to_string(n - used) + " bytes after the end of the zlib stream");
  if (raw_len < kMaskBytes) {
    fail(c.path, name + "inflates to " + std::to_string(raw_len) + " bytes, less than the 64-byte voxel mask");
  }
  size_t count = 0;
  for (size_t k = 0; k < kMaskBytes; ++k) count += static_cast<size_t>(__builtin_popcount(raw[k]));
  if (raw_len != kMaskBytes + count * per_voxel) {
    fail(c.path, name + "inflates to " + std::to_string(raw_len) + " bytes, its mask of " + std::to_string(count) +
                     " voxels needs " + std::to_string(kMaskBytes + count * per_voxel));
  }
  const unsigned char* tsdf = raw.data() + kMaskBytes;
  const unsigned char* weight = tsdf + count * sizeof(float);
  const unsigned char* intensity = weight + count * sizeof(float);
  size_t s = 0;
  for (int v = 0; v < FM_BLOCK_VOXELS; ++v) {
    if (!(raw[v / 8] & (1u << (v % 8)))) continue;
    block->voxels[v].tsdf = unplane(tsdf, count, s);
    block->voxels[v].weight = unplane(weight, count, s);
    if (grey) block->grey[v] = intensity[s];
    ++s;
  }
}

// The blocks of a version 3 or 4 file (variable-size, compressed records).
BlockMap readBlocksV3(const MapFileInfo& info, const BlockCheck& c) {
  const std::string& path = c.path;
  const uint64_t room = info.file_size < kHeaderV2 ? 0 : (info.file_size - kHeaderV2) / kMinRecordV3;
  if (info.num_blocks > room) {
    std::ostringstream msg;
    msg << "truncated map file (block " << room << " of " << info.num_blocks << "): the header counts "
        << info.num_blocks << " blocks, the file has room for at most " << room;
    fail(path, msg.str());
  }
  const uLong max_packed = compressBound(kRawV4);
  std::ifstream f(path, std::ios::binary);
  f.seekg(static_cast<std::streamoff>(kHeaderV2));
  BlockMap loaded;
  std::unordered_map<BlockIndex, uint64_t, BlockIndexHash> ordinal;
  loaded.reserve(info.num_blocks);
  std::vector<char> buf(kHeadV3 + max_packed + sizeof(uint32_t));
  uint64_t at = kHeaderV2;
  for (uint64_t i = 0; i < info.num_blocks; ++i) {
    const std::string truncated =
        "truncated map file (block " + std::to_string(i) + " of " + std::to_string(info.num_blocks) + ")";
    if (!f.read(buf.data(), kHeadV3)) fail(path, truncated);
    const BlockIndex b(readAt<int32_t>(buf.data()), readAt<int32_t>(buf.data() + 4), readAt<int32_t>(buf.data() + 8));
    const uint32_t packed = readAt<uint32_t>(buf.data() + 12);
    if (packed < 8 || packed > max_packed) {
      fail(path, blockName(i, b) + ": compressed size " + std::to_string(packed) + " bytes out of range (8.." +
                     std::to_string(max_packed) + "): damaged record");
    }
    if (!f.read(buf.data() + kHeadV3, packed + sizeof(uint32_t))) fail(path, truncated);
    if (crc32(buf.data(), kHeadV3 + packed) != readAt<uint32_t>(buf.data() + kHeadV3 + packed)) {
      fail(path, blockName(i, b) + ": checksum mismatch (the block's bytes are damaged)");
    }
    auto block = std::make_unique<VoxelBlock>();
    inflateBlock(c, i, b, reinterpret_cast<const unsigned char*>(buf.data() + kHeadV3), packed, block.get(),
                 info.version);
    addBlock(c, i, b, std::move(block), &loaded, &ordinal);
    at += kHeadV3 + packed + sizeof(uint32_t);
  }
  if (at != info.file_size) {
    std::ostringstream msg;
    msg << "the header counts " << info.num_blocks << " blocks but " << (info.file_size - at)
        << " bytes follow the last of them: block count damaged or bytes appended";
    fail(path, msg.str());
  }
  return loaded;
}

// Appends block b's version-2 record to `out`.
void appendRecordV2(const BlockIndex& b, const VoxelBlock& blk, std::vector<char>* out) {
  const int32_t idx[3] = {b.x(), b.y(), b.z()};
  const size_t at = out->size();
  out->resize(at + kRecordV2);
  char* r = out->data() + at;
  std::memcpy(r, idx, sizeof(idx));
  std::memcpy(r + sizeof(idx), blk.voxels.data(), sizeof(blk.voxels));
  const uint32_t crc = crc32(r, kPayload);
  std::memcpy(r + kPayload, &crc, sizeof(crc));
}

// Appends block b's version-3 or -4 record to `out` (layout at the top).
void appendRecordV3(const BlockIndex& b, const VoxelBlock& blk, std::vector<char>* out, const std::string& path,
                    uint32_t version) {
  std::array<unsigned char, kRawV4> raw{};
  static constexpr FmVoxel kEmpty{};
  const bool grey = version >= 4;
  size_t count = 0;
  for (int v = 0; v < FM_BLOCK_VOXELS; ++v) {
    if (std::memcmp(&blk.voxels[v], &kEmpty, sizeof(FmVoxel)) != 0 || (grey && blk.grey[v] != 0)) {
      raw[v / 8] |= 1u << (v % 8), ++count;
    }
  }
  unsigned char* tsdf = raw.data() + kMaskBytes;
  unsigned char* weight = tsdf + count * sizeof(float);
  unsigned char* intensity = weight + count * sizeof(float);
  size_t s = 0;
  for (int v = 0; v < FM_BLOCK_VOXELS; ++v) {
    if (!(raw[v / 8] & (1u << (v % 8)))) continue;
    toPlanes(blk.voxels[v].tsdf, tsdf, count, s);
    toPlanes(blk.voxels[v].weight, weight, count, s);
    if (grey) intensity[s] = blk.grey[v];
    ++s;
  }
  const size_t per_voxel = sizeof(FmVoxel) + (grey ? 1 : 0);
  const size_t at = out->size();
  uLongf packed = compressBound(kRawV4);
  out->resize(at + kHeadV3 + packed + sizeof(uint32_t));
  char* r = out->data() + at;
  const int rc = compress2(reinterpret_cast<unsigned char*>(r + kHeadV3), &packed, raw.data(),
                           kMaskBytes + count * per_voxel, kMapCompressionLevel);
  if (rc != Z_OK) fail(path, "cannot compress the block at " + indexText(b) + ": " + zlibError(rc));
  const int32_t idx[3] = {b.x(), b.y(), b.z()};
  const uint32_t size = static_cast<uint32_t>(packed);
  std::memcpy(r, idx, sizeof(idx));
  std::memcpy(r + 12, &size, sizeof(size));
  const uint32_t crc = crc32(r, kHeadV3 + packed);
  std::memcpy(r + kHeadV3 + packed, &crc, sizeof(crc));
  out->resize(at + kHeadV3 + packed + sizeof(uint32_t));
}

}  // namespace

MapFileInfo readMapFileHeader(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) fail(path, "is a directory, not a map file");
  // A FIFO or a device would block or stream without end (common/safe_open.h).
  if (const std::string why = regularFileProblem(path, kMaxMapFileBytes); !why.empty()) fail(path, why + ", not a map file");
  std::ifstream f(path, std::ios::binary);
  if (!f) fail(path, std::string("cannot open map file (") + std::strerror(errno) + ")");
  const uint64_t size = std::filesystem::file_size(path, ec);
  if (ec) fail(path, "cannot open map file (" + ec.message() + ")");
  char header[kHeaderV2] = {};
  f.read(header, sizeof(header));
  return parseHeader(path, header, static_cast<size_t>(f.gcount()), size);
}

void loadMapFile(BlockStore& store, const std::string& path) {
  const TsdfConfig& config = store.config();
  const MapFileInfo info = readMapFileHeader(path);
  if (info.voxel_size != config.voxel_size || info.truncation_voxels != config.truncation_voxels) {
    std::ostringstream msg;
    msg << "map has voxel_size " << info.voxel_size << " and truncation_voxels " << info.truncation_voxels
        << ", the node is configured with " << config.voxel_size << " and " << config.truncation_voxels;
    fail(path, msg.str());
  }
  const BlockCheck check{path, info.version == 1 ? config.max_weight : info.max_weight, config.blockSize()};
  // Read and check everything before touching the map.
  BlockMap loaded = info.version >= 3 ? readBlocksV3(info, check) : readBlocksFixed(info, check);
  store.replaceAll(std::move(loaded));
}

void saveMapFile(BlockStore& store, const std::string& path, const MapSaveOptions& options) {
  namespace fs = std::filesystem;
  if (path.empty()) throw std::runtime_error("cannot save the map: empty path");
  std::error_code ec;
  // A link at the path is replaced, never followed (SafeFileWriter); a FIFO
  // or a device is refused there.
  const fs::file_status st = fs::symlink_status(path, ec);
  if (fs::is_directory(st)) fail(path, "is a directory; give the map a file path (e.g. " + path + "/map.fmtsdf)");
  if (options.format_version < 2 || options.format_version > 4) {
    fail(path, "cannot write map format version " + std::to_string(options.format_version) + " (only 2, 3 or 4)");
  }
  if (options.refuse_empty_overwrite && store.numBlocks() == 0) {
    const std::string why = holdsData(path);
    if (!why.empty()) fail(path, "refusing to replace it by an empty map: " + why);
  }

  // Beside the target, never through a link at it; every write, the fsync,
  // the size and the close checked (SafeFileWriter).
  SafeFileWriter tmp(path);

  char header[kHeaderV2] = {};
  tmp.write(header, sizeof(header));  // filled in at the end
  std::vector<char> buf;
  buf.reserve(256 * kRecordV2);
  uint64_t n = 0;
  const uint32_t version = options.format_version;
  VoxelBlock from_disk;
  for (const BlockIndex& b : store.allBlocks()) {
    // Resident, cached, or read from its swap file into from_disk; nullptr
    // when that file is unreadable (the block is lost: saved without it).
    const VoxelBlock* blk = store.fetchInto(b, &from_disk);
    if (!blk) continue;
    if (version >= 3) {
      appendRecordV3(b, *blk, &buf, path, version);
    } else {
      appendRecordV2(b, *blk, &buf);
    }
    ++n;
    if (buf.size() >= 255 * kRecordV2) {
      tmp.write(buf.data(), buf.size());
      buf.clear();
    }
  }
  tmp.write(buf.data(), buf.size());
  if (n == 0 && options.refuse_empty_overwrite) {
    const std::string why = holdsData(path);
    if (!why.empty()) fail(path, "refusing to replace it by an empty map: " + why);
  }

  std::memcpy(header, kMagic, sizeof(kMagic));
  const double vs = store.config().voxel_size, tr = store.config().truncation_voxels;
  const float mw = store.config().max_weight;
  std::memcpy(header + 8, &version, 4);
  std::memcpy(header + 12, &vs, 8);
  std::memcpy(header + 20, &tr, 8);
  std::memcpy(header + 28, &n, 8);
  std::memcpy(header + 36, &mw, 4);
  const uint32_t hcrc = crc32(header, 40);
  std::memcpy(header + 40, &hcrc, 4);
  tmp.writeAt(header, sizeof(header), 0);
  // The previous file stays as <path>.1 when asked; path is replaced
  // atomically.
  tmp.commit(options.keep_previous);
}

}  // namespace fisheye_mapping
