// TSDF map files: save (atomic, checksummed), load (validated before anything
// is replaced), readMapFileHeader. The CRC-32 is block_store.h's.
//
// Layout, little-endian (version 2, written now):
//   0  char[8]  "FMTSDF01"
//   8  uint32   version = 2
//  12  float64  voxel_size
//  20  float64  truncation_voxels
//  28  uint64   number of blocks N
//  36  float32  max_weight (the cap of the voxels' weights)
//  40  uint32   CRC-32 of bytes 0..39
//  44  N records: int32 x, y, z (block index); 512 x {float32 tsdf, float32
//      weight} (x fastest); uint32 CRC-32 of the record's first 4108 bytes
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

namespace fisheye_mapping {
namespace {

constexpr char kMagic[8] = {'F', 'M', 'T', 'S', 'D', 'F', '0', '1'};
constexpr uint32_t kVersion = 2;
constexpr size_t kHeaderV1 = 36;
constexpr size_t kHeaderV2 = 44;
constexpr size_t kPayload = 3 * sizeof(int32_t) + sizeof(VoxelBlock::voxels);  // 4108
constexpr size_t kRecordV1 = kPayload;
constexpr size_t kRecordV2 = kPayload + sizeof(uint32_t);
// Block indices beyond this many metres from the origin are garbage.
constexpr double kMaxExtentM = 1e5;
constexpr float kTsdfSlack = 1e-4f;  // rounding of the running average

static_assert(sizeof(FmVoxel) == 8, "map files store 8-byte voxels");
static_assert(sizeof(VoxelBlock::voxels) == 4096, "map files store 512 voxels per block");

std::string blockName(uint64_t ordinal, const BlockIndex& b) {
  std::ostringstream s;
  s << "block #" << ordinal << " (" << b.x() << ", " << b.y() << ", " << b.z() << ")";
  return s.str();
}

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
  if (info.version == 2) {
    if (available < kHeaderV2) fail(path, "not a fisheye_mapping TSDF map (bad header: too short)");
    info.max_weight = readAt<float>(bytes + 36);
    if (crc32(bytes, 40) != readAt<uint32_t>(bytes + 40)) {
      fail(path, "header checksum mismatch (the header is damaged)");
    }
    if (!(info.max_weight > 0.0f) || !std::isfinite(info.max_weight)) {
      fail(path, "bad header: max_weight " + std::to_string(info.max_weight));
    }
  } else if (info.version != 1) {
    fail(path, "not a fisheye_mapping TSDF map (bad header: unknown version " + std::to_string(info.version) + ")");
  }
  if (!(info.voxel_size > 0.0) || !std::isfinite(info.voxel_size) || !(info.truncation_voxels > 0.0) ||
      !std::isfinite(info.truncation_voxels)) {
    fail(path, "not a fisheye_mapping TSDF map (bad header: voxel size or truncation)");
  }
  return info;
}

// Writes all of [data, data + n) to fd; throws on error.
void writeAll(int fd, const char* data, size_t n, const std::string& path) {
  while (n > 0) {
    const ssize_t w = ::write(fd, data, n);
    if (w < 0) {
      if (errno == EINTR) continue;
      fail(path, std::string("write failed: ") + std::strerror(errno));
    }
    data += w;
    n -= static_cast<size_t>(w);
  }
}

// The temporary file of a save: closed and removed unless committed.
struct TmpFile {
  std::string path;
  int fd = -1;
  bool keep = false;
  ~TmpFile() {
    if (fd >= 0) ::close(fd);
    if (!keep && !path.empty()) ::unlink(path.c_str());
  }
};

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

}  // namespace

MapFileInfo readMapFileHeader(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) fail(path, "is a directory, not a map file");
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
  const float max_weight = v2 ? info.max_weight : config.max_weight;
  const double block_size = config.blockSize();

  // Read and check everything before touching the map.
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
    for (int a = 0; a < 3; ++a) {
      const double extent = (std::abs(static_cast<double>(b[a])) + 1.0) * block_size;
      if (!(extent < kMaxExtentM)) {
        std::ostringstream msg;
        msg << blockName(i, b) << ": block index lies " << extent << " m from the origin (limit " << kMaxExtentM
            << " m): garbage index";
        fail(path, msg.str());
      }
    }
    auto block = std::make_unique<VoxelBlock>();
    std::memcpy(block->voxels.data(), buf.data() + 12, sizeof(block->voxels));
    for (int v = 0; v < FM_BLOCK_VOXELS; ++v) {
      const FmVoxel& vox = block->voxels[v];
      if (!(std::abs(vox.tsdf) <= 1.0f + kTsdfSlack) || !(vox.weight >= 0.0f) ||
          !(vox.weight <= max_weight * (1.0f + 1e-6f))) {
        std::ostringstream msg;
        msg << blockName(i, b) << ", voxel " << v << ": tsdf " << vox.tsdf << ", weight " << vox.weight
            << " (valid: finite, |tsdf| <= 1, 0 <= weight <= " << max_weight << ")";
        fail(path, msg.str());
      }
    }
    const auto [it, fresh] = ordinal.emplace(b, i);
    if (!fresh) fail(path, blockName(i, b) + ": duplicate of block #" + std::to_string(it->second));
    loaded.emplace(b, std::move(block));
  }

  store.replaceAll(std::move(loaded));
}

void saveMapFile(BlockStore& store, const std::string& path, const MapSaveOptions& options) {
  namespace fs = std::filesystem;
  if (path.empty()) throw std::runtime_error("cannot save the map: empty path");
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (fs::is_directory(st)) fail(path, "is a directory; give the map a file path (e.g. " + path + "/map.fmtsdf)");
  if (fs::exists(st) && !fs::is_regular_file(st)) fail(path, "exists and is not a regular file");
  if (options.refuse_empty_overwrite && store.numBlocks() == 0) {
    const std::string why = holdsData(path);
    if (!why.empty()) fail(path, "refusing to replace it by an empty map: " + why);
  }

  TmpFile tmp;
  const std::string tmp_path = path + ".tmp";
  if (fs::is_directory(tmp_path, ec)) fail(path, tmp_path + " is a directory; cannot write the map beside it");
  tmp.fd = ::open(tmp_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (tmp.fd < 0) fail(path, "cannot write " + tmp_path + ": " + std::strerror(errno));
  tmp.path = tmp_path;

  char header[kHeaderV2] = {};
  writeAll(tmp.fd, header, sizeof(header), path);  // filled in at the end
  std::vector<char> buf;
  buf.reserve(256 * kRecordV2);
  uint64_t n = 0;
  VoxelBlock from_disk;
  for (const BlockIndex& b : store.allBlocks()) {
    // Resident, cached, or read from its swap file into from_disk; nullptr
    // when that file is unreadable (the block is lost: saved without it).
    const VoxelBlock* blk = store.fetchInto(b, &from_disk);
    if (!blk) continue;
    const int32_t idx[3] = {b.x(), b.y(), b.z()};
    const size_t at = buf.size();
    buf.resize(at + kRecordV2);
    std::memcpy(buf.data() + at, idx, sizeof(idx));
    std::memcpy(buf.data() + at + sizeof(idx), blk->voxels.data(), sizeof(blk->voxels));
    const uint32_t crc = crc32(buf.data() + at, kPayload);
    std::memcpy(buf.data() + at + kPayload, &crc, sizeof(crc));
    ++n;
    if (buf.size() >= 255 * kRecordV2) {
      writeAll(tmp.fd, buf.data(), buf.size(), path);
      buf.clear();
    }
  }
  writeAll(tmp.fd, buf.data(), buf.size(), path);
  if (n == 0 && options.refuse_empty_overwrite) {
    const std::string why = holdsData(path);
    if (!why.empty()) fail(path, "refusing to replace it by an empty map: " + why);
  }

  std::memcpy(header, kMagic, sizeof(kMagic));
  const double vs = store.config().voxel_size, tr = store.config().truncation_voxels;
  const float mw = store.config().max_weight;
  std::memcpy(header + 8, &kVersion, 4);
  std::memcpy(header + 12, &vs, 8);
  std::memcpy(header + 20, &tr, 8);
  std::memcpy(header + 28, &n, 8);
  std::memcpy(header + 36, &mw, 4);
  const uint32_t hcrc = crc32(header, 40);
  std::memcpy(header + 40, &hcrc, 4);
  if (::pwrite(tmp.fd, header, sizeof(header), 0) != static_cast<ssize_t>(sizeof(header))) {
    fail(path, std::string("write failed: ") + std::strerror(errno));
  }
  if (::fsync(tmp.fd) != 0) fail(path, std::string("write failed (fsync): ") + std::strerror(errno));
  const int fd = tmp.fd;
  tmp.fd = -1;
  if (::close(fd) != 0) fail(path, std::string("write failed (close): ") + std::strerror(errno));

  if (options.keep_previous && fs::is_regular_file(path, ec)) {
    // The previous file stays as <path>.1: a hard link (atomic, no copy),
    // else a copy; path itself is replaced atomically below.
    const std::string prev = path + ".1";
    fs::remove(prev, ec);
    if (::link(path.c_str(), prev.c_str()) != 0) {
      ec.clear();
      fs::copy_file(path, prev, fs::copy_options::overwrite_existing, ec);
      if (ec) fail(path, "cannot keep the previous map as " + prev + ": " + ec.message() + "; nothing replaced");
    }
  }
  if (::rename(tmp_path.c_str(), path.c_str()) != 0) {
    fail(path, "cannot replace it with " + tmp_path + ": " + std::strerror(errno));
  }
  tmp.keep = true;
  // Make the rename durable too.
  const fs::path dir = fs::path(path).has_parent_path() ? fs::path(path).parent_path() : fs::path(".");
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

}  // namespace fisheye_mapping
