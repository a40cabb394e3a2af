// A multi-camera rig on a vehicle: camera models plus extrinsics, loaded from a
// Kalibr camchain and our mount YAML, or from PlaneSweepLib's calib.txt.
//
// Frames (REP 103 / 105): base_link has x forward, y left, z up and its origin
// on the ground plane, so the ground is z = 0 in base_link. Camera frames are
// optical frames (x right, y down, z forward). T_A_B maps points from frame B to
// frame A: p_A = T_A_B * p_B.
#ifndef FISHEYE_MAPPING_CORE_CAMERA_RIG_H_
#define FISHEYE_MAPPING_CORE_CAMERA_RIG_H_

#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "fisheye_mapping/core/camera/camera_model.h"

namespace fisheye_mapping {

// Thrown for any problem with a calibration file. what() names the file and the
// field, e.g. "rig.yaml: cam2.intrinsics: expected 5 values for camera_model
// 'omni', got 4".
class CalibrationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// At most this many cameras in a rig (keys cam0 ... cam63).
constexpr int kMaxRigCameras = 64;
// Camera positions (T_base_cam0, T_cn_cnm1 translations) within this many metres.
constexpr double kMaxRigTranslation = 1e4;

struct RigCamera {
  std::string name;      // "cam0", "cam1", ... as in the camchain
  std::string frame_id;  // tf frame of the camera (optical frame)
  std::string rostopic;  // image topic recorded in the camchain (may be empty)
  CameraModel model;
  Eigen::Isometry3d T_cam0_cam = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_base_cam = Eigen::Isometry3d::Identity();
};

struct Rig {
  std::string base_frame = "base_link";
  std::vector<RigCamera> cameras;

  // Index of the camera called `name`, or -1.
  int indexOf(const std::string& name) const;
  // Like indexOf, but throws CalibrationError listing the known names.
  const RigCamera& camera(const std::string& name) const;
};

// Reads a Kalibr camchain YAML (camera_model omni / ds / pinhole; distortion
// radtan / equidistant / none) and our mount YAML:
//   base_frame: base_link            # optional, default base_link
//   T_base_cam0: 4x4 row-major list  # required
//   frame_ids: {cam0: cam0, ...}     # optional, default: the camera name
// Throws CalibrationError naming the file and field on any problem: a missing
// file or a directory, a file over 1 MiB, YAML syntax, keys camN out of range
// (at most kMaxRigCameras) or given twice, gaps in the chain, intrinsics out of
// the camera model's limits (camera_model.h: resolution, focal length, ...),
// non-rigid transforms, frame ids empty, equal to the base frame or shared by
// two cameras.
Rig loadKalibrRig(const std::string& camchain_path, const std::string& mount_path);
// The same from the files' texts; the names stand for the files in errors.
Rig loadKalibrRigFromStrings(const std::string& camchain_yaml, const std::string& mount_yaml,
                             const std::string& camchain_name = "camchain.yaml",
                             const std::string& mount_name = "mount.yaml");

// Reads PlaneSweepLib's calib.txt: line 1 "fx skew cx fy cy xi k1 k2 p1 p2"
// (unified model, radtan), then three lines of the 3x4 camera-to-system
// transform [R | C]. The system frame becomes the rig's base frame. The image
// size is not in the file and must be given.
Rig loadPslCalibration(const std::string& calib_path, int width, int height,
                       const std::string& camera_name = "cam0");
// The same from the file's text; `calib_name` stands for the file in errors.
Rig loadPslCalibrationFromString(const std::string& text, const std::string& calib_name, int width,
                                 int height, const std::string& camera_name = "cam0");

// A rig as the text of a Kalibr camchain plus mount YAML that loadKalibrRig
// reads back.
struct KalibrRigText {
  std::string camchain, mount;
};
KalibrRigText kalibrRigText(const Rig& rig);
// The same written to the two files (writeFileSafely: each complete or not at
// all, no link followed; used by the synthetic-drive generator). Throws
// std::runtime_error naming the file and the OS error.
void writeKalibrRig(const Rig& rig, const std::string& camchain_path,
                    const std::string& mount_path);

// Throws CalibrationError when an image of width x height does not match the
// camera's calibrated resolution.
void checkImageSize(const RigCamera& camera, int width, int height);

// Throws CalibrationError (message prefixed by `where`) unless `T` is a rigid
// transform: orthonormal rotation with determinant +1, finite translation.
void checkRigidTransform(const Eigen::Matrix4d& T, const std::string& where);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_CAMERA_RIG_H_
