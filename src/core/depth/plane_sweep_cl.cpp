// OpenCL plane sweep: sweep_warp + sweep_cost per plane into a cost volume
// on the device, sweep_select once per scale (src/core/depth/plane_sweep.cl).
// Programs are built once per device; buffers grow as needed and are reused
// from frame to frame; ray tables are uploaded only when they change. Work
// is skipped where the sweep's plane activity (SweepLevel::active) allows:
// a plane active in no tile is not warped; pixels whose samples no active
// window reads are not warped; a column's band with no active tile is not
// summed.
#include <algorithm>
#include <cstring>
#include <map>

#include "fisheye_mapping/core/common/opencl_context.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {
namespace {

class ClSweepBackend : public SweepBackend {
 public:
  explicit ClSweepBackend(const std::string& device) : ctx_(device) {
    kernels(1, -1, 4);  // build once up front: a broken device or kernel fails here
  }

  std::string name() const override { return "opencl: " + ctx_.deviceName(); }

  void sweep(const SweepLevel& level, const std::vector<FmSweepPlane>& planes, const PlaneSweepConfig& config,
             cv::Mat* range, cv::Mat* cost, cv::Mat* ratio) override {
    const int w = level.width, h = level.height, npix = w * h;
    const int views = static_cast<int>(level.cameras.size());
    const int n_planes = static_cast<int>(planes.size());
    int model = level.cameras.empty() ? -1 : level.cameras[0].model;
    for (const auto& c : level.cameras) model = c.model == model ? model : -1;
    Kernels& k = kernels(views, model, level.radius);
    cl::Kernel& warp_ = k.warp;
    cl::Kernel& cost_ = k.cost;
    cl::Kernel& select_ = k.select;
    Slot& s = slots_[level.id];
    cl::CommandQueue& q = ctx_.queue();

    // Inputs.
    const size_t img_bytes = npix * sizeof(float);
    if (s.rays_version != level.rays_version || s.rays_pixels != npix) {
      q.enqueueWriteBuffer(reserve(&s.rays, level.rays->size() * sizeof(float), CL_MEM_READ_ONLY), CL_FALSE, 0,
                           level.rays->size() * sizeof(float), level.rays->data());
      s.rays_version = level.rays_version;
      s.rays_pixels = npix;
    }
    offsets_host_.clear();
    size_t total = 0;
    for (const auto& im : level.images) {
      offsets_host_.push_back(static_cast<int>(total));
      total += im.total();
    }
    images_host_.resize(total);
    for (int v = 0; v < views; ++v) {
      std::memcpy(&images_host_[offsets_host_[v]], level.images[v].ptr<float>(), level.images[v].total() * sizeof(float));
    }
    const size_t plane_bytes = planes.size() * sizeof(FmSweepPlane);
    auto upload = [&](Buf* b, size_t bytes, const void* data) {
      q.enqueueWriteBuffer(reserve(b, bytes, CL_MEM_READ_ONLY), CL_FALSE, 0, bytes, data);
    };
    const cv::Mat ref = continuous(level.ref), mean = continuous(level.ref_mean), stdev = continuous(level.ref_std);
    upload(&s.images, total * sizeof(float), images_host_.data());
    upload(&s.planes, plane_bytes, planes.data());
    upload(&s.cams, views * sizeof(FmCameraT<float>), level.cameras.data());
    upload(&s.poses, views * sizeof(FmViewPose), level.poses.data());
    upload(&s.offsets, views * sizeof(int), offsets_host_.data());
    upload(&s.ref, img_bytes, ref.ptr<float>());
    upload(&s.mean, img_bytes, mean.ptr<float>());
    upload(&s.stdev, img_bytes, stdev.ptr<float>());
    // Plane activity per tile (SweepLevel::active; all ones when empty).
    const int tiles_x = level.active.empty() ? (w + FM_SWEEP_TILE - 1) / FM_SWEEP_TILE : level.tiles_x;
    const int tiles_y = level.active.empty() ? (h + FM_SWEEP_TILE - 1) / FM_SWEEP_TILE : level.tiles_y;
    const size_t tiles = static_cast<size_t>(tiles_x) * tiles_y;
    active_host_ = level.active;
    if (active_host_.empty()) active_host_.assign(tiles * n_planes, 1);
    upload(&s.active, active_host_.size(), active_host_.data());
    // Where each plane's samples are read: its active tiles grown by one tile
    // (a window reaches at most its radius, no more than a tile, beyond its
    // pixel); every tile when the radius is larger.
    needed_host_.assign(active_host_.size(), level.radius > FM_SWEEP_TILE ? 1 : 0);
    if (level.radius <= FM_SWEEP_TILE) {
      for (int p = 0; p < n_planes; ++p) {
        const uint8_t* a = active_host_.data() + p * tiles;
        uint8_t* n = needed_host_.data() + p * tiles;
        for (int ty = 0; ty < tiles_y; ++ty) {
          for (int tx = 0; tx < tiles_x; ++tx) {
            if (!a[ty * tiles_x + tx]) continue;
            for (int y = std::max(0, ty - 1); y <= std::min(tiles_y - 1, ty + 1); ++y) {
              for (int x = std::max(0, tx - 1); x <= std::min(tiles_x - 1, tx + 1); ++x) n[y * tiles_x + x] = 1;
            }
          }
        }
      }
    }
    upload(&s.needed, needed_host_.size(), needed_host_.data());
    reserve(&s.warped, static_cast<size_t>(views) * img_bytes, CL_MEM_READ_WRITE);
    reserve(&s.volume, static_cast<size_t>(n_planes) * img_bytes, CL_MEM_READ_WRITE);
    reserve(&s.range, img_bytes, CL_MEM_WRITE_ONLY);
    reserve(&s.cost, img_bytes, CL_MEM_WRITE_ONLY);
    reserve(&s.ratio, img_bytes, CL_MEM_WRITE_ONLY);

    // Per plane: warp, then cost.
    warp_.setArg(0, s.rays.buffer);
    warp_.setArg(1, npix);
    warp_.setArg(2, s.planes.buffer);
    warp_.setArg(4, s.cams.buffer);
    warp_.setArg(5, s.poses.buffer);
    warp_.setArg(6, views);
    warp_.setArg(7, s.images.buffer);
    warp_.setArg(8, s.offsets.buffer);
    warp_.setArg(9, s.needed.buffer);
    warp_.setArg(10, w);
    warp_.setArg(11, tiles_x);
    warp_.setArg(12, tiles_y);
    warp_.setArg(13, s.warped.buffer);
    const int band = config.band_rows;
    cost_.setArg(0, s.warped.buffer);
    cost_.setArg(1, s.ref.buffer);
    cost_.setArg(2, s.mean.buffer);
    cost_.setArg(3, s.stdev.buffer);
    cost_.setArg(4, w);
    cost_.setArg(5, h);
    cost_.setArg(6, band);
    cost_.setArg(7, config.aggregation == SweepAggregation::BestK ? FM_AGGREGATE_BEST_K : FM_AGGREGATE_AVERAGE);
    cost_.setArg(8, config.best_k);
    cost_.setArg(10, s.active.buffer);
    cost_.setArg(11, tiles_x);
    cost_.setArg(12, tiles_y);
    cost_.setArg(13, s.volume.buffer);
    const cl::NDRange warp_global(npix);
    const cl::NDRange cost_global(w, (h + band - 1) / band);
    for (int p = 0; p < n_planes; ++p) {
      // A plane swept in no tile needs no samples: sweep_cost only writes
      // FM_COST_INVALID for it.
      const uint8_t* a = active_host_.data() + p * tiles;
      if (std::any_of(a, a + tiles, [](uint8_t x) { return x != 0; })) {
        warp_.setArg(3, p);
        q.enqueueNDRangeKernel(warp_, cl::NullRange, warp_global, cl::NullRange);
      }
      cost_.setArg(9, p);
      q.enqueueNDRangeKernel(cost_, cl::NullRange, cost_global, cl::NullRange);
    }

    // Winner takes all.
    select_.setArg(0, s.volume.buffer);
    select_.setArg(1, npix);
    select_.setArg(2, s.planes.buffer);
    select_.setArg(3, n_planes);
    select_.setArg(4, s.rays.buffer);
    select_.setArg(5, config.subpixel ? 1 : 0);
    select_.setArg(6, s.range.buffer);
    select_.setArg(7, s.cost.buffer);
    select_.setArg(8, s.ratio.buffer);
    q.enqueueNDRangeKernel(select_, cl::NullRange, cl::NDRange(npix), cl::NullRange);
    *range = cv::Mat(h, w, CV_32FC1);
    *cost = cv::Mat(h, w, CV_32FC1);
    *ratio = cv::Mat(h, w, CV_32FC1);
    q.enqueueReadBuffer(s.range.buffer, CL_FALSE, 0, img_bytes, range->ptr<float>());
    q.enqueueReadBuffer(s.cost.buffer, CL_FALSE, 0, img_bytes, cost->ptr<float>());
    q.enqueueReadBuffer(s.ratio.buffer, CL_TRUE, 0, img_bytes, ratio->ptr<float>());
  }

 private:
  struct Buf {
    cl::Buffer buffer;
    size_t capacity = 0;
  };
  struct Slot {
    Buf rays, images, planes, cams, poses, offsets, ref, mean, stdev, warped, volume, range, cost, ratio, active, needed;
    unsigned rays_version = 0;
    int rays_pixels = -1;
  };

  static cv::Mat continuous(const cv::Mat& m) { return m.isContinuous() ? m : m.clone(); }

  // Grows `b` to hold `bytes` and returns its buffer.
  cl::Buffer& reserve(Buf* b, size_t bytes, cl_mem_flags flags) {
    if (bytes > b->capacity || b->capacity == 0) {
      b->capacity = std::max<size_t>(bytes + bytes / 4, 64);
      b->buffer = cl::Buffer(ctx_.context(), flags, b->capacity);
    }
    return b->buffer;
  }

  struct Kernels {
    cl::Kernel warp, cost, select;
  };
  // Kernels specialised for the number of views and (when all views share
  // it; -1 otherwise) the camera model; built on first use, then cached.
  Kernels& kernels(int views, int model, int radius) {
    const int key = (radius * 16 + views) * 16 + (model + 1);
    auto it = kernels_.find(key);
    if (it != kernels_.end()) return it->second;
    std::string options = "-DFM_CAM_SPACE=__global -DFM_SWEEP_VIEWS=" + std::to_string(views) +
                          " -DFM_SWEEP_RADIUS=" + std::to_string(radius);
    if (model >= 0) options += " -DFM_FIXED_MODEL=" + std::to_string(model);
    cl::Program& program = ctx_.program(
        {clSource("camera_model_shared.h"), clSource("plane_sweep_shared.h"), clSource("plane_sweep.cl")}, options);
    Kernels k{cl::Kernel(program, "sweep_warp"), cl::Kernel(program, "sweep_cost"), cl::Kernel(program, "sweep_select")};
    return kernels_.emplace(key, k).first->second;
  }

  OpenClContext ctx_;
  std::map<int, Kernels> kernels_;
  Slot slots_[4];
  std::vector<int> offsets_host_;
  std::vector<float> images_host_;
  std::vector<uint8_t> active_host_, needed_host_;
};

}  // namespace

std::unique_ptr<SweepBackend> makeOpenClSweepBackend(const std::string& device) {
  return std::make_unique<ClSweepBackend>(device);
}

}  // namespace fisheye_mapping
