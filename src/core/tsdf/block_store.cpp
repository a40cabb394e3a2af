#include "fisheye_mapping/core/tsdf/block_store.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace fisheye_mapping {
namespace {

struct CrcTable {
  uint32_t t[256];
  constexpr CrcTable() : t() {
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
  }
};
constexpr CrcTable kCrc;

}  // namespace

uint32_t crc32(const void* data, size_t size, uint32_t crc) {
  const unsigned char* p = static_cast<const unsigned char*>(data);
  uint32_t c = ~crc;
  for (size_t i = 0; i < size; ++i) c = kCrc.t[(c ^ p[i]) & 0xFFu] ^ (c >> 8);
  return ~c;
}

BlockStore::BlockStore(const TsdfConfig& config) : config_(config) {
  if (!config_.swap_directory.empty()) std::filesystem::create_directories(config_.swap_directory);
}

BlockStore::~BlockStore() = default;

void BlockStore::setLocalCenter(const Eigen::Vector3d& vehicle_W) {
  local_center_ = vehicle_W + config_.local_map_offset;
  has_local_center_ = true;
}

bool BlockStore::insideLocalMap(const BlockIndex& block) const {
  if (!has_local_center_) return true;
  const Eigen::Vector3d centre = (block.cast<double>() + Eigen::Vector3d::Constant(0.5)) * config_.blockSize();
  return ((centre - local_center_).cwiseAbs().array() <= 0.5 * config_.local_map_size.array()).all();
}

std::string BlockStore::swapPath(const BlockIndex& b) const {
  std::ostringstream name;
  name << config_.swap_directory << "/block_" << b.x() << "_" << b.y() << "_" << b.z() << ".bin";
  return name.str();
}

// Swap file: the block's voxels, its intensities, then the CRC32 of those bytes.
void BlockStore::swapOut(const BlockIndex& index) {
  auto it = active_.find(index);
  if (it == active_.end()) return;
  std::unique_ptr<VoxelBlock> block = std::move(it->second);
  active_.erase(it);
  if (!config_.swap_directory.empty()) {
    const std::string path = swapPath(index);
    const uint32_t crc =
        crc32(block->grey.data(), sizeof(block->grey), crc32(block->voxels.data(), sizeof(block->voxels)));
    bool ok = false;
    {
      std::ofstream f(path, std::ios::binary | std::ios::trunc);
      f.write(reinterpret_cast<const char*>(block->voxels.data()), sizeof(block->voxels));
      f.write(reinterpret_cast<const char*>(block->grey.data()), sizeof(block->grey));
      f.write(reinterpret_cast<const char*>(&crc), sizeof(crc));
      f.close();
      ok = static_cast<bool>(f);
    }
    if (ok) {
      block.reset();
    } else {
      // Keep the block in RAM rather than lose it.
      std::error_code ec;
      std::filesystem::remove(path, ec);
      ++swap_write_failures_;
      std::ostringstream msg;
      msg << "cannot write swap file " << path << " (" << std::strerror(errno) << "): block (" << index.x() << ", "
          << index.y() << ", " << index.z() << ") stays in RAM";
      reportSwapError(false, msg.str());
    }
  }
  swapped_[index] = std::move(block);
}

bool BlockStore::readSwapFile(const BlockIndex& index, VoxelBlock* out, std::string* why) const {
  const std::string path = swapPath(index);
  std::ifstream f(path, std::ios::binary);
  if (!f) {
    *why = std::string("cannot open (") + std::strerror(errno) + ")";
    return false;
  }
  uint32_t crc = 0;
  f.read(reinterpret_cast<char*>(out->voxels.data()), sizeof(out->voxels));
  f.read(reinterpret_cast<char*>(out->grey.data()), sizeof(out->grey));
  f.read(reinterpret_cast<char*>(&crc), sizeof(crc));
  if (!f) {
    *why = "short file";
    return false;
  }
  if (f.peek() != std::char_traits<char>::eof()) {
    *why = "file longer than a block";
    return false;
  }
  if (crc32(out->grey.data(), sizeof(out->grey), crc32(out->voxels.data(), sizeof(out->voxels))) != crc) {
    *why = "checksum mismatch";
    return false;
  }
  return true;
}

void BlockStore::reportSwapError(bool lost, const std::string& message) const {
  if (swap_error_cb_) {
    swap_error_cb_(lost, message);
  } else {
    std::fprintf(stderr, "[TsdfMap] %s\n", message.c_str());
  }
}

void BlockStore::markLost(const BlockIndex& index, const std::string& why) {
  const std::string path = swapPath(index);
  swapped_.erase(index);
  read_cache_.erase(index);
  changed_.insert(index);  // its mesh is stale now
  ++lost_blocks_;
  std::error_code ec;
  std::filesystem::remove(path, ec);
  std::ostringstream msg;
  msg << "swapped block (" << index.x() << ", " << index.y() << ", " << index.z() << ") lost: " << path << ": " << why
      << "; the map goes on without it (" << lost_blocks_ << " lost so far)";
  reportSwapError(true, msg.str());
}

std::unique_ptr<VoxelBlock> BlockStore::takeSwapped(const BlockIndex& index) {
  auto it = swapped_.find(index);
  if (it == swapped_.end()) return nullptr;
  std::unique_ptr<VoxelBlock> block = std::move(it->second);
  if (!block) {
    auto cached = read_cache_.find(index);
    if (cached != read_cache_.end()) {
      block = std::move(cached->second);
      read_cache_.erase(cached);
    } else {
      block = std::make_unique<VoxelBlock>();
      std::string why;
      if (!readSwapFile(index, block.get(), &why)) {
        markLost(index, why);
        return nullptr;
      }
    }
    std::error_code ec;
    std::filesystem::remove(swapPath(index), ec);
  }
  swapped_.erase(index);
  return block;
}

size_t BlockStore::moveLocalMap(const Eigen::Vector3d& vehicle_W) {
  setLocalCenter(vehicle_W);
  std::vector<BlockIndex> leaving, returning;
  for (const auto& kv : active_) {
    if (!insideLocalMap(kv.first)) leaving.push_back(kv.first);
  }
  for (const auto& kv : swapped_) {
    if (insideLocalMap(kv.first)) returning.push_back(kv.first);
  }
  for (const auto& b : leaving) swapOut(b);
  for (const auto& b : returning) {
    std::unique_ptr<VoxelBlock> block = takeSwapped(b);
    if (block) active_[b] = std::move(block);
  }
  return leaving.size();
}

BlockWork BlockStore::allocate(const BlockSet& touched, size_t* allocated, size_t* swapped_in) {
  BlockWork work;
  work.reserve(touched.size());
  for (const auto& b : touched) {
    auto it = active_.find(b);
    if (it == active_.end()) {
      std::unique_ptr<VoxelBlock> block = takeSwapped(b);
      if (block) {
        ++*swapped_in;
      } else {
        block = std::make_unique<VoxelBlock>();
        ++*allocated;
      }
      it = active_.emplace(b, std::move(block)).first;
    }
    work.emplace_back(b, it->second.get());
  }
  return work;
}

const VoxelBlock* BlockStore::find(const BlockIndex& index) const {
  auto it = active_.find(index);
  if (it != active_.end()) return it->second.get();
  auto st = swapped_.find(index);
  if (st == swapped_.end()) return nullptr;
  if (st->second) return st->second.get();
  auto cached = read_cache_.find(index);
  return cached != read_cache_.end() ? cached->second.get() : nullptr;
}

const VoxelBlock* BlockStore::fetchInto(const BlockIndex& index, VoxelBlock* scratch) {
  if (const VoxelBlock* found = find(index)) return found;
  if (swapped_.count(index) == 0) return nullptr;  // not in the map
  std::string why;
  if (!readSwapFile(index, scratch, &why)) {
    markLost(index, why);
    return nullptr;
  }
  return scratch;
}

const VoxelBlock* BlockStore::fetch(const BlockIndex& index) {
  if (const VoxelBlock* found = find(index)) return found;
  if (swapped_.count(index) == 0) return nullptr;  // not in the map
  auto block = std::make_unique<VoxelBlock>();
  std::string why;
  if (!readSwapFile(index, block.get(), &why)) {
    markLost(index, why);
    return nullptr;
  }
  return read_cache_.emplace(index, std::move(block)).first->second.get();
}

size_t BlockStore::memoryBytes() const {
  size_t in_ram = active_.size() + read_cache_.size();
  for (const auto& kv : swapped_) in_ram += kv.second != nullptr;
  return in_ram * sizeof(VoxelBlock);
}

std::vector<BlockIndex> BlockStore::allBlocks() const {
  std::vector<BlockIndex> out;
  out.reserve(numBlocks());
  for (const auto& kv : active_) out.push_back(kv.first);
  for (const auto& kv : swapped_) out.push_back(kv.first);
  return out;
}

std::vector<BlockIndex> BlockStore::activeBlocks() const {
  std::vector<BlockIndex> out;
  out.reserve(active_.size());
  for (const auto& kv : active_) out.push_back(kv.first);
  return out;
}

BlockSet BlockStore::takeChangedBlocks() {
  BlockSet out;
  out.swap(changed_);
  return out;
}

void BlockStore::replaceAll(BlockMap blocks) {
  clear();
  for (auto& kv : blocks) {
    changed_.insert(kv.first);
    active_[kv.first] = std::move(kv.second);
    if (!insideLocalMap(kv.first)) swapOut(kv.first);
  }
}

void BlockStore::clear() {
  for (const auto& kv : swapped_) {
    std::error_code ec;  // a file already gone is no error here
    if (!kv.second) std::filesystem::remove(swapPath(kv.first), ec);
  }
  active_.clear();
  swapped_.clear();
  read_cache_.clear();
  changed_.clear();
}

}  // namespace fisheye_mapping
