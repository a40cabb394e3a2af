// The plane sweep's configuration (PlaneSweepConfig, DepthFilterConfig): its
// enumerations, its parameter declarations (params()) and validation.
#include <stdexcept>
#include <string>
#include <utility>

#include "fisheye_mapping/core/common/param_table.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {
namespace {

void require(bool ok, const std::string& field, const std::string& what) {
  if (!ok) throw std::invalid_argument(field + ": " + what);
}

}  // namespace

SweepAggregation parseSweepAggregation(const std::string& s) {
  if (s == "average") return SweepAggregation::Average;
  if (s == "best_k") return SweepAggregation::BestK;
  throw std::invalid_argument("aggregation: must be 'average' or 'best_k', got '" + s + "'");
}

SweepResolution parseSweepResolution(const std::string& s) {
  if (s == "full") return SweepResolution::Full;
  if (s == "half") return SweepResolution::Half;
  if (s == "multiscale") return SweepResolution::Multiscale;
  throw std::invalid_argument("resolution: must be 'full', 'half' or 'multiscale', got '" + s + "'");
}

SweepBackendType parseSweepBackend(const std::string& s) {
  if (s == "auto") return SweepBackendType::Auto;
  if (s == "native") return SweepBackendType::Native;
  if (s == "opencl") return SweepBackendType::OpenCl;
  if (s == "cpu") return SweepBackendType::Cpu;
  throw std::invalid_argument("backend: must be 'auto', 'native', 'opencl' or 'cpu', got '" + s + "'");
}

std::string toString(SweepAggregation a) {
  switch (a) {
    case SweepAggregation::Average: return "average";
    case SweepAggregation::BestK: return "best_k";
  }
  return "?";
}

std::string toString(SweepResolution r) {
  switch (r) {
    case SweepResolution::Full: return "full";
    case SweepResolution::Half: return "half";
    case SweepResolution::Multiscale: return "multiscale";
  }
  return "?";
}

std::string toString(SweepBackendType b) {
  switch (b) {
    case SweepBackendType::Auto: return "auto";
    case SweepBackendType::Native: return "native";
    case SweepBackendType::OpenCl: return "opencl";
    case SweepBackendType::Cpu: return "cpu";
  }
  return "?";
}

const ParamTable<DepthFilterConfig>& DepthFilterConfig::params() {
  using C = DepthFilterConfig;
  using R = ParamRange;
  constexpr auto kRun = ParamChange::Runtime;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("depth filters");
    t.flag("filter_texture", [](C& c) -> bool& { return c.texture; },
           "Drop pixels whose reference window has too little texture for the image's noise (sky, blank walls)", kRun)
        .number("min_texture_snr", [](C& c) -> double& { return c.min_texture_snr; }, R::atLeast(0), "",
                "Smallest window std / sensor noise std kept, for a 3x3 window; larger windows need the same "
                "significance, so less (1.5: 1.23 at 7x7); also defines textureless regions",
                kRun)
        .number("min_noise_std", [](C& c) -> double& { return c.min_noise_std; }, R::above(0), "",
                "Floor of the estimated sensor noise std, image values in [0, 1] (1/255: one 8-bit step)")
        .flag("filter_cost", [](C& c) -> bool& { return c.cost; }, "Drop pixels whose best matching cost exceeds alpha",
              kRun)
        .number("alpha_upper", [](C& c) -> double& { return c.alpha_upper; }, R::between(0, 1), "",
                "Cost threshold above the horizon (the rows above split_row without a mount)", kRun)
        .number("alpha_lower", [](C& c) -> double& { return c.alpha_lower; }, R::between(0, 1), "",
                "Cost threshold below the horizon (the rows below split_row without a mount)", kRun)
        .flag("alpha_by_horizon", [](C& c) -> bool& { return c.alpha_by_horizon; },
              "With the camera's mount: alpha_lower where the ray points below the base frame's horizontal "
              "plane (the ground, whatever the camera's pitch); false: split_row",
              kRun)
        .number("split_row", [](C& c) -> double& { return c.split_row; }, R::between(0, 1), "",
                "Boundary between the upper and lower part without a mount (or alpha_by_horizon false), fraction "
                "of the image height",
                kRun)
        .flag("filter_uniqueness", [](C& c) -> bool& { return c.uniqueness; },
              "Drop pixels whose best / second-best cost ratio exceeds max_ratio", kRun)
        .number("max_ratio", [](C& c) -> double& { return c.max_ratio; }, R::aboveUpTo(0, 1), "",
                "Largest best / second-best cost ratio kept", kRun)
        .flag("filter_consistency", [](C& c) -> bool& { return c.consistency; },
              "Local depth consistency check", kRun)
        .number("consistency_window", [](C& c) -> int& { return c.consistency_window; }, R::atLeast(3), "px",
                "Window of the consistency check (odd)", kRun)
        .number("gamma", [](C& c) -> double& { return c.gamma; }, R::above(0), "m",
                "Depth difference under which a neighbour is consistent", kRun)
        .number("road_gamma_relative", [](C& c) -> double& { return c.road_gamma_relative; }, R::between(0, 1), "",
                "On the road (points within the ground planes' heights, with the mount) the consistency tolerance "
                "grows with the range: max(gamma, road_gamma_relative * range); 0: gamma alone",
                kRun)
        .number("delta", [](C& c) -> double& { return c.delta; }, R::between(0, 1), "",
                "Smallest share of consistent neighbours kept", kRun)
        .flag("filter_infinity", [](C& c) -> bool& { return c.infinity; },
              "Drop pixels whose best cost is not below the cost at infinity by infinity_margin (sky, no parallax), and the sky's fattened edges",
              kRun)
        .number("infinity_margin", [](C& c) -> double& { return c.infinity_margin; }, R::between(0, 1), "",
                "Smallest amount by which the best cost must beat the cost at infinity", kRun);
    t.rule([](const C& c) {
      require(c.consistency_window % 2 == 1, "consistency_window",
              "must be odd, got " + std::to_string(c.consistency_window));
    });
    return t;
  }();
  return t;
}

void DepthFilterConfig::validate() const { params().check(*this); }

const ParamTable<PlaneSweepConfig>& PlaneSweepConfig::params() {
  using C = PlaneSweepConfig;
  using R = ParamRange;
  constexpr auto kRun = ParamChange::Runtime;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("depth");
    t.number("fronto_planes", [](C& c) -> int& { return c.fronto_planes; }, R::atLeast(2), "",
             "Planes parallel to the reference image plane, uniform in inverse depth over [near, far]")
        .number("near", [](C& c) -> double& { return c.near; }, R::above(0), "m",
                "Nearest range kept (along the ray); nearest fronto-parallel plane (z)", kRun)
        .number("far", [](C& c) -> double& { return c.far; }, R::above(0), "m",
                "Farthest range kept; farthest fronto-parallel plane (> near)", kRun)
        .number("ground_planes", [](C& c) -> int& { return c.ground_planes; }, R::atLeast(0), "",
                "Planes parallel to the ground (0: none, else at least 2)")
        .number("ground_height", [](C& c) -> double& { return c.ground_height; }, R::any(), "m",
                "z of the road in the base frame (0: base frame on the ground; -0.3: base 0.3 m above the road)", kRun)
        .number("ground_min", [](C& c) -> double& { return c.ground_min; }, R::any(), "m",
                "Lowest ground plane above the road", kRun)
        .number("ground_max", [](C& c) -> double& { return c.ground_max; }, R::any(), "m",
                "Highest ground plane above the road (> ground_min)", kRun)
        .number("wall_planes", [](C& c) -> int& { return c.wall_planes; }, R::atLeast(0), "",
                "Vertical planes parallel to the driving direction on each side, for facades (0: none, else at "
                "least 2)")
        .number("wall_min", [](C& c) -> double& { return c.wall_min; }, R::above(0), "m",
                "Nearest wall plane: lateral offset from the base frame's x-z plane", kRun)
        .number("wall_max", [](C& c) -> double& { return c.wall_max; }, R::above(0), "m",
                "Farthest wall plane's lateral offset (> wall_min); uniform in inverse offset between", kRun)
        .number("window_full", [](C& c) -> int& { return c.window_full; }, R::atLeast(3), "px",
                "Matching window at full resolution (odd)")
        .number("window_half", [](C& c) -> int& { return c.window_half; }, R::atLeast(3), "px",
                "Matching window at half resolution (odd)")
        .choice("aggregation", {"average", "best_k"}, [](const C& c) { return toString(c.aggregation); },
                [](C& c, const std::string& v) { c.aggregation = parseSweepAggregation(v); },
                "Cost over the supporting views: their mean, or the mean of the best best_k")
        .number("best_k", [](C& c) -> int& { return c.best_k; }, R::atLeast(1), "",
                "Views averaged by aggregation best_k")
        .flag("subpixel", [](C& c) -> bool& { return c.subpixel; }, "Parabolic sub-plane refinement")
        .choice("resolution", {"full", "half", "multiscale"}, [](const C& c) { return toString(c.resolution); },
                [](C& c, const std::string& v) { c.resolution = parseSweepResolution(v); },
                "Scales swept: full, half, or multiscale (half over the view + full in the centre crop)")
        .number("crop_width", [](C& c) -> double& { return c.crop_width; }, R::aboveUpTo(0, 1), "",
                "Width of the full-resolution centre crop, fraction of the image")
        .number("crop_height", [](C& c) -> double& { return c.crop_height; }, R::aboveUpTo(0, 1), "",
                "Height of the full-resolution centre crop, fraction of the image")
        .number("crop_search_planes", [](C& c) -> int& { return c.crop_search_planes; }, R::atLeast(0), "",
                "Multiscale: the crop sweeps, per 8x8 tile, only the planes within this many of the half-resolution "
                "winners there (0: every plane)")
        .number("half_search_planes", [](C& c) -> int& { return c.half_search_planes; }, R::atLeast(0), "",
                "Half resolution: after a quarter-resolution sweep of every other plane, sweep per 8x8 tile only the "
                "planes within this many of its winners there (0: no quarter-resolution sweep, every plane)")
        .number("window_quarter", [](C& c) -> int& { return c.window_quarter; }, R::atLeast(3), "px",
                "Matching window of the quarter-resolution sweep (odd)")
        .number("min_parallax_px", [](C& c) -> double& { return c.min_parallax_px; }, R::atLeast(0), "px",
                "Smallest parallax per plane (pixels of the coarser image) of a supporting view", kRun)
        .number("min_parallax_ratio", [](C& c) -> double& { return c.min_parallax_ratio; }, R::between(0, 1), "",
                "Smallest share of the best view's parallax a supporting view must have", kRun)
        .number("min_overlap", [](C& c) -> double& { return c.min_overlap; }, R::between(0, 1), "",
                "Smallest share of the reference's pixels a supporting view must see", kRun)
        .choice("backend", {"auto", "native", "opencl", "cpu"}, [](const C& c) { return toString(c.backend); },
                [](C& c, const std::string& v) { c.backend = parseSweepBackend(v); },
                "auto (opencl on a GPU, else native) | native (CPU SIMD) | opencl | cpu (slow reference)")
        .text("device", [](C& c) -> std::string& { return c.device; },
              "OpenCL device: empty = first GPU, else first device (a name here makes auto take opencl)")
        .include(DepthFilterConfig::params(), [](C& c) -> DepthFilterConfig& { return c.filters; });
    t.rule([](const C& c) {
      require(c.ground_planes == 0 || c.ground_planes >= 2, "ground_planes",
              "must be 0 or at least 2, got " + std::to_string(c.ground_planes));
      require(c.wall_planes == 0 || c.wall_planes >= 2, "wall_planes",
              "must be 0 or at least 2, got " + std::to_string(c.wall_planes));
      if (!(c.wall_max > c.wall_min))
        requireInRange("wall_max", ParamRange::above(c.wall_min), c.wall_max, "m (greater than wall_min)");
      if (!(c.far > c.near)) requireInRange("far", ParamRange::above(c.near), c.far, "m (greater than near)");
      if (!(c.ground_max > c.ground_min))
        requireInRange("ground_max", ParamRange::above(c.ground_min), c.ground_max, "m (greater than ground_min)");
      require(c.window_full % 2 == 1, "window_full", "must be odd, got " + std::to_string(c.window_full));
      require(c.window_half % 2 == 1, "window_half", "must be odd, got " + std::to_string(c.window_half));
      require(c.window_quarter % 2 == 1, "window_quarter", "must be odd, got " + std::to_string(c.window_quarter));
      require(c.band_rows >= 1, "band_rows", "must be at least 1");
    });
    return t;
  }();
  return t;
}

void PlaneSweepConfig::validate() const { params().check(*this); }

DepthFilterConfig DepthFilterConfig::fromParams(const ParamSource& p, DepthFilterConfig base) {
  return params().read(p, std::move(base));
}

PlaneSweepConfig PlaneSweepConfig::fromParams(const ParamSource& p) { return fromParams(p, PlaneSweepConfig()); }

PlaneSweepConfig PlaneSweepConfig::fromParams(const ParamSource& p, PlaneSweepConfig base) {
  return params().read(p, std::move(base));
}

}  // namespace fisheye_mapping
