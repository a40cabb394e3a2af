// depth_benchmark: milliseconds per frame of the plane-sweep depth stage for
// full / half / multi-scale, without and with filters, on one rendered frame
// set of the rig (5 cameras at 1024x544 for the default rig), for each
// backend asked for, and the share of the machine's FP32 FMA peak that the
// sweep reaches, with the peak measured in the same run: an FMA-only OpenCL
// kernel on the OpenCL device, and native AVX2 FMA chains on every OpenMP
// thread of the CPU; the larger of the two CPU figures is the CPU's peak.
// Also prints the process's peak resident memory, the share of the (plane,
// pixel) pairs each configuration sweeps (the stage skips the work the
// filters would drop and searches the crop coarse-to-fine), and the
// multi-scale filtered time with every plane swept at every pixel, for the
// speed-up that doing less work gives in the same run.
//
//   depth_benchmark --camchain F --mount F [--repeats N] [--device D]
//                   [--backends native,opencl] [--band-rows N] [--threads N]
//                   [--scales full,half,multiscale]
//
// Achieved FLOP/s are estimated from operation counts: about kFlopsPerSample
// floating-point operations per pixel, plane and supporting view (plane
// intersection, transform, unified projection with radial-tangential
// distortion, bilinear sample, running window sums, ZNCC), counting a
// division or square root as one.
#include <sys/resource.h>

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <sstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/core/common/opencl_context.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"

namespace fm = fisheye_mapping;

namespace {

constexpr double kFlopsPerSample = 200.0;

// FP32 FMA peak of the device: every work item runs independent float8 FMA
// chains, enough to hide latency; 2 FLOP per FMA lane.
double measurePeakGflops(fm::OpenClContext& ctx) {
  const char* src = R"(
__kernel void fma_peak(__global float* out, int iters) {
  float8 a = (float8)(get_global_id(0) * 1e-7f), b = a + 0.1f, c = a + 0.2f, d = a + 0.3f,
         e = a + 0.4f, f = a + 0.5f, g = a + 0.6f, h = a + 0.7f;
  const float8 m = (float8)(0.9999f), k = (float8)(1e-4f);
  for (int i = 0; i < iters; ++i) {
    a = fma(a, m, k); b = fma(b, m, k); c = fma(c, m, k); d = fma(d, m, k);
    e = fma(e, m, k); f = fma(f, m, k); g = fma(g, m, k); h = fma(h, m, k);
  }
  float8 s = a + b + c + d + e + f + g + h;
  out[get_global_id(0)] = s.s0 + s.s1 + s.s2 + s.s3 + s.s4 + s.s5 + s.s6 + s.s7;
})";
  cl::Program& program = ctx.program({src});
  cl::Kernel kernel(program, "fma_peak");
  const size_t items = 1 << 16;
  const int iters = 2000;
  cl::Buffer out(ctx.context(), CL_MEM_WRITE_ONLY, items * sizeof(float));
  kernel.setArg(0, out);
  kernel.setArg(1, iters);
  double best = 0;
  for (int r = 0; r < 4; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    ctx.queue().enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(items), cl::NullRange);
    ctx.queue().finish();
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (r > 0) best = std::max(best, 2.0 * 8 * 8 * iters * static_cast<double>(items) / s / 1e9);
  }
  return best;
}

// FP32 FMA peak of the CPU: independent 8-wide FMA chains on every OpenMP
// thread (AVX2 + FMA when the CPU has them; 0 otherwise).
#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target("avx2,fma"))) double fmaChainsGflops(long iters) {
  typedef float v8 __attribute__((vector_size(32)));
  double flops = 0;
  const auto t0 = std::chrono::steady_clock::now();
#pragma omp parallel reduction(+ : flops)
  {
    v8 a = {1, 2, 3, 4, 5, 6, 7, 8}, b = a + 1, c = a + 2, d = a + 3, e = a + 4, f = a + 5, g = a + 6, h = a + 7,
       i = a + 8, j = a + 9;
    const v8 m = {0.9999f, 0.9999f, 0.9999f, 0.9999f, 0.9999f, 0.9999f, 0.9999f, 0.9999f};
    const v8 k = {1e-4f, 1e-4f, 1e-4f, 1e-4f, 1e-4f, 1e-4f, 1e-4f, 1e-4f};
    for (long n = 0; n < iters; ++n) {
      a = a * m + k; b = b * m + k; c = c * m + k; d = d * m + k; e = e * m + k;
      f = f * m + k; g = g * m + k; h = h * m + k; i = i * m + k; j = j * m + k;
      // Keeps every chain alive and in registers: nothing can be folded.
      asm volatile("" : "+x"(a), "+x"(b), "+x"(c), "+x"(d), "+x"(e), "+x"(f), "+x"(g), "+x"(h), "+x"(i), "+x"(j));
    }
    const v8 s = a + b + c + d + e + f + g + h + i + j;
    volatile float sink = 0;
    for (int l = 0; l < 8; ++l) sink = sink + s[l];
    flops += 2.0 * 8 * 10 * iters;
  }
  const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return flops / sec / 1e9;
}
double measureCpuPeakGflops() {
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma")) return 0.0;
  double best = 0;
  for (int r = 0; r < 4; ++r) best = std::max(best, fmaChainsGflops(20000000));
  return best;
}
#else
double measureCpuPeakGflops() { return 0.0; }
#endif

double peakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

}  // namespace

int main(int argc, char** argv) {
  namespace cli = fm::cli;
  std::map<std::string, std::string> a;
  const char* usage =
      "usage: depth_benchmark --camchain F --mount F [--repeats N] [--device D]\n"
      "                       [--backends native,opencl] [--band-rows N] [--threads N]\n"
      "                       [--scales full,half,multiscale]\n"
      "  --camchain F, --mount F  the rig (Kalibr camchain and mount)\n"
      "  --repeats N              timed runs per configuration, 1 to 1000 (default 3)\n"
      "  --device D               OpenCL device: part of its \"platform / device\" name\n"
      "                           (default: the first GPU)\n"
      "  --backends LIST          sweep backends to time, comma-separated, 1 to 8 names\n"
      "                           (default native,opencl)\n"
      "  --band-rows N            rows per band of the native backend, 1 to 20000\n"
      "                           (default: the stage's own)\n"
      "  --threads N              OpenMP threads, 1 to 1024 (default: OMP_NUM_THREADS or every core)\n"
      "  --scales LIST            scales to time, comma-separated (default full,half,multiscale; the\n"
      "                           every-plane comparison runs with multiscale)\n";
  int repeats = 3, band_rows = 0, threads = 0;
  const int rc = cli::parseCommandLine("depth_benchmark", usage, [&] {
    cli::forEachOption(argc, argv, 1, [&](const std::string& opt, const cli::NextValue& next) {
      static const char* kKnown[] = {"--camchain", "--mount", "--repeats", "--device", "--backends", "--band-rows",
                                     "--threads", "--scales"};
      if (std::find(std::begin(kKnown), std::end(kKnown), opt) == std::end(kKnown)) return false;
      a[opt.substr(2)] = next();
      return true;
    });
    if (!a.count("camchain") || !a.count("mount")) throw cli::UsageError("--camchain and --mount are required");
    cli::requireInputFile("--camchain", a["camchain"]);
    cli::requireInputFile("--mount", a["mount"]);
    if (a.count("repeats")) repeats = static_cast<int>(cli::parseInt("--repeats", a["repeats"], 1, 1000));
    if (a.count("scales")) {
      std::stringstream ss(a["scales"]);
      for (std::string sc; std::getline(ss, sc, ',');) {
        if (sc != "full" && sc != "half" && sc != "multiscale")
          throw cli::UsageError("--scales: unknown scale '" + sc + "' (full, half, multiscale)");
      }
    }
    if (a.count("threads")) threads = static_cast<int>(cli::parseInt("--threads", a["threads"], 1, 1024));
    if (a.count("band-rows")) band_rows = static_cast<int>(cli::parseInt("--band-rows", a["band-rows"], 1, 20000));
    if (a.count("backends")) {
      std::stringstream ss(a["backends"]);
      int n = 0;
      for (std::string b; std::getline(ss, b, ',');) {
        if (b.empty()) throw cli::UsageError("--backends: empty name in '" + a["backends"] + "'");
        ++n;
      }
      if (n == 0 || n > 8) throw cli::UsageError("--backends needs 1 to 8 names, got '" + a["backends"] + "'");
    }
  });
  if (rc >= 0) return rc;
  try {
    if (threads > 0) omp_set_num_threads(threads);
    const fm::Rig rig = fm::loadKalibrRig(a["camchain"], a["mount"]);
    fm::synth::WorldConfig wc;
    wc.route_length = 120;
    const fm::synth::World world(wc);
    const double t = 2.0;
    std::vector<cv::Mat> images;
    for (size_t c = 0; c < rig.cameras.size(); ++c) {
      const auto& cam = rig.cameras[c];
      images.push_back(world.render(cam.model, fm::pixelRays(cam.model), world.egoPose(t) * cam.T_base_cam, t, c).image);
    }
    std::vector<fm::SweepView> supports;
    for (size_t i = 1; i < rig.cameras.size(); ++i) supports.push_back(fm::rigSweepView(rig, i, 0, images[i]));
    const fm::SweepView ref = fm::rigSweepView(rig, 0, 0, images[0]);
    const Eigen::Isometry3d T_base_ref = rig.cameras[0].T_base_cam;

    std::vector<std::string> backends;
    {
      std::stringstream ss(a.count("backends") ? a["backends"] : "native,opencl");
      for (std::string b; std::getline(ss, b, ',');) backends.push_back(b);
    }
    const double cpu_peak = measureCpuPeakGflops();
    std::cout << "CPU FP32 FMA peak measured (AVX2 FMA chains, every OpenMP thread): " << std::fixed
              << std::setprecision(1) << cpu_peak << " GFLOP/s\n";
    double cl_peak = 0.0;
    std::string cl_name;
    try {
      fm::OpenClContext ctx(a.count("device") ? a["device"] : "");
      cl_peak = measurePeakGflops(ctx);
      cl_name = ctx.deviceName();
      std::cout << "OpenCL device: " << cl_name << ", FP32 FMA peak measured: " << cl_peak << " GFLOP/s\n";
    } catch (const std::exception& e) {
      std::cout << "OpenCL: no device (" << e.what() << ")\n";
    }
    const bool cl_is_gpu = fm::OpenClContext::hasGpu() && !cl_name.empty();
    std::cout << "rig: " << rig.cameras.size() << " cameras, " << rig.cameras[0].model.width() << "x"
              << rig.cameras[0].model.height() << ", reference " << rig.cameras[0].name << "; " << repeats
              << " timed runs after one warm-up, median; " << omp_get_max_threads() << " OpenMP threads\n\n"
              << "| backend | scales | filters | ms per frame | supporting views | pairs swept | share of FMA peak |\n"
              << "|---|---|---|---:|---:|---:|---:|\n";
    std::map<std::string, double> ms_of;
    std::string product;
    for (const std::string& backend : backends) {
      // The CPU's peak is the larger of the two measurements of it; a GPU's
      // is its own.
      const double peak = (backend == "opencl" && cl_is_gpu) ? cl_peak : std::max(cpu_peak, cl_peak);
      // The three scales without and with filters, then multi-scale filtered
      // with every plane swept at every pixel (skip_work off), and with the
      // infinity filter (off by default: what it costs).
      std::vector<std::tuple<std::string, bool, bool, bool>> runs;
      std::vector<std::string> scales;
      {
        std::stringstream ss(a.count("scales") ? a["scales"] : "full,half,multiscale");
        for (std::string sc; std::getline(ss, sc, ',');) scales.push_back(sc);
      }
      for (const std::string& res : scales) {
        for (const bool filters : {false, true}) runs.emplace_back(res, filters, true, false);
      }
      if (std::count(scales.begin(), scales.end(), "multiscale")) {
        runs.emplace_back("multiscale", true, false, false);
        runs.emplace_back("multiscale", true, true, true);
      }
      for (const auto& [res, filters, skip, infinity] : runs) {
        fm::PlaneSweepConfig c;
        c.backend = fm::parseSweepBackend(backend);
        c.resolution = fm::parseSweepResolution(res);
        c.device = a.count("device") ? a["device"] : "";
        c.skip_work = skip;
        if (band_rows > 0) c.band_rows = band_rows;
        if (!filters) c.filters.cost = c.filters.uniqueness = c.filters.consistency = false;
        c.filters.infinity = infinity;
        fm::PlaneSweep sweep(c);
        fm::DepthResult r = sweep.compute(ref, supports, &T_base_ref);  // warm-up: kernel builds, buffers
        std::vector<double> ms;
        for (int k = 0; k < repeats; ++k) ms.push_back(sweep.compute(ref, supports, &T_base_ref).total_ms);
        std::sort(ms.begin(), ms.end());
        const double med = ms[ms.size() / 2];
        const double W = rig.cameras[0].model.width(), H = rig.cameras[0].model.height();
        const double planes = fm::makeSweepPlanes(c, &T_base_ref).size();
        double pixels = W * H;
        if (res == "half") pixels = (W / 2) * (H / 2);
        if (res == "multiscale")
          pixels = (W / 2) * (H / 2) + std::round(c.crop_width * W) * std::round(c.crop_height * H);
        // The work done: the pairs swept, not those skipped.
        const double gflop = kFlopsPerSample * pixels * planes * r.swept_share * r.used_views.size() / 1e9;
 ms_of[backend + ":" + res + (filters ? "+f" : "") + (skip ? "" : ":every") + (infinity ? ":inf" : "")] =
            med;
        std::cout << "| " << sweep.backendName() << " | " << res << (skip ? "" : ", every plane everywhere") << " | "
                  << (filters ? (infinity ? "on + infinity filter" : "on") : "off") << " | " << std::setprecision(0) << med << " | "
                  << r.used_views.size() << " | " << std::setprecision(1) << 100.0 * r.swept_share << " % | "
                  << (peak > 0 ? 100.0 * gflop / (med / 1e3) / peak : 0.0) << " % |\n";
      }
      if (product.empty()) product = backend;
    }
    std::cout << "\npeak resident memory: " << std::setprecision(0) << peakRssMb() << " MB\n";
    for (const std::string& backend : backends) {
      const std::string b = backend + ":";
      if (ms_of.count(b + "multiscale") && ms_of.count(b + "full")) {
        std::cout << backend << ": multi-scale / full time (no filters): " << std::setprecision(2)
                  << ms_of[b + "multiscale"] / ms_of[b + "full"] << " (paper: 36 / 50 = 0.72)\n";
      }
      if (ms_of.count(b + "multiscale+f:every")) {
        std::cout << backend << ": less work: every plane everywhere / as the stage runs (multi-scale filtered): "
                  << std::setprecision(2) << ms_of[b + "multiscale+f:every"] / ms_of[b + "multiscale+f"] << "\n";
      }
      if (ms_of.count(b + "multiscale+f:inf")) {
        std::cout << backend << ": the infinity filter's cost: with / without (multi-scale filtered): "
                  << std::setprecision(2) << ms_of[b + "multiscale+f:inf"] / ms_of[b + "multiscale+f"] << "\n";
      }
    }
    // The last line: the first backend listed (the product's on this machine).
    if (ms_of.count(product + ":multiscale+f")) {
      std::cout << "multi-scale filtered: " << std::setprecision(0) << ms_of[product + ":multiscale+f"]
                << " ms per frame (" << product << ", " << omp_get_max_threads()
                << " threads; target <= 200, goal 120)\n";
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "depth_benchmark: " << e.what() << "\n";
    return 1;
  }
}
