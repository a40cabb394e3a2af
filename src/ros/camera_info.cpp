#include "fisheye_mapping/ros/camera_info.h"

#include <cmath>
#include <map>
#include <sstream>
#include <stdexcept>

#include <sensor_msgs/distortion_models.h>
#include <tf2_eigen/tf2_eigen.h>

namespace fisheye_mapping {
namespace {

// Ours: the Kalibr camera model names (see the header).
const char* const kOmni = "omni";
const char* const kDoubleSphere = "double_sphere";

std::string joined(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

// Every error of a CameraInfo names it by its frame id, then the field.
[[noreturn]] void fail(const sensor_msgs::CameraInfo& msg, const std::string& field,
                       const std::string& what) {
  throw CalibrationError("CameraInfo '" + msg.header.frame_id + "': " + field + ": " + what);
}

std::string str(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

// The D layout of each accepted model: coefficient names, in order.
const std::map<std::string, std::vector<std::string>>& distortionLayouts() {
  static const std::map<std::string, std::vector<std::string>> layouts = {
      {sensor_msgs::distortion_models::PLUMB_BOB, {"k1", "k2", "p1", "p2", "k3"}},
      {sensor_msgs::distortion_models::RATIONAL_POLYNOMIAL,
       {"k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"}},
      {sensor_msgs::distortion_models::EQUIDISTANT, {"k1", "k2", "k3", "k4"}},
      {kOmni, {"xi", "k1", "k2", "p1", "p2"}},
      {kDoubleSphere, {"xi", "alpha"}},
  };
  return layouts;
}

// D, checked: the model's length, finite, and zero from index `first_zero`
// on (coefficients of the standard layout that our model does not have).
std::vector<double> checkedD(const sensor_msgs::CameraInfo& msg, size_t first_zero) {
  const std::vector<std::string>& names = distortionLayouts().at(msg.distortion_model);
  if (msg.D.size() != names.size()) {
    fail(msg, "D", "expected " + std::to_string(names.size()) + " values for distortion_model '" +
                       msg.distortion_model + "' (" + joined(names) + "), got " +
                       std::to_string(msg.D.size()));
  }
  for (size_t i = 0; i < msg.D.size(); ++i) {
    const std::string field = "D[" + std::to_string(i) + "] (" + names[i] + ")";
    if (!std::isfinite(msg.D[i])) fail(msg, field, "must be finite, got " + str(msg.D[i]));
    if (i >= first_zero && msg.D[i] != 0.0) {
      fail(msg, field, "must be 0 (the camera model has no " + names[i] + "), got " + str(msg.D[i]));
    }
  }
  return msg.D;
}

// Size and K, checked: K = [fx skew cx; 0 fy cy; 0 0 1] with fx, fy > 0.
Intrinsics checkedIntrinsics(const sensor_msgs::CameraInfo& msg) {
  if (msg.width == 0) fail(msg, "width", "must be positive, got 0");
  if (msg.height == 0) fail(msg, "height", "must be positive, got 0");
  if (msg.width > static_cast<uint32_t>(kMaxImageSide) || msg.height > static_cast<uint32_t>(kMaxImageSide)) {
    fail(msg, "width x height", "must be at most " + std::to_string(kMaxImageSide) + " pixels a side, got " +
                                    std::to_string(msg.width) + "x" + std::to_string(msg.height));
  }
  const auto& K = msg.K;
  for (size_t i = 0; i < K.size(); ++i) {
    if (!std::isfinite(K[i])) fail(msg, "K[" + std::to_string(i) + "]", "must be finite, got " + str(K[i]));
  }
  if (!(K[0] > 0.0)) fail(msg, "K[0] (fx)", "must be positive, got " + str(K[0]) +
                                                (K[0] == 0.0 ? " (an uncalibrated camera?)" : ""));
  if (!(K[4] > 0.0)) fail(msg, "K[4] (fy)", "must be positive, got " + str(K[4]));
  if (K[3] != 0.0 || K[6] != 0.0 || K[7] != 0.0 || K[8] != 1.0) {
    fail(msg, "K", "must be [fx skew cx; 0 fy cy; 0 0 1], got bottom rows [" + str(K[3]) + " " + str(K[4]) +
                       " " + str(K[5]) + "; " + str(K[6]) + " " + str(K[7]) + " " + str(K[8]) + "]");
  }
  if (msg.binning_x > 1 || msg.binning_y > 1) {
    fail(msg, "binning_x/binning_y", "binning " + std::to_string(msg.binning_x) + "x" +
                                         std::to_string(msg.binning_y) +
                                         " is not supported (publish K of the image as sent, binning 0)");
  }
  const auto& roi = msg.roi;
  const bool full = (roi.width == 0 && roi.height == 0 && roi.x_offset == 0 && roi.y_offset == 0) ||
                    (roi.x_offset == 0 && roi.y_offset == 0 && roi.width == msg.width && roi.height == msg.height);
  if (!full) fail(msg, "roi", "a partial region of interest is not supported (roi must be all zero)");
  Intrinsics in;
  in.width = static_cast<int>(msg.width);
  in.height = static_cast<int>(msg.height);
  in.fx = K[0], in.skew = K[1], in.cx = K[2], in.fy = K[4], in.cy = K[5];
  return in;
}

CameraModel makeCamera(const sensor_msgs::CameraInfo& msg, const Intrinsics& in) {
  const std::string& model = msg.distortion_model;
  if (model == sensor_msgs::distortion_models::PLUMB_BOB ||
      model == sensor_msgs::distortion_models::RATIONAL_POLYNOMIAL) {
    const auto d = checkedD(msg, 4);
    return CameraModel::pinhole(in, d[0], d[1], d[2], d[3]);
  }
  if (model == sensor_msgs::distortion_models::EQUIDISTANT) {
    const auto d = checkedD(msg, 4);
    return CameraModel::kannalaBrandt(in, d[0], d[1], d[2], d[3]);
  }
  if (model == kOmni) {
    const auto d = checkedD(msg, 5);
    if (d[0] < 0.0) fail(msg, "D[0] (xi)", "must be >= 0, got " + str(d[0]));
    return CameraModel::unified(in, d[0], d[1], d[2], d[3], d[4]);
  }
  const auto d = checkedD(msg, 2);  // double sphere
  return CameraModel::doubleSphere(in, d[0], d[1]);
}

}  // namespace

const std::vector<std::string>& acceptedDistortionModels() {
  static const std::vector<std::string> names = {
      sensor_msgs::distortion_models::PLUMB_BOB, sensor_msgs::distortion_models::RATIONAL_POLYNOMIAL,
      sensor_msgs::distortion_models::EQUIDISTANT, kOmni, kDoubleSphere};
  return names;
}

sensor_msgs::CameraInfo toCameraInfo(const CameraModel& cam, const std::string& frame_id,
                                     const ros::Time& stamp) {
  const FmCameraT<double>& p = cam.params();
  sensor_msgs::CameraInfo msg;
  msg.header.frame_id = frame_id;
  msg.header.stamp = stamp;
  msg.width = static_cast<uint32_t>(p.width);
  msg.height = static_cast<uint32_t>(p.height);
  switch (cam.type()) {
    case CameraModelType::kPinhole:
      msg.distortion_model = sensor_msgs::distortion_models::PLUMB_BOB;
      msg.D = {p.k1, p.k2, p.p1, p.p2, 0.0};
      break;
    case CameraModelType::kKannalaBrandt:
      msg.distortion_model = sensor_msgs::distortion_models::EQUIDISTANT;
      msg.D = {p.k1, p.k2, p.k3, p.k4};
      break;
    case CameraModelType::kUnified:
      msg.distortion_model = kOmni;
      msg.D = {p.xi, p.k1, p.k2, p.p1, p.p2};
      break;
    case CameraModelType::kDoubleSphere:
      msg.distortion_model = kDoubleSphere;
      msg.D = {p.xi, p.alpha};
      break;
  }
  msg.K = {p.fx, p.skew, p.cx, 0.0, p.fy, p.cy, 0.0, 0.0, 1.0};
  msg.R = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  msg.P = {p.fx, p.skew, p.cx, 0.0, 0.0, p.fy, p.cy, 0.0, 0.0, 0.0, 1.0, 0.0};
  return msg;
}

sensor_msgs::CameraInfo toCameraInfo(const RigCamera& cam, const ros::Time& stamp) {
  return toCameraInfo(cam.model, cam.frame_id, stamp);
}

CameraModel fromCameraInfo(const sensor_msgs::CameraInfo& msg) {
  if (!distortionLayouts().count(msg.distortion_model)) {
    fail(msg, "distortion_model", "unknown distortion model '" + msg.distortion_model + "' (accepted: " +
                                      joined(acceptedDistortionModels()) + ")");
  }
  const Intrinsics in = checkedIntrinsics(msg);
  try {
    return makeCamera(msg, in);
  } catch (const std::invalid_argument& e) {  // the model's own limits, e.g. "alpha must be in [0, 1]"
    fail(msg, "K / D", e.what());
  }
}

Rig rigFromCameraInfos(const std::vector<CameraInfoAndPose>& cameras, const std::string& base_frame) {
  if (cameras.empty()) throw CalibrationError("rig from CameraInfos: no camera");
  if (cameras.size() > static_cast<size_t>(kMaxRigCameras)) {
    throw CalibrationError("rig from CameraInfos: " + std::to_string(cameras.size()) +
                           " cameras, at most " + std::to_string(kMaxRigCameras));
  }
  if (base_frame.empty()) throw CalibrationError("rig from CameraInfos: base frame must not be empty");
  Rig rig;
  rig.base_frame = base_frame;
  std::map<std::string, std::string> camera_of_frame;
  for (size_t i = 0; i < cameras.size(); ++i) {
    const CameraInfoAndPose& c = cameras[i];
    RigCamera cam;
    cam.name = c.name.empty() ? "cam" + std::to_string(i) : c.name;
    cam.frame_id = c.info.header.frame_id;
    const std::string where = "rig from CameraInfos: " + cam.name;
    if (rig.indexOf(cam.name) >= 0) throw CalibrationError(where + ": name given to two cameras");
    if (cam.frame_id.empty()) throw CalibrationError(where + ": header.frame_id must not be empty");
    if (cam.frame_id == base_frame) {
      throw CalibrationError(where + ": frame '" + cam.frame_id + "' is the base frame; each camera needs its own frame");
    }
    const auto taken = camera_of_frame.find(cam.frame_id);
    if (taken != camera_of_frame.end()) {
      throw CalibrationError(where + ": frame '" + cam.frame_id + "' is also " + taken->second +
                             "'s; each camera needs its own tf frame");
    }
    camera_of_frame[cam.frame_id] = cam.name;
    cam.model = fromCameraInfo(c.info);
    checkRigidTransform(c.T_base_cam.matrix(), where + ": T_base_cam (" + base_frame + " <- " + cam.frame_id + ")");
    if (c.T_base_cam.translation().cwiseAbs().maxCoeff() > kMaxRigTranslation) {
      throw CalibrationError(where + ": T_base_cam translation must lie within " + str(kMaxRigTranslation) + " m");
    }
    // Re-orthonormalized, as the camchain loader does, so compositions stay rigid.
    cam.T_base_cam.linear() = Eigen::Quaterniond(c.T_base_cam.rotation()).normalized().toRotationMatrix();
    cam.T_base_cam.translation() = c.T_base_cam.translation();
    rig.cameras.push_back(cam);
  }
  const Eigen::Isometry3d T_cam0_base = rig.cameras[0].T_base_cam.inverse();
  for (RigCamera& cam : rig.cameras) cam.T_cam0_cam = T_cam0_base * cam.T_base_cam;
  return rig;
}

sensor_msgs::CameraInfo scaledCameraInfo(const CameraModel& cam, double scale, const std::string& frame_id,
                                         const ros::Time& stamp) {
  if (!(scale > 0.0) || !std::isfinite(scale)) {
    throw std::invalid_argument("scaledCameraInfo: scale must be finite and positive, got " + str(scale));
  }
  // The depth stage's sizes: W/2 x H/2 (integer division) at scale 0.5; the
  // epsilon keeps exact products such as 1024 * 0.5 from rounding down.
  const int width = static_cast<int>(std::floor(cam.width() * scale + 1e-9));
  const int height = static_cast<int>(std::floor(cam.height() * scale + 1e-9));
  if (width < 1 || height < 1) {
    throw std::invalid_argument("scaledCameraInfo: scale " + str(scale) + " leaves no pixel of the " +
                                std::to_string(cam.width()) + "x" + std::to_string(cam.height()) + " image");
  }
  return toCameraInfo(cam.scaled(scale, width, height), frame_id, stamp);
}

Rig rigFromCameraInfosAndTf(const std::vector<sensor_msgs::CameraInfo>& infos, const std::vector<std::string>& names,
                            const tf2_ros::Buffer& tf, const std::string& base_frame, const ros::Time& stamp,
                            double timeout_s) {
  if (!names.empty() && names.size() != infos.size()) {
    throw std::invalid_argument("rig from CameraInfos: " + std::to_string(names.size()) + " camera names for " +
                                std::to_string(infos.size()) + " CameraInfos");
  }
  std::vector<CameraInfoAndPose> cameras(infos.size());
  for (size_t i = 0; i < infos.size(); ++i) {
    CameraInfoAndPose& c = cameras[i];
    c.info = infos[i];
    if (!names.empty()) c.name = names[i];
    const std::string& frame = c.info.header.frame_id;
    try {
      c.T_base_cam = tf2::transformToEigen(tf.lookupTransform(base_frame, frame, stamp, ros::Duration(timeout_s)));
    } catch (const tf2::TransformException& e) {
      throw tf2::TransformException("rig from CameraInfos: " + (c.name.empty() ? "cam" + std::to_string(i) : c.name) +
                                    ": no transform from '" + frame + "' to '" + base_frame + "': " + e.what());
    }
  }
  return rigFromCameraInfos(cameras, base_frame);
}

bool sameCalibration(const sensor_msgs::CameraInfo& a, const sensor_msgs::CameraInfo& b) {
  sensor_msgs::CameraInfo a0 = a, b0 = b;
  a0.header.stamp = b0.header.stamp = ros::Time();
  a0.header.seq = b0.header.seq = 0;
  return a0 == b0;
}

}  // namespace fisheye_mapping
