// Depth checks that need no ground truth, for real data: agreement between
// the depth of two frames moved into one frame with their poses, and the
// flatness of the road near the vehicle.
//
// Depth images are CV_32FC1 range along the pixel's ray in metres, NaN (or
// <= 0) invalid, as written by PlaneSweep.
#ifndef FISHEYE_MAPPING_CORE_EVAL_DEPTH_CONSISTENCY_H_
#define FISHEYE_MAPPING_CORE_EVAL_DEPTH_CONSISTENCY_H_

#include <cstddef>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/camera_model.h"

namespace fisheye_mapping {

struct FrameConsistency {
  double share = 0.0;            // of the compared pixels, relative difference <= rel_tol
  size_t compared = 0;           // pixels of a with a valid range and a point of b
  double median_rel_diff = 0.0;  // median of |r_a - r_b| / r_a over the compared pixels
  size_t valid_a = 0;            // valid pixels of depth_a
};

// Moves the points of depth_b into frame a (p_a = T_a_b * p_b), projects them
// with cam_a to the nearest pixel and keeps the nearest point per pixel
// (z-buffer, so a surface b sees behind a nearer one does not count). Each
// pixel of a with a valid range and a point of b is compared: relative
// difference |r_a - r_b| / r_a with r_b the point's range from camera a.
// Occlusion: only pixels valid in both are compared; a point b sees that a
// does not (disoccluded) lands behind a's surface and counts as a
// disagreement, which at small baselines is rare. Throws
// std::invalid_argument when an image does not match its camera.
FrameConsistency frameConsistency(const cv::Mat& depth_a, const CameraModel& cam_a, const cv::Mat& depth_b,
                                  const CameraModel& cam_b, const Eigen::Isometry3d& T_a_b,
                                  double rel_tol = 0.05);

// A box on the nominal ground in a ground frame (z up, ground z = 0).
struct GroundBox {
  double x_min = 2.0;  // metres along the ground frame's x ("ahead")
  double x_max = 8.0;
  double y_min = -2.0;  // metres along its y (lateral)
  double y_max = 2.0;
};

// Ground frame under a camera: origin at the camera's foot point on the
// ground z = ground_z of the base frame, z along the base frame's z (up), x
// along the camera's optical axis projected on the ground (the direction the
// camera looks in), y = z x x. Returns T_ground_cam. Throws
// std::invalid_argument when the optical axis is vertical.
Eigen::Isometry3d cameraGroundFrame(const Eigen::Isometry3d& T_base_cam, double ground_z = 0.0);

// CV_8UC1 mask (255) of the pixels whose ray meets the ground plane z = 0 of
// the ground frame inside `box` (in front of the camera). The region follows
// from the calibration alone, not from any depth, so a wrong depth inside it
// still counts against flatness.
cv::Mat groundRegionMask(const CameraModel& camera, const Eigen::Isometry3d& T_ground_cam, const GroundBox& box);

struct RoadFlatness {
  double share = 0.0;              // of the points, distance to the plane <= tol
  size_t points = 0;               // valid depth pixels inside the mask
  size_t inliers = 0;
  double median_abs_dist = 0.0;    // metres, over all points
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // fitted plane n . p + d = 0
  double d = 0.0;                                    // (camera frame, |n| = 1)
};

// Back-projects the valid depth pixels where `mask` is non-zero (an empty
// mask: all pixels) to points in the camera frame, fits a plane robustly
// (RANSAC with threshold tol, fixed seed, then least-squares refits on the
// inliers) and returns the share of points within tol of it. Fewer than 3
// points: share 0, normal zero. Throws std::invalid_argument when depth or
// mask do not match the camera.
RoadFlatness roadPlaneFlatness(const cv::Mat& depth, const CameraModel& camera, const cv::Mat& mask,
                               double tol = 0.05);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_EVAL_DEPTH_CONSISTENCY_H_
