#include "fisheye_mapping/core/tsdf/tsdf_map.h"

#include "fisheye_mapping/core/tsdf/tsdf_integrator_cpu.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace fisheye_mapping {
namespace {

int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

// Unit rays of every pixel of one camera, computed once (unprojection inverts
// the distortion by Newton steps, too slow to repeat per frame).
struct TsdfMap::RayTable {
  FmCameraT<double> params;
  std::vector<Eigen::Vector3f> rays;  // NaN where the pixel is outside the model's domain
};

namespace {

TsdfConfig validated(const TsdfConfig& config) {
  config.validate();
  return config;
}

}  // namespace

TsdfMap::TsdfMap(const TsdfConfig& config)
    : config_(validated(config)),
      store_(std::make_unique<BlockStore>(config_)),
      integrator_(makeTsdfIntegrator(config_)) {}

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

IntegrationStats TsdfMap::integrate(const cv::Mat& depth, const CameraModel& camera,
                                    const Eigen::Isometry3d& T_W_C, const Eigen::Vector3d& vehicle_W,
                                    const std::vector<Eigen::AlignedBox3d>& carve, const cv::Mat& grey,
                                    float observation_weight) {
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
  if (!grey.empty() && grey.type() != CV_8UC1) {
    throw std::invalid_argument("intensity image must be mono8 (CV_8UC1), got OpenCV type " +
                                std::to_string(grey.type()));
  }
  if (!grey.empty() && (grey.cols != camera.width() || grey.rows != camera.height())) {
    std::ostringstream msg;
    msg << "intensity image is " << grey.cols << "x" << grey.rows << " but the camera is " << camera.width() << "x"
        << camera.height();
    throw std::invalid_argument(msg.str());
  }
  if (!T_W_C.matrix().allFinite() || !vehicle_W.allFinite()) {
    throw std::invalid_argument("camera pose or vehicle position is not finite");
  }
  if (!(observation_weight > 0.0f && observation_weight <= 1.0f)) {
    throw std::invalid_argument("observation weight must be in (0, 1], got " + std::to_string(observation_weight));
  }

  IntegrationStats stats;
  using Clock = std::chrono::steady_clock;
  auto ms_since = [](Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); };
  const auto t_start = Clock::now();
  // The loops' num_threads clause; the process-wide setting is left alone.
  const int nthreads = config_.threads > 0 ? config_.threads : omp_get_max_threads();
  const size_t lost_before = store_->numLostBlocks();
  store_->setLocalCenter(vehicle_W);

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
  float R[9], t[3];
  for (int r = 0; r < 3; ++r) {
    t[r] = static_cast<float>(T_W_C.translation()(r));
    for (int c = 0; c < 3; ++c) R[3 * r + c] = static_cast<float>(T_W_C.linear()(r, c));
  }
  const int w = camera.width(), h = camera.height();
  const float* rays = table.rays.data()->data();  // Eigen::Vector3f: 3 packed floats
  // A team never has more threads than num_threads asks for.
  std::vector<std::vector<BlockIndex>> per_thread(nthreads);
  size_t valid_pixels = 0;
#pragma omp parallel num_threads(nthreads) reduction(+ : valid_pixels)
  {
    std::vector<BlockIndex>& out = per_thread[omp_get_thread_num()];
    // Each row's samples (tsdfRowBlockSamples, vectorized), then deduplicated:
    // neighbouring pixels mostly cross the same blocks, so a sample equal to
    // the previous pixel's at the same step is dropped at once, and the rest
    // go through a direct-mapped cache of recently emitted blocks.
    std::vector<float> scratch(5 * static_cast<size_t>(w));
    std::vector<int> keys(3 * static_cast<size_t>(n_steps) * w), valid(w);
    constexpr int kCache = 4096;
    std::vector<BlockIndex> cache(kCache, BlockIndex(INT32_MIN, INT32_MIN, INT32_MIN));
#pragma omp for schedule(dynamic, 8)
    for (int v = 0; v < h; ++v) {
      const size_t row = static_cast<size_t>(v) * w;
      tsdfRowBlockSamples(d_ptr + row, rays + 3 * row, w, R, t, mu, inv_block, n_steps, scratch.data(), keys.data(),
                          valid.data());
      for (int u = 0; u < w; ++u) valid_pixels += valid[u];
      for (int s = 0; s < n_steps; ++s) {
        const int* kx = keys.data() + 3 * s * w;
        const int* ky = kx + w;
        const int* kz = ky + w;
        BlockIndex last(INT32_MIN, INT32_MIN, INT32_MIN);
        for (int u = 0; u < w; ++u) {
          if (!valid[u]) continue;
          const BlockIndex b(kx[u], ky[u], kz[u]);
          if (b == last) continue;
          last = b;
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
      if (store_->insideLocalMap(b)) touched.insert(b);
    }
  }
  // Carve regions: their blocks in memory, however far from this frame's surfaces.
  for (const Eigen::AlignedBox3d& region : carve) {
    if (region.isEmpty() || !region.min().allFinite() || !region.max().allFinite()) continue;
    const Eigen::Vector3i lo = (region.min() / config_.blockSize()).array().floor().cast<int>();
    const Eigen::Vector3i hi = (region.max() / config_.blockSize()).array().floor().cast<int>();
    if (((hi - lo).array() > 256).any()) continue;  // not a vehicle's region
    for (int x = lo.x(); x <= hi.x(); ++x)
      for (int y = lo.y(); y <= hi.y(); ++y)
        for (int z = lo.z(); z <= hi.z(); ++z) {
          const BlockIndex b(x, y, z);
          if (store_->isActive(b) && store_->insideLocalMap(b)) touched.insert(b);
        }
  }
  const FmCameraT<float> cam = camera.floatParams();
  const Eigen::Isometry3d T_C_W_d = T_W_C.inverse();
  float T_C_W[12];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) T_C_W[4 * r + c] = static_cast<float>(T_C_W_d.matrix()(r, c));
  }
  // Free-space carving: the active blocks this frame sees wholly in front of
  // its measured surface. A block's centre is projected; when the pixel's
  // range exceeds the centre's by more than mu plus half the block's
  // diagonal, no voxel of the block lies in the surface's band at that pixel,
  // so no ray of this frame allocated it, yet its voxels see free space: the
  // integration below gives them the free-space update, and a surface that
  // earlier frames fused there by mistake is averaged away.
  if (config_.free_space_carving) {
    const float bs = static_cast<float>(config_.blockSize());
    const float margin = mu + 0.5f * std::sqrt(3.0f) * bs;
    for (const BlockIndex& b : store_->activeBlocks()) {
      if (touched.count(b)) continue;
      const float px = (static_cast<float>(b.x()) + 0.5f) * bs;
      const float py = (static_cast<float>(b.y()) + 0.5f) * bs;
      const float pz = (static_cast<float>(b.z()) + 0.5f) * bs;
      const float x = T_C_W[0] * px + T_C_W[1] * py + T_C_W[2] * pz + T_C_W[3];
      const float y = T_C_W[4] * px + T_C_W[5] * py + T_C_W[6] * pz + T_C_W[7];
      const float z = T_C_W[8] * px + T_C_W[9] * py + T_C_W[10] * pz + T_C_W[11];
      const int pixel = fm_tsdf_voxel_pixel(&cam, x, y, z);
      if (pixel < 0) continue;
      const float measured = d_ptr[pixel];  // NaN beyond max_range
      if (measured > 0.0f && measured <= 1e30f && measured - std::sqrt(x * x + y * y + z * z) > margin) {
        touched.insert(b);
        ++stats.blocks_carved;
      }
    }
  }
  stats.blocks_touched = touched.size();
  const BlockWork work = store_->allocate(touched, &stats.blocks_allocated, &stats.blocks_swapped_in);

  stats.allocation_ms = ms_since(t_start);
  const auto t_integrate = Clock::now();

  // 2. Integration of every voxel of the touched blocks.
  std::vector<char> changed;
  const cv::Mat grey_c = grey.empty() || grey.isContinuous() ? grey : grey.clone();
  integrator_->integrate(work, depth_c, grey_c, cam, T_C_W, observation_weight, &changed);
  for (size_t n = 0; n < work.size(); ++n) {
    if (changed[n]) store_->markChanged(work[n].first);
  }

  stats.integration_ms = ms_since(t_integrate);

  // 3. Local map: swap out what the vehicle left behind.
  const auto t_local = Clock::now();
  stats.blocks_swapped_out = store_->moveLocalMap(vehicle_W);
  stats.local_map_ms = ms_since(t_local);
  stats.blocks_lost = store_->numLostBlocks() - lost_before;
  return stats;
}

namespace {

const FmVoxel* voxelIn(const VoxelBlock* blk, const BlockIndex& b, const Eigen::Vector3i& g) {
  if (!blk) return nullptr;
  const Eigen::Vector3i l = g - b * FM_BLOCK_SIDE;
  return &blk->voxels[VoxelBlock::linear(l.x(), l.y(), l.z())];
}

BlockIndex blockOf(const Eigen::Vector3i& g) {
  return BlockIndex(floorDiv(g.x(), FM_BLOCK_SIDE), floorDiv(g.y(), FM_BLOCK_SIDE), floorDiv(g.z(), FM_BLOCK_SIDE));
}

}  // namespace

const FmVoxel* TsdfMap::voxel(const Eigen::Vector3i& g) {
  const BlockIndex b = blockOf(g);
  return voxelIn(block(b), b, g);
}

int TsdfMap::grey(const Eigen::Vector3i& g) {
  const BlockIndex b = blockOf(g);
  const VoxelBlock* blk = block(b);
  if (!blk) return -1;
  const Eigen::Vector3i l = g - b * FM_BLOCK_SIDE;
  return blk->grey[VoxelBlock::linear(l.x(), l.y(), l.z())];
}

const FmVoxel* TsdfMap::voxel(const Eigen::Vector3i& g) const {
  const BlockIndex b = blockOf(g);
  return voxelIn(block(b), b, g);
}

}  // namespace fisheye_mapping
