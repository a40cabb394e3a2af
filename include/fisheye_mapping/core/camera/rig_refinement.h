// Rig refinement from image features: corrects the extrinsic rotation of each
// support camera relative to a reference camera (and optionally the direction
// of its translation, the calibrated baseline length kept).
//
// Per frame set, each support image is resampled into the reference camera's
// geometry through the calibrated rotation (patches then look alike in both
// images whatever the cameras' yaw; only parallax and the rotation error
// separate them). ORB features of the reference image are matched to those of
// the resampled image within a window around their epipolar plane (mutual best
// match, ratio test), and each match is refined to subpixel by KLT (a match
// KLT moves 3 px or more is dropped, unless fewer than min_settled settle:
// then it keeps its keypoint at 1/16 of the weight; a wide baseline's
// patches differ in scale and blur, docs/depth.md "A surround-view rig"). Keypoints
// become unit bearing rays through the camera models (any direction, z <= 0
// included); a resampled pixel's ray is the support camera's ray, exactly.
// Matches of all frame sets are pooled per camera. With the calibrated
// translation t of the support camera in the reference frame, a match (f_ref,
// f_sup) satisfies the epipolar constraint f_ref . (t x R f_sup) = 0. RANSAC
// over minimal samples (3 matches, rotation solved by Gauss-Newton from the
// calibration) finds the inliers; Huber-weighted Gauss-Newton over an so(3)
// increment R = R_cal * exp(w) then minimises the angular epipolar residual
// (angle of each ray to the epipolar plane, symmetric in both rays). Distant
// points constrain R directly; the known translation fixes the rest.
//
// Residuals are angles in degrees. A camera with too few inliers keeps its
// calibration. Whether the fit is better is decided without favouring the
// calibration being corrected (the matches were found in images resampled with
// it, so counting inliers at a fixed threshold would): two-fold
// cross-validation, each half's fit scored on the other half's matches by a
// truncated RMS residual (heldout_truncation_deg) against the calibration's
// score on the same matches (halves of whole frame sets when there are
// several: a bias of one scene does not score on itself); both halves must
// improve, the residual explained on held-out matches must be a fair share of
// the one explained on the fitted ones, and the correction must exceed its own
// standard error (significance) - else the camera keeps its calibration.
//
// The pieces are used on their own by the online self-calibration
// (online_calibration.h): RigMatcher gathers one frame set's matches,
// estimateCameraCorrection fits one camera.
#ifndef FISHEYE_MAPPING_CORE_CAMERA_RIG_REFINEMENT_H_
#define FISHEYE_MAPPING_CORE_CAMERA_RIG_REFINEMENT_H_

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/rig.h"

namespace fisheye_mapping {

struct RigRefinementConfig {
  int max_features = 6000;          // ORB keypoints per image
  int pyramid_levels = 4;           // ORB scale levels (factor 1.2)
  double ratio = 0.8;               // Lowe ratio test on the two best matches
  int max_hamming = 80;             // largest descriptor distance (of 256 bits) of a match
  bool warp_support = true;         // match against support images resampled into the reference geometry
  bool subpixel = true;             // refine support keypoints by local image alignment (KLT)
  int klt_window = 15;              // KLT window side, pixels
  bool weight_by_resolution = true;  // weight residuals by the images' pixels per radian at the rays
  int min_inliers = 20;             // fewer: the camera is left unchanged (docs/depth.md "One frame set")
  // Fewer matches than this settle under KLT: the unsettled keep their
  // keypoints at 1/16 of the weight (a wide baseline's matches).
  int min_settled = 50;
  double max_initial_residual_deg = 3.0;  // matches beyond this at the calibration are dropped
  double ransac_threshold_deg = 0.3;
  int ransac_iterations = 300;
  double huber_deg = 0.1;           // Huber loss scale of the final fit
  int max_iterations = 30;          // Gauss-Newton iterations
  bool refine_translation = false;  // also the translation direction (baseline length kept)
  uint64_t seed = 1;                // RANSAC sampling
  // Held-out test: residuals beyond this count as this much (outliers weigh
  // the same under any calibration).
  double heldout_truncation_deg = 1.0;
  // The correction must exceed this many standard errors (from the fit's
  // normal equations and residual spread) to be applied.
  double min_significance = 4.0;
  // The residual the fit explains on held-out matches (sqrt(before^2 -
  // after^2)) must be at least this share of what it explains on the
  // matches it was fitted to.
  double min_generalization = 0.5;
  // A camera's candidates beyond this are evenly subsampled for the fits
  // (0: all).
  int max_fit_matches = 0;

  // Throws std::invalid_argument naming the field.
  void validate() const;
};

struct CameraRefinement {
  enum class Status {
    kReference,     // the reference camera itself
    kApplied,       // corrected
    kTooFewInliers, // fewer than min_inliers: unchanged
    kNotImproved,   // the fit did not lower the held-out residual, or is not significant: unchanged
  };
  int camera = -1;
  std::string name;
  Status status = Status::kReference;
  int matches = 0;                // mutual feature matches over all frame sets
  int candidates = 0;             // of which within max_initial_residual_deg at the calibration
  int inliers = 0;                // within ransac_threshold_deg at the estimate
  double rms_before_deg = 0.0;    // RMS angular epipolar residual over the inliers, calibration
  double rms_after_deg = 0.0;     // the same at the estimate
  double correction_deg = 0.0;    // angle of the estimated rotation correction
  Eigen::Vector3d correction_axis = Eigen::Vector3d::Zero();  // in the camera's frame
  double translation_change_deg = 0.0;  // angle between old and new translation direction
  double translation_change_mm = 0.0;   // estimateCameraPose: length of the translation change
  double translation_standard_error_mm = 0.0;  // ... its standard error along the change
  double heldout_before_deg = 0.0;  // held-out truncated RMS residual, calibration (mean of both halves)
  double heldout_after_deg = 0.0;   // the same of each half's fit
  double standard_error_deg = 0.0;  // of the correction's angle
  // R_ref_cam(refined) = R_ref_cam(calibrated) * correction (camera frame).
  Eigen::Matrix3d correction = Eigen::Matrix3d::Identity();
  std::string message;            // why a camera was left unchanged
};

const char* toString(CameraRefinement::Status status);

struct RigRefinementResult {
  Rig rig;                                // the input rig with the applied corrections
  std::vector<CameraRefinement> cameras;  // one per rig camera, rig order
  int frame_sets = 0;
  int applied() const;                    // cameras corrected
  int totalInliers() const;
};

// Refines `rig` from synchronized frame sets: frame_sets[k][c] is camera c's
// CV_8UC1 image of set k, of the calibrated size. self_masks is empty or has
// one (possibly empty) CV_8UC1 mask per camera; non-zero pixels (car body) give
// no features. Throws std::invalid_argument naming the problem (reference out
// of range, no frame set, wrong image count, size or type, bad mask).
RigRefinementResult refineRig(const Rig& rig, int reference,
                              const std::vector<std::vector<cv::Mat>>& frame_sets,
                              const std::vector<cv::Mat>& self_masks = {},
                              const RigRefinementConfig& config = {});

// One correspondence between the reference camera and a support camera: unit
// bearings in each camera's own frame (they do not depend on the extrinsics,
// so matches gathered under one calibration stay valid under another), and
// the inverse variance of its residual, relative.
struct EpipolarMatch {
  Eigen::Vector3d f_ref, f_cam;
  double weight = 1.0;
};

// Feature matches of frame sets between a rig's reference camera and its
// support cameras (the first half of refineRig). Keeps the resampling maps of
// each support camera and makes them anew only when the rig's rotation of that
// camera moved by more than 0.25 degrees (the maps only need to make patches
// look alike) or its model changed.
class RigMatcher {
 public:
  // self_masks: none, or one per camera (empty or CV_8UC1, non-zero = car
  // body: no features), of the calibrated size (checked by match()).
  explicit RigMatcher(const RigRefinementConfig& config, std::vector<cv::Mat> self_masks = {});
  // Matches of one frame set per rig camera (empty for the reference and for
  // cameras whose image is empty). images: CV_8UC1 of the calibrated sizes (a
  // support camera's may be empty: skipped). raw: mutual feature matches
  // before subpixel refinement and masking, per camera. band_deg: none, or
  // per camera the half-width of the search band around the current
  // epipolar planes (0: max_initial_residual_deg), narrower for a camera
  // known to be close (less work). Throws std::invalid_argument naming the
  // camera for a wrong image.
  std::vector<std::vector<EpipolarMatch>> match(const Rig& rig, int reference, const std::vector<cv::Mat>& images,
                                                std::vector<int>* raw = nullptr,
                                                const std::vector<double>& band_deg = {});

 private:
  struct Warp {
    Eigen::Matrix3d R_ref_cam = Eigen::Matrix3d::Zero();
    int width = 0, height = 0;
    cv::Mat map_x, map_y, feature_mask;
    cv::Mat map_fixed, map_fraction;  // map_x/map_y as cv::convertMaps' fixed-point pair: remap's fast path
  };
  const Warp& warpFor(const Rig& rig, int reference, int c);
  RigRefinementConfig config_;
  std::vector<cv::Mat> self_masks_;
  std::vector<cv::Mat> detect_masks_;  // per camera: non-zero where features may lie (outside the self-mask)
  std::vector<Warp> warps_;
  int warp_reference_ = -1;
  std::vector<Eigen::Vector3f> ref_rays_;  // the reference camera's pixel rays, kept with its model
  int ref_rays_width_ = 0, ref_rays_height_ = 0;
  FmCameraT<double> ref_rays_camera_{};
};

// Fits one support camera's pose relative to the reference, T_ref_cam (the
// rig's current), to matches; the result's status says whether it is applied
// (kApplied: *T_estimated is the new pose; else *T_estimated = T_ref_cam).
// rng: RANSAC sampling. groups: none, or per match the frame set it came
// from: the held-out halves are then whole frame sets (alternate groups), so
// that a bias of one scene is not scored on itself.
CameraRefinement estimateCameraCorrection(const std::vector<EpipolarMatch>& matches, const Eigen::Isometry3d& T_ref_cam,
                                          const RigRefinementConfig& config, std::mt19937_64& rng,
                                          Eigen::Isometry3d* T_estimated, const std::vector<int>& groups = {});

// A support camera's observation of a point whose position in the reference
// camera's frame is known metrically: triangulated from the reference
// camera's own motion between two frame sets (the vehicle's poses), so it
// carries the scale the rig's images alone cannot (the baselines' lengths).
// f_cam: unit bearing in the support camera's frame; weight: relative inverse
// variance of its residual.
struct MetricMatch {
  Eigen::Vector3d X_ref, f_cam;
  double weight = 1.0;
};

// The full pose of one support camera (rotation and translation) fitted to
// metric matches, T_ref_cam the rig's current: robust Gauss-Newton on the
// angular reprojection residual from the current pose (matches beyond
// max_initial_residual_deg dropped, then inliers re-selected at
// ransac_threshold_deg), and the same acceptance as estimateCameraCorrection:
// each half (whole groups: frame pairs) fitted alone and scored on the other
// half against the current pose's score there (both must improve, the fit
// must explain min_generalization of its own residual on the held-out one),
// and the translation change must exceed min_significance standard errors
// of the translation (its marginal covariance). kApplied: *T_estimated is the
// fit (rotation and translation); else *T_estimated = T_ref_cam. The
// result's translation_change_mm and translation_standard_error_mm say how
// far and how sure.
CameraRefinement estimateCameraPose(const std::vector<MetricMatch>& matches, const Eigen::Isometry3d& T_ref_cam,
                                    const RigRefinementConfig& config, Eigen::Isometry3d* T_estimated,
                                    const std::vector<int>& groups = {});

// How well a support camera's epipolar matches fit each of two translations
// (t_a, t_b: T_ref_cam's translation; only their directions matter), each
// with the rotation re-fitted from R0 (Huber Gauss-Newton): the truncated RMS
// angular epipolar residual (heldout_truncation_deg), in degrees, over the
// matches within max_initial_residual_deg at (R0, t_a). The rig's own matches
// never saw the frame-to-frame tracks a translation fit came from: an
// independent check of its direction.
void compareTranslations(const std::vector<EpipolarMatch>& matches, const Eigen::Matrix3d& R0,
                         const Eigen::Vector3d& t_a, const Eigen::Vector3d& t_b, const RigRefinementConfig& config,
                         double* rms_a_deg, double* rms_b_deg);

// The rig with camera `camera`'s pose relative to `reference` replaced by
// T_ref_cam; every camera's T_cam0_cam / T_base_cam stay consistent (cam0 may
// be the corrected one).
Rig withRelativePose(const Rig& rig, int reference, int camera, const Eigen::Isometry3d& T_ref_cam);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_CAMERA_RIG_REFINEMENT_H_
