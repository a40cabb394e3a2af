#include "fisheye_mapping/core/detection/depth_mask.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

#include "fisheye_mapping/core/common/param_table.h"

namespace fisheye_mapping {

const ParamTable<DepthMaskConfig>& DepthMaskConfig::params() {
  using C = DepthMaskConfig;
  using R = ParamRange;
  constexpr auto kRun = ParamChange::Runtime;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("depth_mask");
    t.number("margin_px", [](C& c) -> double& { return c.margin_px; }, R::atLeast(0), "px",
             "Pixels added on each side of every box before masking", kRun)
        .number("wait_for_detections", [](C& c) -> double& { return c.wait_for_detections; }, R::atLeast(0), "s",
                "Wall time a depth map waits for its detections before it passes unmasked", kRun)
        .number("max_pending", [](C& c) -> int& { return c.max_pending; }, R::atLeast(1), "",
                "Depth maps / detection sets held while pairing", kRun)
        .number("time_reset_threshold", [](C& c) -> double& { return c.time_reset_threshold; }, R::atLeast(0), "s",
                "Time a stream may step back before the pairing resets; 0: never", kRun)
        .numbers("colour_range", 2, R::above(0), "m",
                 [](const C& c) { return std::vector<double>{c.colour_near, c.colour_far}; },
                 [](C& c, const std::vector<double>& v) {
                   c.colour_near = v[0];
                   c.colour_far = v[1];
                 },
                 "[near, far] of the colour scale of depth_masked/colour")
        .flag("mask_parked", [](C& c) -> bool& { return c.mask_parked; },
              "Mask parked vehicles too (false: only moving vehicles and those not decided yet)")
        .number("hold_time", [](C& c) -> double& { return c.hold_time; }, R::atLeast(0), "s",
                "Time an undecided vehicle's masked depth is held, to be fused (depth_masked/held) once the vehicle is "
                "decided parked; 0: dropped")
        .number("moving_speed", [](C& c) -> double& { return c.motion.moving_speed; }, R::above(0), "m/s",
                "A tracked vehicle this fast or faster moves; slower, it is parked")
        .number("speed_significance", [](C& c) -> double& { return c.motion.speed_significance; }, R::atLeast(0),
                "", "Standard errors a vehicle's measured speed must lie above (moving) or below (parked) moving_speed "
                "to be decided; 0: the speed alone decides")
        .number("position_noise", [](C& c) -> double& { return c.motion.position_noise; }, R::atLeast(0), "m",
                "Scatter assumed of a vehicle's placed positions at 10 m or nearer, growing with the square of the range "
                "(for the speed's standard error)")
        .number("parked_tolerance", [](C& c) -> double& { return c.motion.parked_tolerance; }, R::atLeast(0), "m",
                "A parked vehicle's box placed farther than this (plus twice its expected scatter) from where it "
                "stands is masked, not fused as parked (a vehicle driving past taken for it, or driving off)")
        .number("decide_after", [](C& c) -> double& { return c.motion.decide_after; }, R::atLeast(0), "s",
                "Time a vehicle is tracked before it is called moving or parked (masked until then)")
        .number("speed_window", [](C& c) -> double& { return c.motion.speed_window; }, R::above(0), "s",
                "Track history a vehicle's speed is measured over")
        .number("track_gate", [](C& c) -> double& { return c.motion.gate; }, R::above(0), "m",
                "Largest distance of a box's vehicle from its track's predicted position")
        .number("track_max_gap", [](C& c) -> double& { return c.motion.max_gap; }, R::above(0), "s",
                "Time a track survives without a box")
        .number("min_vehicle_points", [](C& c) -> int& { return c.motion.min_points; }, R::atLeast(1), "",
                "Depth pixels a box needs to place its vehicle (fewer: undecided, masked)")
        .number("vehicle_max_range", [](C& c) -> double& { return c.motion.max_range; }, R::above(0), "m",
                "Depth beyond this does not place a vehicle")
        .number("decide_range", [](C& c) -> double& { return c.motion.decide_range; }, R::above(0), "m",
                "A vehicle farther from the camera is tracked, not measured (undecided until nearer)")
        .number("border_px", [](C& c) -> double& { return c.motion.border_px; }, R::any(), "px",
                "A box this near the image border is cut by it: it keeps its track's decision (negative: never)")
        .number("duplicate_distance", [](C& c) -> double& { return c.motion.duplicate_distance; }, R::atLeast(0),
                "m", "Boxes whose vehicles lie this close are one vehicle (one decision)")
        .number("static_interval", [](C& c) -> double& { return c.motion.static_interval; }, R::atLeast(0), "s",
                "The static check: a vehicle's body is compared with the depth map of this long before (agreeing: "
                "it stands still); 0: off")
        .number("static_share", [](C& c) -> double& { return c.motion.static_share; }, R::between(0, 1), "",
                "Share of the body's points that must agree with that depth map for a frame set to look static")
        .number("static_frames", [](C& c) -> int& { return c.motion.static_frames; }, R::atLeast(1), "",
                "Frame sets in a row a vehicle must look static (moving, if at all, along the ego's heading) to be "
                "called parked whatever its measured speed")
        .number("moving_share", [](C& c) -> double& { return c.motion.moving_share; }, R::between(0, 1), "",
                "With the static check on, a vehicle is called moving only when at most this share of its body "
                "agrees with that depth map (beyond static_range, or in between, it stays undecided, masked); "
                "below static_share")
        .number("moving_frames", [](C& c) -> int& { return c.motion.moving_frames; }, R::atLeast(1), "",
                "Measured frame sets in a row whose body must read moved (moving_share) before a vehicle is called "
                "moving (once moving, it stays so)")
        .number("static_range", [](C& c) -> double& { return c.motion.static_range; }, R::above(0), "m",
                "Vehicles farther from the camera are not checked (coarse depth)")
        .number("carve_time", [](C& c) -> double& { return c.motion.carve_time; }, R::atLeast(0), "s",
                "Time the map carves free the region of a parked vehicle that drove off (0: never)")
        .number("carve_half_size", [](C& c) -> double& { return c.motion.carve_half_size; }, R::above(0), "m",
                "Half the side of that region, around where the vehicle was parked");
    t.rule([](const C& c) {
      if (!(c.motion.moving_share < c.motion.static_share))
        requireInRange("moving_share", ParamRange{0.0, c.motion.static_share, false, true}, c.motion.moving_share,
                       "(below static_share)");
      if (!(c.colour_far > c.colour_near))
        requireInRange("colour_range", ParamRange::above(c.colour_near), c.colour_far, "m (far greater than near)");
    });
    return t;
  }();
  return t;
}

void DepthMaskConfig::validate() const { params().check(*this); }

DepthMaskConfig DepthMaskConfig::fromParams(const ParamSource& p, DepthMaskConfig base) {
  return params().read(p, std::move(base));
}

cv::Rect maskedRect(const Detection& b, float margin_px, cv::Size depth_size, int image_w, int image_h) {
  if (!std::isfinite(b.x_min) || !std::isfinite(b.y_min) || !std::isfinite(b.x_max) || !std::isfinite(b.y_max))
    return cv::Rect();
  const float sx = float(depth_size.width) / image_w, sy = float(depth_size.height) / image_h;
  // Pixel u is inside when its centre u + 0.5 lies in [x_min - m, x_max + m] (depth pixels).
  const int u0 = std::max(0, int(std::ceil((b.x_min - margin_px) * sx - 0.5f)));
  const int u1 = std::min(depth_size.width - 1, int(std::floor((b.x_max + margin_px) * sx - 0.5f)));
  const int v0 = std::max(0, int(std::ceil((b.y_min - margin_px) * sy - 0.5f)));
  const int v1 = std::min(depth_size.height - 1, int(std::floor((b.y_max + margin_px) * sy - 0.5f)));
  if (u1 < u0 || v1 < v0) return cv::Rect();
  return cv::Rect(u0, v0, u1 - u0 + 1, v1 - v0 + 1);
}

cv::Mat maskDepthBoxes(cv::Mat& depth, const std::vector<Detection>& boxes, float margin_px, int image_w,
                       int image_h) {
  if (depth.type() != CV_32FC1) throw std::invalid_argument("maskDepthBoxes: depth must be 32FC1");
  if (image_w <= 0 || image_h <= 0) throw std::invalid_argument("maskDepthBoxes: detection image size must be positive");
  if (!(margin_px >= 0.f)) throw std::invalid_argument("maskDepthBoxes: margin must be >= 0");
  cv::Mat mask(depth.size(), CV_8UC1, cv::Scalar(0));
  for (const auto& b : boxes) {
    const cv::Rect r = maskedRect(b, margin_px, depth.size(), image_w, image_h);
    if (r.empty()) continue;
    depth(r).setTo(std::numeric_limits<float>::quiet_NaN());
    mask(r).setTo(255);
  }
  return mask;
}

}  // namespace fisheye_mapping
