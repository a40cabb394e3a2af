// Rig refinement from image features: corrects the extrinsic rotation of each
// support camera relative to a reference camera (and optionally the direction
// of its translation, the calibrated baseline length kept).
//
// Per frame set, each support image is resampled into the reference camera's
// geometry through the calibrated rotation (patches then look alike in both
// images whatever the cameras' yaw; only parallax and the rotation error
// separate them). ORB features of the reference image are matched to those of
// the resampled image within a window around their epipolar plane (mutual best
// match, ratio test), and each match is refined to subpixel by KLT. Keypoints
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
// Residuals are angles in degrees. A camera with too few inliers, or whose RMS
// residual over its inliers does not improve, keeps its calibration: the
// result is never worse than the input.
#ifndef FISHEYE_MAPPING_CORE_CAMERA_RIG_REFINEMENT_H_
#define FISHEYE_MAPPING_CORE_CAMERA_RIG_REFINEMENT_H_

#include <cstdint>
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
  int min_inliers = 50;             // fewer: the camera is left unchanged
  double max_initial_residual_deg = 3.0;  // matches beyond this at the calibration are dropped
  double ransac_threshold_deg = 0.3;
  int ransac_iterations = 300;
  double huber_deg = 0.1;           // Huber loss scale of the final fit
  int max_iterations = 30;          // Gauss-Newton iterations
  bool refine_translation = false;  // also the translation direction (baseline length kept)
  uint64_t seed = 1;                // RANSAC sampling
  // Throws std::invalid_argument naming the field.
  void validate() const;
};

struct CameraRefinement {
  enum class Status {
    kReference,     // the reference camera itself
    kApplied,       // corrected
    kTooFewInliers, // fewer than min_inliers: unchanged
    kNotImproved,   // the fit did not lower the residual: unchanged
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

// The rig with camera `camera`'s pose relative to `reference` replaced by
// T_ref_cam; every camera's T_cam0_cam / T_base_cam stay consistent (cam0 may
// be the corrected one).
Rig withRelativePose(const Rig& rig, int reference, int camera, const Eigen::Isometry3d& T_ref_cam);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_CAMERA_RIG_REFINEMENT_H_
