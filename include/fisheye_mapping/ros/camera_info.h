// sensor_msgs/CameraInfo <-> core camera models and rigs (library
// fisheye_mapping_ros).
//
// distortion_model strings and D layouts (K, width, height as usual):
//   "plumb_bob"            pinhole + radtan      D = [k1, k2, p1, p2, k3], k3 = 0
//   "rational_polynomial"  pinhole + radtan      D = [k1, k2, p1, p2, k3, k4, k5, k6],
//                          (read only; written as "plumb_bob")   k3..k6 = 0
//   "equidistant"          Kannala-Brandt        D = [k1, k2, k3, k4]
//   "omni"                 Mei unified + radtan  D = [xi, k1, k2, p1, p2]
//   "double_sphere"        double sphere         D = [xi, alpha]
// The first three are sensor_msgs/distortion_models.h's names, so image_proc
// and image_geometry read our pinhole and Kannala-Brandt cameras. Mei and
// double sphere have no standard name; "omni" and "double_sphere" are Kalibr's
// camera model names as ethz-asl/image_undistort spells them, and D puts the
// Kalibr intrinsics ahead of the distortion coefficients as image_undistort
// does (docs/calibration.md#camerainfo).
//
// K = [fx skew cx; 0 fy cy; 0 0 1] (pixel centres at integers, as in the core
// and OpenCV), R = identity, P = [K | 0], binning 0, roi all zero (the full
// image). Reading ignores R and P (they describe a rectified image, which the
// core never uses) and rejects binning above 1 and a partial roi.
//
// Every reader throws CalibrationError (rig.h) whose message names the
// CameraInfo by its frame id and the field, e.g.
//   "CameraInfo 'cam0_optical': D: expected 5 values for distortion_model
//    'omni' (xi, k1, k2, p1, p2), got 4".
#ifndef FISHEYE_MAPPING_ROS_CAMERA_INFO_H_
#define FISHEYE_MAPPING_ROS_CAMERA_INFO_H_

#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <tf2_ros/buffer.h>

#include "fisheye_mapping/core/camera/camera_model.h"
#include "fisheye_mapping/core/camera/rig.h"

namespace fisheye_mapping {

// The distortion_model strings fromCameraInfo accepts (the table above).
const std::vector<std::string>& acceptedDistortionModels();

// The CameraInfo of images from `cam`. Exact: fromCameraInfo gives back the
// same parameters.
sensor_msgs::CameraInfo toCameraInfo(const CameraModel& cam, const std::string& frame_id,
                                     const ros::Time& stamp);
// The same with the rig camera's frame id.
sensor_msgs::CameraInfo toCameraInfo(const RigCamera& cam, const ros::Time& stamp);

// The camera a CameraInfo describes. Throws CalibrationError naming the field:
// unknown distortion_model (listing the accepted ones), D of the wrong length
// or with coefficients the model cannot hold, K not upper triangular with
// K[8] = 1, fx or fy not finite and positive, width or height zero, xi < 0,
// binning above 1, a partial roi, or any other parameter out of the camera
// model's limits (camera_model.h).
CameraModel fromCameraInfo(const sensor_msgs::CameraInfo& msg);

// One camera of a rig built from CameraInfos: the message and the camera's
// pose in the base frame (from tf2: lookupTransform(base_frame,
// info.header.frame_id, ...)).
struct CameraInfoAndPose {
  sensor_msgs::CameraInfo info;  // header.frame_id: the camera's optical frame
  Eigen::Isometry3d T_base_cam = Eigen::Isometry3d::Identity();
  std::string name;  // empty: "cam<index>"
};

// The rig of these cameras, in order (cameras[0] is cam0, the frame of
// T_cam0_cam), like loadKalibrRig's: camera frame ids from the headers,
// rostopic empty. Throws CalibrationError naming the camera and the field: no
// camera or more than kMaxRigCameras, any fromCameraInfo error, a pose that is
// not rigid or lies beyond kMaxRigTranslation, an empty base frame, a frame id
// that is empty, the base frame or another camera's, two cameras of one name.
Rig rigFromCameraInfos(const std::vector<CameraInfoAndPose>& cameras,
                       const std::string& base_frame = "base_link");

// The CameraInfo of an image resampled from the camera's by `scale` (0.5: a
// half-resolution depth image), of the size the depth stage gives such an
// image: floor(width * scale) x floor(height * scale) (W/2 x H/2 at 0.5). fx,
// fy, skew scale; cx, cy keep pixel centres consistent: c' = (c + 0.5) *
// scale - 0.5 (CameraModel::scaled). xi, alpha and the distortion
// coefficients act on normalized coordinates and do not change. Throws
// std::invalid_argument for a scale that is not finite and positive or gives
// an empty image.
sensor_msgs::CameraInfo scaledCameraInfo(const CameraModel& cam, double scale,
                                         const std::string& frame_id, const ros::Time& stamp);


// The rig of these CameraInfos (in order; names[i] the camera's name, an empty
// list or name: "cam<index>") with each camera's pose looked up in tf2:
// lookupTransform(base_frame, info.header.frame_id, stamp, timeout_s) -
// ros::Time(0) for the latest, as for a static mount - then
// rigFromCameraInfos. Throws tf2::TransformException naming the camera and
// the missing transform ("rig from CameraInfos: cam1: no transform from
// 'cam1_optical' to 'base_link': ..."), std::invalid_argument when names and
// infos differ in length, and rigFromCameraInfos' CalibrationErrors.
Rig rigFromCameraInfosAndTf(const std::vector<sensor_msgs::CameraInfo>& infos, const std::vector<std::string>& names,
                            const tf2_ros::Buffer& tf, const std::string& base_frame, const ros::Time& stamp,
                            double timeout_s);

// Whether two CameraInfos describe the same camera: all but header.stamp and
// header.seq equal (a rig built from `a` holds for `b`).
bool sameCalibration(const sensor_msgs::CameraInfo& a, const sensor_msgs::CameraInfo& b);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_CAMERA_INFO_H_
