// Which detected vehicles move (issue 31): parked cars belong to the static
// street a planner needs, so only moving vehicles, and those not decided
// yet, are masked out of the depth before fusion. No ROS.
//
// Each box is placed in the world from the depth inside it: the pixels of
// its inner part (the box shrunk, to leave out the background around the
// body), the nearest cluster of their ranges (the body, not the road or
// facade seen past it), and the median of those points' world x and y.
// Boxes are tracked across frame sets by that position (nearest track within
// a gate around its prediction); a track's speed is the slope of a
// least-squares line through its positions of the last `speed_window`
// seconds. Only vehicles within `decide_range` of the camera are measured
// (farther, stereo depth is too coarse to tell a parked car from a slow one;
// the map fuses nearer depth only). A vehicle is decided once tracked for
// `decide_after` seconds, and only when its measured speed is clear of
// `moving_speed`: the speed's standard error (the positions' scatter about
// the fitted line, at least `position_noise`, over the spread of their
// stamps) times `speed_significance` must separate the speed from
// moving_speed; moving above, parked below, undecided (masked) in between.
// A few noisy positions at first sight (a parked car's first boxes placed a
// metre apart) so no longer decide "moving" for good.
// A vehicle once seen moving stays moving. The static check (within
// static_range) compares the body's depth with the camera's depth map of
// static_interval earlier: a vehicle is called moving only when its body
// moved (at most moving_share of its points agree, in moving_frames measured
// frame sets in a row; beyond static_range, or in between, it stays
// undecided); one that has looked static (static_share
// agree) in static_frames frame sets in a row is called parked whatever its
// measured speed, only while its measured velocity runs along the ego's
// heading: the near face of a parked car passed close by slides that way,
// while a vehicle crossing moves across it, its flank sliding along itself
// (which the depth check cannot see). A box of a parked vehicle's
// track placed more than `parked_tolerance` (plus twice its expected
// scatter) from where the vehicle stands is undecided (masked), not parked:
// another vehicle driving past taken for it, or the vehicle driving off. A box cut by the image border
// only shows part of its vehicle, a part that changes as the vehicle leaves
// the view (a parked car passed by seems to move along with the ego), so it
// keeps its track's decision and position for the association but does not
// measure speed. A second box on an already tracked vehicle (within
// `duplicate_distance` of a box of this frame set, e.g. "car" and "truck" on
// one vehicle) gets that box's decision. Undecided: a new or lost track, a
// box with too little depth (glass, dark paint), or no pose for the frame
// set.
//
// A vehicle that was parked (so fused into the map) and then drives off
// leaves a ghost in the map: its region (a box of carve_half_size around
// where it was parked) is handed out by ghostRegions() for carve_time
// seconds, for the map to carve free where the space behind it is seen
// (TsdfMap::integrate's carve regions).
#ifndef FISHEYE_MAPPING_CORE_DETECTION_VEHICLE_MOTION_H_
#define FISHEYE_MAPPING_CORE_DETECTION_VEHICLE_MOTION_H_

#include <cstdint>
#include <deque>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/StdVector>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/camera_model.h"
#include "fisheye_mapping/core/detection/detector.h"

namespace fisheye_mapping {

enum class VehicleMotion : uint8_t { Undecided = 0, Moving = 1, Parked = 2 };
const char* toString(VehicleMotion m);

struct VehicleMotionConfig {
  double moving_speed = 2.5;   ///< m/s: a vehicle this fast or faster moves
  double speed_significance = 2.0;  ///< standard errors the speed must lie from moving_speed to decide; 0: none
  double position_noise = 0.15;     ///< m: the scatter of a vehicle's placed positions at 10 m (grows with range^2)
  double parked_tolerance = 1.0;    ///< m (plus twice the scatter): a parked vehicle's box placed farther from where it stands is not called parked
  double decide_after = 0.3;   ///< s a vehicle is tracked before it is decided
  double speed_window = 1.0;   ///< s of track history the speed is measured over
  double gate = 2.5;           ///< m a box may lie from its track's prediction
  double max_gap = 1.0;        ///< s a track survives unseen
  int min_points = 20;         ///< depth pixels a box needs for a position
  double max_range = 40.0;     ///< m: farther depth does not place a vehicle
  double decide_range = 25.0;  ///< m: a vehicle farther from the camera is tracked but not measured
  double border_px = 3.0;      ///< px (of the detection image): a box this near the border is cut by it
  double duplicate_distance = 1.0;  ///< m between two boxes of one vehicle
  /// The static check: a vehicle's body points, placed in the world, are
  /// projected into the camera's depth map of static_interval s earlier;
  /// where that map sees them where they stand (within twice the position
  /// noise), the share that agrees tells a parked body (most) from a moving
  /// one (few), also where the placed position slides (a parked car passed
  /// close by: its near face changes). 0: off.
  double static_interval = 0.5;
  double static_share = 0.5;   ///< share of the seen body points that agree for a frame set to look static
  int static_frames = 3;       ///< frame sets in a row a vehicle must look static to be called parked (or not moving)
  double static_range = 15.0;  ///< m: farther vehicles are not checked (coarse depth)
  /// With the static check on, a vehicle is called moving only when at most
  /// this share of its body agrees with that depth map (< static_share):
  /// where the check cannot measure (beyond static_range, no depth there)
  /// or reads in between, the vehicle stays undecided (masked).
  double moving_share = 0.25;
  /// Frame sets in a row (of those the check measures) in which the body must
  /// read moved before the vehicle is called moving: a vehicle once called
  /// moving stays so, and one odd reading (a parked car's smooth body given
  /// a wrong depth in one of the two depth maps) must not decide that.
  int moving_frames = 2;
  double carve_time = 10.0;         ///< s a departed parked vehicle's region is carved; 0: never
  double carve_half_size = 3.0;     ///< m: half the side of that region (horizontal)
};

class VehicleMotionTracker {
 public:
  struct Decision {
    VehicleMotion motion = VehicleMotion::Undecided;
    int track = -1;                                                 ///< track id; -1: no position
    double speed = std::numeric_limits<double>::quiet_NaN();        ///< m/s; NaN until measurable
    Eigen::Vector3d position = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  };

  explicit VehicleMotionTracker(const VehicleMotionConfig& config = VehicleMotionConfig());

  /// Decides every box. `boxes` are in pixels of an image_w x image_h image
  /// (scaled to the depth's size when it differs); `depth`: CV_32FC1 range
  /// along the rays of `camera` (the depth's size), NaN invalid, before any
  /// masking; T_W_C: the camera's pose in the world at the frame set, none
  /// when unknown (every box undecided, the tracks kept). A stamp before the
  /// last one resets the tracks. Throws std::invalid_argument on a depth that
  /// is not CV_32FC1 or not of the camera's size, a non-positive image size,
  /// or a non-finite stamp.
  std::vector<Decision> update(const std::vector<Detection>& boxes, int image_w, int image_h, const cv::Mat& depth,
                               const CameraModel& camera, const std::optional<Eigen::Isometry3d>& T_W_C,
                               double stamp_s);
  void reset();
  size_t tracks() const { return tracks_.size(); }
  const VehicleMotionConfig& config() const { return config_; }
  /// The world regions of parked vehicles that drove off within the last
  /// carve_time seconds (of the last update's stamp).
  std::vector<Eigen::AlignedBox3d> ghostRegions() const;

  /// The world position of the vehicle in `box` (see the top of the file),
  /// none with fewer than min_points usable depth pixels; with body_C, the
  /// body's points in the camera too.
  std::optional<Eigen::Vector3d> place(const Detection& box, int image_w, int image_h, const cv::Mat& depth,
                                       const CameraModel& camera, const Eigen::Isometry3d& T_W_C,
                                       std::vector<Eigen::Vector3d>* body_C = nullptr) const;
  /// The share of `body_C` (points in the camera at T_W_C) that an earlier
  /// depth map of the same camera (`past`, at T_W_P) sees where a static body
  /// would be: projected there, a range within twice the position noise of
  /// that map's (the 3 x 3 pixels around). NaN with fewer than min_points
  /// seen there.
  double staticShare(const std::vector<Eigen::Vector3d>& body_C, const Eigen::Isometry3d& T_W_C, const cv::Mat& past,
                     const CameraModel& camera, const Eigen::Isometry3d& T_W_P) const;

 private:
  struct Track {
    int id = 0;
    // (stamp, position) of the boxes inside the image, over speed_window.
    std::deque<std::pair<double, Eigen::Vector3d>> history;
    double last_seen = 0.0;            // any box, cut or not
    Eigen::Vector3d last_position;     // of that box
    double first_seen = 0.0;
    VehicleMotion state = VehicleMotion::Undecided;
    Eigen::Vector3d parked_position;   // the last one while parked
    Eigen::Vector3d parked_centre;     // the body's middle then: a half length on from the near face
    // The least-squares line through the history: velocity, the stamps'
    // spread (sum of squared deviations) and the positions' scatter about it
    // per axis (0 with two points); false with fewer than two stamps apart.
    bool fit(Eigen::Vector2d* velocity, double* stt, double* sigma) const;
    double speed() const;
    std::deque<double> noise;  // each history position's expected scatter (m)
    int static_hits = 0;       // frame sets in a row it looked static (the static check)
    int moved_hits = 0;        // measured frame sets in a row its body read moved (the static check)
    // The speed's standard error: the positions' scatter about the fitted
    // line (at least their expected scatter) over the root of the stamps' spread.
    double speedError() const;
  };
  // The expected scatter of a position placed at p_W from a camera at T_W_C:
  // position_noise at 10 m or nearer, growing with the square of the range.
  double positionNoise(const Eigen::Vector3d& p_W, const Eigen::Isometry3d& T_W_C) const;
  double noiseAt(double range) const;  // the same at a range from the camera
  // Whether a track's measured velocity runs along the heading of the
  // camera at T_W_C (its component across less than half moving_speed).
  bool alongHeading(const Track& tr, const Eigen::Isometry3d& T_W_C) const;
  struct Ghost {
    Eigen::AlignedBox3d region;
    double until = 0.0;
  };
  std::vector<Ghost> ghosts_;
  // The depth maps the static check compares with: the newest at least
  // static_interval old and those after it.
  struct Past {
    double stamp;
    cv::Mat depth;
    Eigen::Isometry3d T_W_C;
  };
  std::deque<Past, Eigen::aligned_allocator<Past>> past_;
  VehicleMotionConfig config_;
  std::vector<Track> tracks_;
  int next_id_ = 0;
  double last_stamp_ = -std::numeric_limits<double>::infinity();
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DETECTION_VEHICLE_MOTION_H_
