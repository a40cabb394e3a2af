#include "fisheye_mapping/core/tsdf/tsdf_map.h"

#include "fisheye_mapping/core/tsdf/tsdf_integrator_cl.h"

#include <omp.h>

#include <chrono>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <limits>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace fisheye_mapping {
namespace {

int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

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
  if (integrator != "cpu" && integrator != "opencl") {
    throw std::invalid_argument("TsdfConfig.integrator must be 'cpu' or 'opencl', got '" + integrator + "'");
  }
}

// Unit rays of every pixel of one camera, computed once (unprojection inverts
// the distortion by Newton steps, too slow to repeat per frame).
struct TsdfMap::RayTable {
  FmCameraT<double> params;
  std::vector<Eigen::Vector3f> rays;  // NaN where the pixel is outside the model's domain
};

TsdfMap::TsdfMap(const TsdfConfig& config) : config_(config) {
  config_.validate();
  if (!config_.swap_directory.empty()) std::filesystem::create_directories(config_.swap_directory);
  if (config_.integrator == "opencl") opencl_ = std::make_unique<TsdfIntegratorCl>(config_.opencl_device);
}

TsdfMap::~TsdfMap() = default;

const TsdfMap::RayTable& TsdfMap::raysFor(const CameraModel& camera) {
  for (const auto& t : ray_tables_) {
    if (std::memcmp(&t->params, &camera.params(), sizeof(FmCameraT<double>)) == 0) return *t;
  }
  auto table = std::make_unique<RayTable>();
  table->params = camera.params();
  table->rays = pixelRays(camera);
  ray_tables_.push_back(std::move(table));
  return *ray_tables_.back();
}

bool TsdfMap::insideLocalMap(const BlockIndex& block) const {
  if (!has_local_center_) return true;
  const Eigen::Vector3d centre = (block.cast<double>() + Eigen::Vector3d::Constant(0.5)) * config_.blockSize();
  return ((centre - local_center_).cwiseAbs().array() <= 0.5 * config_.local_map_size.array()).all();
}

std::string TsdfMap::swapPath(const BlockIndex& b) const {
  std::ostringstream name;
  name << config_.swap_directory << "/block_" << b.x() << "_" << b.y() << "_" << b.z() << ".bin";
  return name.str();
}

// Swap file: the block's voxels, then the CRC32 of those bytes.
void TsdfMap::swapOut(const BlockIndex& index) {
  auto it = active_.find(index);
  if (it == active_.end()) return;
  std::unique_ptr<VoxelBlock> block = std::move(it->second);
  active_.erase(it);
  if (!config_.swap_directory.empty()) {
    const std::string path = swapPath(index);
    const uint32_t crc = crc32(block->voxels.data(), sizeof(block->voxels));
    bool ok = false;
    {
      std::ofstream f(path, std::ios::binary | std::ios::trunc);
      f.write(reinterpret_cast<const char*>(block->voxels.data()), sizeof(block->voxels));
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

bool TsdfMap::readSwapFile(const BlockIndex& index, VoxelBlock* out, std::string* why) const {
  const std::string path = swapPath(index);
  std::ifstream f(path, std::ios::binary);
  if (!f) {
    *why = std::string("cannot open (") + std::strerror(errno) + ")";
    return false;
  }
  uint32_t crc = 0;
  f.read(reinterpret_cast<char*>(out->voxels.data()), sizeof(out->voxels));
  f.read(reinterpret_cast<char*>(&crc), sizeof(crc));
  if (!f) {
    *why = "short file";
    return false;
  }
  if (f.peek() != std::char_traits<char>::eof()) {
    *why = "file longer than a block";
    return false;
  }
  if (crc32(out->voxels.data(), sizeof(out->voxels)) != crc) {
    *why = "checksum mismatch";
    return false;
  }
  return true;
}

void TsdfMap::reportSwapError(bool lost, const std::string& message) const {
  if (swap_error_cb_) {
    swap_error_cb_(lost, message);
  } else {
    std::fprintf(stderr, "[TsdfMap] %s\n", message.c_str());
  }
}

void TsdfMap::markLost(const BlockIndex& index, const std::string& why) const {
  const std::string path = swapPath(index);
  swapped_.erase(index);
  disk_cache_.erase(index);
  changed_.insert(index);  // its mesh is stale now
  ++lost_blocks_;
  std::error_code ec;
  std::filesystem::remove(path, ec);
  std::ostringstream msg;
  msg << "swapped block (" << index.x() << ", " << index.y() << ", " << index.z() << ") lost: " << path << ": " << why
      << "; the map goes on without it (" << lost_blocks_ << " lost so far)";
  reportSwapError(true, msg.str());
}

std::unique_ptr<VoxelBlock> TsdfMap::takeSwapped(const BlockIndex& index) {
  auto it = swapped_.find(index);
  if (it == swapped_.end()) return nullptr;
  std::unique_ptr<VoxelBlock> block = std::move(it->second);
  if (!block) {
    auto cached = disk_cache_.find(index);
    if (cached != disk_cache_.end()) {
      block = std::move(cached->second);
      disk_cache_.erase(cached);
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

size_t TsdfMap::moveLocalMap(const Eigen::Vector3d& vehicle_W) {
  local_center_ = vehicle_W + config_.local_map_offset;
  has_local_center_ = true;
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

IntegrationStats TsdfMap::integrate(const cv::Mat& depth, const CameraModel& camera,
                                    const Eigen::Isometry3d& T_W_C, const Eigen::Vector3d& vehicle_W) {
  if (depth.type() != CV_32FC1) {
    throw std::invalid_argument("depth image must be 32FC1 (metres of range along the ray), got OpenCV type " +
                                std::to_string(depth.type()));
  }
  if (depth.cols != camera.width() || depth.rows != camera.height()) {
    std::ostringstream msg;
    msg << "depth image is " << depth.cols << "x" << depth.rows << " but the camera is "
        << camera.width() << "x" << camera.height();
    throw std::invalid_argument(msg.str());
  }
  if (!T_W_C.matrix().allFinite() || !vehicle_W.allFinite()) {
    throw std::invalid_argument("camera pose or vehicle position is not finite");
  }
  if (config_.threads > 0) omp_set_num_threads(config_.threads);

  IntegrationStats stats;
  using Clock = std::chrono::steady_clock;
  auto ms_since = [](Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); };
  const auto t_start = Clock::now();
  const int nthreads = omp_get_max_threads();
  const size_t lost_before = lost_blocks_;
  local_center_ = vehicle_W + config_.local_map_offset;
  has_local_center_ = true;

  // 1. Allocation: blocks crossed by each valid ray between d - mu and d + mu.
  const RayTable& table = raysFor(camera);
  cv::Mat depth_c = depth.isContinuous() ? depth : depth.clone();
  if (config_.max_range > 0.0) {  // beyond max_range: no measurement
    if (depth_c.data == depth.data) depth_c = depth.clone();
    cv::Mat far = depth_c > config_.max_range;
    depth_c.setTo(std::numeric_limits<float>::quiet_NaN(), far);
  }
  const float* d_ptr = depth_c.ptr<float>();
  const float mu = static_cast<float>(config_.truncation());
  const float inv_block = static_cast<float>(1.0 / config_.blockSize());
  const float step = static_cast<float>(0.5 * config_.blockSize());
  const int n_steps = static_cast<int>(std::ceil(2.0f * mu / step)) + 1;
  const Eigen::Matrix3f R = T_W_C.linear().cast<float>();
  const Eigen::Vector3f t = T_W_C.translation().cast<float>();
  const int w = camera.width(), h = camera.height();
  std::vector<std::vector<BlockIndex>> per_thread(nthreads);
  size_t valid_pixels = 0;
#pragma omp parallel reduction(+ : valid_pixels)
  {
    std::vector<BlockIndex>& out = per_thread[omp_get_thread_num()];
    // Direct-mapped cache of recently emitted blocks: neighbouring pixels
    // mostly cross the same blocks.
    constexpr int kCache = 4096;
    std::vector<BlockIndex> cache(kCache, BlockIndex(INT32_MIN, INT32_MIN, INT32_MIN));
#pragma omp for schedule(dynamic, 8)
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const size_t i = static_cast<size_t>(v) * w + u;
        const float d = d_ptr[i];
        if (!(d > 0.0f) || d > 1e30f) continue;
        const Eigen::Vector3f& ray = table.rays[i];
        if (!(ray.z() == ray.z())) continue;
        ++valid_pixels;
        const Eigen::Vector3f dir_W = R * ray;
        const float start = std::max(d - mu, 0.0f);
        const float length = d + mu - start;
        for (int s = 0; s < n_steps; ++s) {
          const float r = start + length * s / (n_steps - 1);
          const Eigen::Vector3f p = t + r * dir_W;
          const BlockIndex b((p * inv_block).array().floor().cast<int>());
          const size_t slot = BlockIndexHash()(b) & (kCache - 1);
          if (cache[slot] == b) continue;
          cache[slot] = b;
          out.push_back(b);
        }
      }
    }
  }
  stats.valid_pixels = valid_pixels;
  BlockSet touched;
  for (const auto& list : per_thread) {
    for (const auto& b : list) {
      if (insideLocalMap(b)) touched.insert(b);
    }
  }
  stats.blocks_touched = touched.size();

  std::vector<std::pair<BlockIndex, VoxelBlock*>> work;
  work.reserve(touched.size());
  for (const auto& b : touched) {
    auto it = active_.find(b);
    if (it == active_.end()) {
      std::unique_ptr<VoxelBlock> block = takeSwapped(b);
      if (block) {
        ++stats.blocks_swapped_in;
      } else {
        block = std::make_unique<VoxelBlock>();
        ++stats.blocks_allocated;
      }
      it = active_.emplace(b, std::move(block)).first;
    }
    work.emplace_back(b, it->second.get());
  }

  stats.allocation_ms = ms_since(t_start);
  const auto t_integrate = Clock::now();

  // 2. Integration of every voxel of the touched blocks.
  const FmCameraT<float> cam = camera.floatParams();
  const Eigen::Isometry3d T_C_W_d = T_W_C.inverse();
  float T_C_W[12];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) T_C_W[4 * r + c] = static_cast<float>(T_C_W_d.matrix()(r, c));
  }
  std::vector<char> changed;
  if (opencl_) {
    opencl_->integrate(work, depth_c, cam, T_C_W, static_cast<float>(config_.voxel_size), mu,
                       config_.max_weight, &changed);
  } else {
    integrateCpu(work, d_ptr, cam, T_C_W, &changed);
  }
  for (size_t n = 0; n < work.size(); ++n) {
    if (changed[n]) changed_.insert(work[n].first);
  }

  stats.integration_ms = ms_since(t_integrate);

  // 3. Local map: swap out what the vehicle left behind.
  const auto t_local = Clock::now();
  stats.blocks_swapped_out = moveLocalMap(vehicle_W);
  stats.local_map_ms = ms_since(t_local);
  stats.blocks_lost = lost_blocks_ - lost_before;
  return stats;
}

void TsdfMap::integrateCpu(const std::vector<std::pair<BlockIndex, VoxelBlock*>>& work, const float* depth,
                           const FmCameraT<float>& cam, const float T_C_W[12], std::vector<char>* changed) const {
  const float vs = static_cast<float>(config_.voxel_size);
  const float mu = static_cast<float>(config_.truncation());
  const float max_w = config_.max_weight;
  changed->assign(work.size(), 0);
#pragma omp parallel for schedule(dynamic, 4)
  for (size_t n = 0; n < work.size(); ++n) {
    const BlockIndex& b = work[n].first;
    FmVoxel* voxels = work[n].second->voxels.data();
    const Eigen::Vector3f origin = (b * FM_BLOCK_SIDE).cast<float>();
    int any = 0;
    for (int k = 0; k < FM_BLOCK_SIDE; ++k) {
      const float pz = (origin.z() + k + 0.5f) * vs;
      for (int j = 0; j < FM_BLOCK_SIDE; ++j) {
        const float py = (origin.y() + j + 0.5f) * vs;
        for (int i = 0; i < FM_BLOCK_SIDE; ++i) {
          const float px = (origin.x() + i + 0.5f) * vs;
          any |= fm_tsdf_integrate_voxel(&voxels[VoxelBlock::linear(i, j, k)], px, py, pz, &cam, T_C_W,
                                         depth, mu, max_w);
        }
      }
    }
    (*changed)[n] = static_cast<char>(any);
  }
}

const VoxelBlock* TsdfMap::block(const BlockIndex& index) const {
  auto it = active_.find(index);
  if (it != active_.end()) return it->second.get();
  auto st = swapped_.find(index);
  if (st == swapped_.end()) return nullptr;
  if (st->second) return st->second.get();
  auto cached = disk_cache_.find(index);
  if (cached != disk_cache_.end()) return cached->second.get();
  auto block = std::make_unique<VoxelBlock>();
  std::string why;
  if (!readSwapFile(index, block.get(), &why)) {
    markLost(index, why);
    return nullptr;
  }
  return disk_cache_.emplace(index, std::move(block)).first->second.get();
}

const FmVoxel* TsdfMap::voxel(const Eigen::Vector3i& g) const {
  const BlockIndex b(floorDiv(g.x(), FM_BLOCK_SIDE), floorDiv(g.y(), FM_BLOCK_SIDE),
                     floorDiv(g.z(), FM_BLOCK_SIDE));
  const VoxelBlock* blk = block(b);
  if (!blk) return nullptr;
  const Eigen::Vector3i l = g - b * FM_BLOCK_SIDE;
  return &blk->voxels[VoxelBlock::linear(l.x(), l.y(), l.z())];
}

std::vector<BlockIndex> TsdfMap::allBlocks() const {
  std::vector<BlockIndex> out;
  out.reserve(numBlocks());
  for (const auto& kv : active_) out.push_back(kv.first);
  for (const auto& kv : swapped_) out.push_back(kv.first);
  return out;
}

BlockSet TsdfMap::takeChangedBlocks() {
  BlockSet out;
  out.swap(changed_);
  return out;
}

// save / load / readHeader: tsdf_io.cpp.

void TsdfMap::clear() {
  for (const auto& kv : swapped_) {
    std::error_code ec;  // a file already gone is no error here
    if (!kv.second) std::filesystem::remove(swapPath(kv.first), ec);
  }
  active_.clear();
  swapped_.clear();
  disk_cache_.clear();
  changed_.clear();
}

}  // namespace fisheye_mapping
