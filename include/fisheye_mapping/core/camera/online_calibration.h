// Online self-calibration (issue 26): keeps each supporting camera's
// rotation relative to the reference camera right while driving, from the
// frame sets the depth stage sweeps anyway, and, given the vehicle's poses,
// its translation (below). No ROS.
//
// Every `period`-th frame set (and the second one; every `period_steady`-th
// once every camera is steady: past its warm-up, its last fit below a third
// of `change_deg`, the newest set alone not far off; the next set when the
// newest set alone is far off, to confirm a knock at once), the rig's matcher
// (RigMatcher, the first half of refine_rig) gathers feature matches between
// the reference and each support camera (within 1 deg of the current
// epipolar planes for a camera whose last pooled fit found it close, within
// the full band otherwise); a match is a pair of bearings in the cameras' own frames, so it stays
// valid whatever rotation is applied later. Per camera:
//  1. the newest frame set's matches are fitted alone (estimateCameraCorrection:
//     RANSAC, Huber Gauss-Newton, held-out acceptance). When that fit needs
//     more than `change_deg` from the current rotation in two updates in a
//     row, both times to within `change_deg` of the same rotation, the older
//     matches no longer describe the camera (it was knocked, or the
//     calibration is still far off): the pool restarts from those two sets;
//  2. the pool (the last `window` sampled frame sets) is fitted; the fit is
//     applied only if the pool holds two frame sets or more and the fit
//     passes the held-out test (halves of whole frame sets, each half's fit
//     scored on the other half against the current rotation's score there:
//     no bias toward the current calibration, nor toward one scene) and is
//     significant. The one exception (`first_set`): a camera never corrected
//     yet takes a fit of the first frame set alone that passes the held-out
//     test on halves of that set's matches (alternate matches), is
//     significant and exceeds `change_deg` (what one set is trusted to tell
//     from its scene's bias), in full: nothing was swept with the calibration as given
//     yet, and a one-set fit (within about 0.1 deg of the truth on
//     realistic rigs) is far closer than a rig a fraction of a degree off,
//     so depth is corrected from the first frame set on (a single frame set,
//     as plane_sweep_depth gets, included); the pool refines it from the
//     second set on;
//  3. a correction whose total from the given calibration exceeds
//     `max_correction_deg` is refused and reported, never applied;
//  4. applied smoothly: the current rotation moves a fraction `gain` of the
//     way to the fit (R <- R exp(gain log(R^T R_fit))).
// Translations (issue 26, part 2; `translation`, with the vehicle's poses):
// a baseline's length cannot be seen in one frame set's images, the
// vehicle's motion between two sets can. At an update whose set and the one
// before it have poses (the reference camera moved 0.3-5 m), the reference
// keypoints of this update's matches are tracked into the previous set's
// reference image (each patch first resampled by the local affine map of a
// surface facing the camera at the depth the current rig gives it, then KLT,
// forward-backward checked) and triangulated with the known motion: points
// of metric position, each seen by the support cameras it was matched in.
// Per camera, the matches of the last 6 x `window` such pairs are pooled and
// the camera's full pose fitted (estimateCameraPose: robust Gauss-Newton on
// the angular reprojection residual, each point weighted by its
// triangulation's uncertainty as the camera sees it); the fit's translation
// is applied (in full) when both halves of the pool (whole frame
// pairs) move it the same way, the change exceeds 4 standard errors (scaled
// up when the halves disagree by more than their covariance allows), the
// pool has 300 inliers or more, and its total from the given calibration is
// at most `max_translation_mm` (else refused and reported). The rotation is
// left to the epipolar fits above, which use the corrected translation from
// the next update on.
// A camera whose image is missing, black or flat (night, lens cap), or frozen
// (the same image as at the last update while the reference image changed)
// gets no update and a warning naming it; the others go on. A static car (the
// reference image as at the last update) brings no new evidence: no update,
// reported as such.
#ifndef FISHEYE_MAPPING_CORE_CAMERA_ONLINE_CALIBRATION_H_
#define FISHEYE_MAPPING_CORE_CAMERA_ONLINE_CALIBRATION_H_

#include <deque>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/camera/rig_refinement.h"

namespace fisheye_mapping {

template <typename Config>
class ParamTable;

struct SelfCalibrationConfig {
  bool enabled = true;               // self_calibration
  int period = 5;                    // self_calibration_period: frame sets from one update to the next
  int period_steady = 8;             // self_calibration_period_steady: ... once every camera is steady
  int window = 4;                    // self_calibration_window: sampled frame sets whose matches are pooled
  double max_correction_deg = 2.0;   // self_calibration_max_correction_deg: from the given calibration
  int min_inliers = 20;              // self_calibration_min_inliers: minimum evidence of a fit (docs/depth.md#one-frame-set-a-fit-from-20-inliers-2026-12-06)
  double gain = 0.6;                 // self_calibration_gain: fraction of a fit applied per update
  double change_deg = 0.15;          // self_calibration_change_deg: the newest set alone needing more restarts the pool
  int max_features = 3000;           // self_calibration_features: ORB keypoints per image
  bool first_set = true;             // self_calibration_first_set: correct from the first frame set on
  std::string start_file;            // self_calibration_start: a camchain saved by a previous run
  bool translation = true;           // self_calibration_translation: also the translations, from the poses
  double max_translation_mm = 50.0;  // self_calibration_max_translation_mm: from the given calibration
  // Throws std::invalid_argument naming the parameter.
  void validate() const;
  // The declarations (included by DepthStageConfig's table).
  static const ParamTable<SelfCalibrationConfig>& params();
  // The matcher and estimator settings these stand for.
  RigRefinementConfig refinement() const;
};

struct CameraCalibrationState {
  int camera = -1;
  std::string name;
  bool reference = false;
  bool warn = false;                  // no update for a reason the user should see
  std::string status;                 // one line: "converged", "correcting", "warming up", or why not updated
  Eigen::Vector3d correction_rotvec_deg = Eigen::Vector3d::Zero();  // applied, from the given calibration, camera frame
  double correction_deg = 0.0;        // its angle
  double residual_deg = 0.0;          // RMS angular epipolar residual over the last fit's inliers, current rotation
  double last_fit_deg = 0.0;          // the last fit's correction from the then current rotation
  int inliers = 0;                    // of the last fit
  int pooled_matches = 0;
  int updates = 0;                    // fits applied
  int refused = 0;                    // fits above max_correction_deg
  int restarts = 0;                   // pool restarts (a knock, or still far off)
  // Translation (from metric matches: points triangulated by the reference
  // camera's own motion between frame sets, seen by this camera).
  Eigen::Vector3d translation_correction_mm = Eigen::Vector3d::Zero();  // applied, from the given, reference frame
  int translation_updates = 0;        // translation fits applied
  int metric_matches = 0;             // pooled metric matches of the last fit
  std::string translation_status;     // one line, as status
};

class OnlineRigCalibrator {
 public:
  // given: the calibration as given; supports: rig indices of the cameras to
  // keep right (not the reference); self_masks: none or one per camera
  // (non-zero = car body, never matched). Throws std::invalid_argument naming
  // the parameter. A config.start_file that cannot be used (missing, corrupt,
  // of another rig) is not an error: the calibrator starts from `given` and
  // startError() says why.
  OnlineRigCalibrator(const Rig& given, int reference, std::vector<int> supports, std::vector<cv::Mat> self_masks,
                      const SelfCalibrationConfig& config);

  // One frame set (images[i]: rig camera i; grey or BGR, 8/16 bit or float in
  // [0, 1]; empty: not in the set). Every period-th call updates (and the
  // second). True when the rig changed. T_world_base: the vehicle's pose at
  // the set, when known (tf): with the previous set's pose it gives the
  // reference camera's motion, which makes points of known metric position
  // from which the supporting cameras' translations are fitted (config
  // translation); without poses only rotations are corrected.
  bool observe(const std::vector<cv::Mat>& images, const Eigen::Isometry3d* T_world_base = nullptr);

  const Rig& rig() const { return rig_; }
  const Rig& givenRig() const { return given_; }
  int reference() const { return ref_; }
  const std::vector<CameraCalibrationState>& state() const { return state_; }
  // Why the last update brought nothing new ("" if it did): a static car.
  const std::string& lastNote() const { return note_; }
  int frameSets() const { return frame_sets_; }
  int updates() const { return updates_; }
  // Frame sets from the last update to the next one: period, period_steady
  // (every camera steady) or 1 (a camera's newest set far off).
  int interval() const { return interval_; }
  double lastUpdateMs() const { return last_ms_; }
  // Of which finding the matches (the rest: the fits).
  double lastMatchMs() const { return last_match_ms_; }
  // Of which tracking and triangulating the metric matches.
  double lastMetricMs() const { return last_metric_ms_; }
  // Time of the last observe() call (0 when it did not update).
  double lastCallMs() const { return last_call_ms_; }
  // Why self_calibration_start could not be used ("" if it was, or none was
  // given): the calibrator then started from the given calibration.
  const std::string& startError() const { return start_error_; }
  const SelfCalibrationConfig& config() const { return config_; }
  double totalMs() const { return total_ms_; }
  // Of totalMs(): finding the matches, and tracking / triangulating the metric matches.
  double totalMatchMs() const { return total_match_ms_; }
  double totalMetricMs() const { return total_metric_ms_; }
  // Whether any correction has been applied since the start (or the start file).
  bool changed() const { return changed_; }

  // Starts from a rig saved by saveCalibration: its rotations of the support
  // cameras relative to the reference replace the current ones. Throws
  // CalibrationError naming the file and what does not fit the given rig
  // (other cameras, intrinsics, baselines, a correction above the maximum);
  // then nothing changes.
  void startFrom(const std::string& camchain_path);
  // Writes the current rig as a Kalibr camchain at camchain_path and its mount
  // beside it (savedMountPath), each through SafeFileWriter (a temporary file
  // beside the target, checked, renamed over it; a link there is replaced,
  // never followed; a FIFO or a device is refused); an existing
  // camchain/mount is kept as <name>.1. Throws std::runtime_error naming the
  // file and the OS error.
  void saveCalibration(const std::string& camchain_path) const;
  static std::string savedMountPath(const std::string& camchain_path);

 private:
  void update(const std::vector<cv::Mat>& grey);
  // One support camera's step of update(): its newest matches join its pool,
  // the fits and tests run, its state is set. Returns the rotation
  // R_ref_cam to apply, if any. Touches only camera c's state (update() runs
  // the cameras in parallel).
  std::optional<Eigen::Matrix3d> fitCamera(int c, std::vector<EpipolarMatch> found);
  // The translation's step: the newest metric matches join camera c's metric
  // pool, the pose fit and its tests run. Returns the translation t_ref_cam
  // to apply, if any. Touches only camera c's state.
  std::optional<Eigen::Vector3d> fitTranslation(int c, std::vector<MetricMatch> found);
  // Metric matches of this set per camera: the reference camera's keypoints
  // of `found` tracked into the previous set's reference image (KLT, from
  // where the current rig's depth puts them; forward-backward checked),
  // triangulated with the reference camera's motion T_cur_prev.
  std::vector<std::vector<MetricMatch>> metricMatches(const cv::Mat& ref_grey,
                                                      const std::vector<std::vector<EpipolarMatch>>& found,
                                                      const Eigen::Isometry3d& T_cur_prev) const;
  void applyPose(int c, const std::optional<Eigen::Matrix3d>& R_ref_cam, const std::optional<Eigen::Vector3d>& t_ref_cam);
  Eigen::Isometry3d relative(const Rig& rig, int c) const;

  Rig given_, rig_;
  int ref_;
  std::vector<int> supports_;
  SelfCalibrationConfig config_;
  RigRefinementConfig refinement_, quick_;  // the pool's fit; the newest set's alone
  RigMatcher matcher_;
  std::vector<std::mt19937_64> rngs_;  // per camera: RANSAC sampling (the cameras' fits run in parallel)
  std::vector<std::deque<std::vector<EpipolarMatch>>> pools_;  // per camera, newest last
  std::vector<std::deque<std::vector<MetricMatch>>> metric_pools_;  // per camera, newest last
  cv::Mat prev_ref_;                                           // the previous set's reference image (8-bit grey)
  std::optional<Eigen::Isometry3d> prev_pose_, pose_;          // T_world_base of the previous and the current set
  std::vector<cv::Mat> last_thumbs_;                           // per camera, at the last update
  std::vector<char> has_far_;                 // per camera (not vector<bool>: written in parallel): the last update's newest set alone was far off
  std::vector<Eigen::Matrix3d> far_target_;   // ... and where it wanted R_ref_cam
  bool started_from_file_ = false;            // self_calibration_start was used
  std::vector<CameraCalibrationState> state_;
  std::string note_;
  int frame_sets_ = 0, updates_ = 0;
  int next_due_ = 0;  // the frame set of the next update (besides the second set)
  int interval_ = 0;
  double last_ms_ = 0.0, total_ms_ = 0.0, last_call_ms_ = 0.0, last_match_ms_ = 0.0, last_metric_ms_ = 0.0;
  double total_match_ms_ = 0.0, total_metric_ms_ = 0.0;
  std::string start_error_;
  bool changed_ = false;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_CAMERA_ONLINE_CALIBRATION_H_
