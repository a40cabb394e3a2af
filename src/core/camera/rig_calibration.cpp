#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/common/safe_open.h"
#include "fisheye_mapping/core/common/safe_write.h"

namespace fisheye_mapping {
namespace {

[[noreturn]] void fail(const std::string& file, const std::string& field, const std::string& what) {
  throw CalibrationError(file + ": " + (field.empty() ? "" : field + ": ") + what);
}

// The whole text of a calibration file: a regular file (a FIFO or a device is
// refused at once, without blocking: common/safe_open.h) of at most
// kMaxCalibrationFileBytes (calibration files are a few kilobytes; anything
// larger is not one and would only cost memory to parse).
std::string readCalibrationFile(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) fail(path, "", "cannot open file");
  if (fs::is_directory(st)) fail(path, "", "is a directory, expected a calibration file");
  std::uint64_t size = 0;
  const std::string why = regularFileProblem(path, kMaxCalibrationFileBytes, &size);
  if (size > kMaxCalibrationFileBytes)
    fail(path, "", "too large for a calibration file (more than " + std::to_string(kMaxCalibrationFileBytes) + " bytes)");
  if (!why.empty()) fail(path, "", why + ", expected a calibration file");
  try {
    return readRegularFile(path, kMaxCalibrationFileBytes, "");
  } catch (const std::runtime_error& e) {
    throw CalibrationError(e.what());
  }
}

YAML::Node parseYaml(const std::string& text, const std::string& name) {
  if (text.size() > kMaxCalibrationFileBytes) fail(name, "", "too large for a calibration file");
  try {
    return YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    fail(name, "", std::string("YAML syntax error: ") + e.what());
  } catch (const std::exception& e) {  // e.g. yaml-cpp's depth limit
    fail(name, "", std::string("cannot parse YAML: ") + e.what());
  }
}

// Every reader takes (file, field) to name the culprit in its error.
std::string readString(const YAML::Node& node, const std::string& file, const std::string& field) {
  if (!node) fail(file, field, "missing");
  if (!node.IsScalar()) fail(file, field, "expected a string");
  return node.as<std::string>();
}

double readDouble(const YAML::Node& node, const std::string& file, const std::string& field) {
  if (!node) fail(file, field, "missing");
  double value = 0.0;
  try {
    if (!node.IsScalar()) throw YAML::BadConversion(node.Mark());
    value = node.as<double>();
  } catch (const YAML::BadConversion&) {
    fail(file, field, "expected a number, got '" + (node.IsScalar() ? node.Scalar() : "non-scalar") +
                          "'");
  }
  if (!std::isfinite(value)) fail(file, field, "must be finite");
  return value;
}

std::vector<double> readDoubles(const YAML::Node& node, const std::string& file,
                                const std::string& field, size_t expected,
                                const std::string& why = "") {
  if (!node) fail(file, field, "missing");
  if (!node.IsSequence()) fail(file, field, "expected a list of numbers");
  if (node.size() != expected) {
    std::ostringstream msg;
    msg << "expected " << expected << " values" << why << ", got " << node.size();
    fail(file, field, msg.str());
  }
  std::vector<double> out;
  for (size_t i = 0; i < node.size(); ++i) {
    out.push_back(readDouble(node[i], file, field + "[" + std::to_string(i) + "]"));
  }
  return out;
}

Eigen::Isometry3d readTransform(const YAML::Node& node, const std::string& file,
                                const std::string& field) {
  if (!node) fail(file, field, "missing");
  if (!node.IsSequence() || node.size() != 4) fail(file, field, "expected a 4x4 matrix (4 rows)");
  Eigen::Matrix4d T;
  for (int r = 0; r < 4; ++r) {
    const auto row =
        readDoubles(node[r], file, field + "[" + std::to_string(r) + "]", 4, " in a matrix row");
    for (int c = 0; c < 4; ++c) T(r, c) = row[c];
  }
  checkRigidTransform(T, file + ": " + field);
  Eigen::Isometry3d iso = Eigen::Isometry3d::Identity();
  // Re-orthonormalize what passed the tolerance check so composition stays rigid.
  iso.linear() = Eigen::Quaterniond(Eigen::Matrix3d(T.topLeftCorner<3, 3>())).normalized()
                     .toRotationMatrix();
  iso.translation() = T.topRightCorner<3, 1>();
  if (iso.translation().cwiseAbs().maxCoeff() > kMaxRigTranslation) {
    std::ostringstream msg;
    msg << "translation must lie within " << kMaxRigTranslation << " m, got [" << iso.translation().transpose()
        << "]";
    fail(file, field, msg.str());
  }
  return iso;
}

CameraModel readCamera(const YAML::Node& cam, const std::string& file, const std::string& name) {
  const std::string model = readString(cam["camera_model"], file, name + ".camera_model");
  const std::string dist = readString(cam["distortion_model"], file, name + ".distortion_model");
  const auto res = readDoubles(cam["resolution"], file, name + ".resolution", 2, " (width, height)");
  Intrinsics in;
  if (res[0] != std::floor(res[0]) || res[1] != std::floor(res[1])) {
    fail(file, name + ".resolution", "must be whole numbers of pixels");
  }
  {
    std::ostringstream size;
    size << res[0] << "x" << res[1];
    if (res[0] < 1 || res[1] < 1) fail(file, name + ".resolution", "resolution must be positive, got " + size.str());
    if (res[0] > kMaxImageSide || res[1] > kMaxImageSide) {
      fail(file, name + ".resolution", "resolution must be at most " + std::to_string(kMaxImageSide) + "x" +
                                           std::to_string(kMaxImageSide) + " pixels, got " + size.str());
    }
  }
  in.width = static_cast<int>(res[0]);
  in.height = static_cast<int>(res[1]);

  size_t n_dist = 0;
  if (dist == "radtan" || dist == "equidistant") {
    n_dist = 4;
  } else if (dist != "none") {
    fail(file, name + ".distortion_model",
         "unknown distortion model '" + dist + "' (expected radtan, equidistant or none)");
  }
  std::vector<double> d(4, 0.0);
  if (n_dist > 0 || cam["distortion_coeffs"]) {
    const auto coeffs = readDoubles(cam["distortion_coeffs"], file, name + ".distortion_coeffs",
                                    n_dist, " for distortion_model '" + dist + "'");
    std::copy(coeffs.begin(), coeffs.end(), d.begin());
  }

  const std::string intr_field = name + ".intrinsics";
  auto intrinsics = [&](size_t n) {
    return readDoubles(cam["intrinsics"], file, intr_field, n,
                       " for camera_model '" + model + "'");
  };
  try {
    if (model == "omni") {
      const auto k = intrinsics(5);  // xi fu fv pu pv
      in.fx = k[1], in.fy = k[2], in.cx = k[3], in.cy = k[4];
      if (dist == "equidistant") fail(file, name + ".distortion_model", "omni supports radtan or none");
      return CameraModel::unified(in, k[0], d[0], d[1], d[2], d[3]);
    }
    if (model == "ds") {
      const auto k = intrinsics(6);  // xi alpha fu fv pu pv
      in.fx = k[2], in.fy = k[3], in.cx = k[4], in.cy = k[5];
      if (dist != "none") fail(file, name + ".distortion_model", "ds supports only 'none'");
      return CameraModel::doubleSphere(in, k[0], k[1]);
    }
    if (model == "pinhole") {
      const auto k = intrinsics(4);  // fu fv pu pv
      in.fx = k[0], in.fy = k[1], in.cx = k[2], in.cy = k[3];
      if (dist == "equidistant") return CameraModel::kannalaBrandt(in, d[0], d[1], d[2], d[3]);
      return CameraModel::pinhole(in, d[0], d[1], d[2], d[3]);
    }
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    std::string field = intr_field;
    if (what.rfind("resolution", 0) == 0) field = name + ".resolution";
    for (const char* k : {"k1 ", "k2 ", "k3 ", "k4 ", "p1 ", "p2 "}) {
      if (what.rfind(k, 0) == 0) field = name + ".distortion_coeffs";
    }
    fail(file, field, what);
  }
  fail(file, name + ".camera_model",
       "unknown camera model '" + model + "' (expected omni, ds or pinhole)");
}

void writeMatrix(YAML::Emitter& out, const Eigen::Isometry3d& T) {
  out << YAML::BeginSeq;
  const Eigen::Matrix4d M = T.matrix();
  for (int r = 0; r < 4; ++r) {
    out << YAML::Flow << YAML::BeginSeq;
    for (int c = 0; c < 4; ++c) out << M(r, c);
    out << YAML::EndSeq;
  }
  out << YAML::EndSeq;
}

}  // namespace

int Rig::indexOf(const std::string& name) const {
  for (size_t i = 0; i < cameras.size(); ++i) {
    if (cameras[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

const RigCamera& Rig::camera(const std::string& name) const {
  const int i = indexOf(name);
  if (i < 0) {
    std::string known;
    for (const auto& c : cameras) known += (known.empty() ? "" : ", ") + c.name;
    throw CalibrationError("unknown camera '" + name + "' (the rig has: " + known + ")");
  }
  return cameras[i];
}

void checkRigidTransform(const Eigen::Matrix4d& T, const std::string& where) {
  if (!T.allFinite()) throw CalibrationError(where + ": transform has non-finite entries");
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const double ortho_err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (ortho_err > 1e-5) {
    std::ostringstream msg;
    msg << where << ": rotation is not orthonormal (max |R^T R - I| = " << ortho_err << ")";
    throw CalibrationError(msg.str());
  }
  if (R.determinant() < 0.0) throw CalibrationError(where + ": rotation has determinant -1 (a reflection)");
  const Eigen::RowVector4d last = T.row(3);
  if ((last - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-9) {
    throw CalibrationError(where + ": last row must be [0, 0, 0, 1]");
  }
}

namespace {

// "camN" with N a camera index without leading zeros: N, or -1 when `key` is
// not a camera key at all. Throws for an index beyond the rig's limit.
int cameraIndex(const std::string& key, const std::string& file) {
  if (key.size() < 4 || key.compare(0, 3, "cam") != 0) return -1;
  const std::string digits = key.substr(3);
  if (digits.find_first_not_of("0123456789") != std::string::npos) return -1;
  if (digits.size() > 1 && digits[0] == '0') {
    fail(file, key, "camera keys are cam0, cam1, ... without leading zeros");
  }
  if (digits.size() > 4 || std::stoi(digits) >= kMaxRigCameras) {
    fail(file, key, "camera index out of range: a rig has at most " + std::to_string(kMaxRigCameras) +
                        " cameras (cam0 ... cam" + std::to_string(kMaxRigCameras - 1) + ")");
  }
  return std::stoi(digits);
}

// The text of a map key, or a CalibrationError for keys that are not scalars.
std::string keyText(const YAML::Node& key, const std::string& file, const std::string& where) {
  if (!key.IsScalar()) fail(file, where, "keys must be plain names, got a " + std::string(key.IsMap() ? "map" : "list"));
  return key.Scalar();
}

Rig parseKalibrRig(const YAML::Node& chain, const YAML::Node& mount, const std::string& camchain_path,
                   const std::string& mount_path) {
  if (!chain.IsMap()) fail(camchain_path, "", "expected a map of cameras (cam0, cam1, ...)");
  if (!mount.IsMap()) fail(mount_path, "", "expected a map with T_base_cam0");

  std::map<int, YAML::Node> by_index;
  for (const auto& kv : chain) {
    const int index = cameraIndex(keyText(kv.first, camchain_path, "(top level)"), camchain_path);
    if (index < 0) continue;
    if (by_index.count(index)) fail(camchain_path, "cam" + std::to_string(index), "appears twice");
    by_index[index] = kv.second;
  }
  if (by_index.empty()) fail(camchain_path, "cam0", "missing (no camera in the camchain)");
  int expected = 0;
  for (const auto& kv : by_index) {
    if (kv.first != expected) fail(camchain_path, "cam" + std::to_string(expected), "missing");
    ++expected;
  }

  Rig rig;
  if (mount["base_frame"]) rig.base_frame = readString(mount["base_frame"], mount_path, "base_frame");
  if (rig.base_frame.empty()) fail(mount_path, "base_frame", "must not be empty");
  const Eigen::Isometry3d T_base_cam0 = readTransform(mount["T_base_cam0"], mount_path, "T_base_cam0");
  const YAML::Node frame_ids = mount["frame_ids"];
  if (frame_ids && !frame_ids.IsMap()) fail(mount_path, "frame_ids", "expected a map camN: frame");
  std::map<std::string, std::string> frame_of;  // camera name -> frame id given in the mount
  if (frame_ids) {
    for (const auto& kv : frame_ids) {
      const std::string key = keyText(kv.first, mount_path, "frame_ids");
      if (frame_of.count(key)) fail(mount_path, "frame_ids." + key, "appears twice");
      frame_of[key] = readString(kv.second, mount_path, "frame_ids." + key);
    }
  }

  Eigen::Isometry3d T_cn_c0 = Eigen::Isometry3d::Identity();
  std::map<std::string, std::string> camera_of_frame;
  for (const auto& kv : by_index) {
    const std::string name = "cam" + std::to_string(kv.first);
    const YAML::Node& node = kv.second;
    if (!node.IsMap()) fail(camchain_path, name, "expected a map");
    RigCamera cam;
    cam.name = name;
    cam.model = readCamera(node, camchain_path, name);
    if (node["rostopic"]) cam.rostopic = readString(node["rostopic"], camchain_path, name + ".rostopic");
    if (kv.first > 0) {
      T_cn_c0 = readTransform(node["T_cn_cnm1"], camchain_path, name + ".T_cn_cnm1") * T_cn_c0;
    }
    cam.T_cam0_cam = T_cn_c0.inverse();
    cam.T_base_cam = T_base_cam0 * cam.T_cam0_cam;
    if (!cam.T_base_cam.matrix().allFinite()) fail(camchain_path, name, "the chained transforms overflow");
    cam.frame_id = name;
    const auto given = frame_of.find(name);
    if (given != frame_of.end()) cam.frame_id = given->second;
    const std::string field = given != frame_of.end() ? "frame_ids." + name : "(frame of " + name + ")";
    if (cam.frame_id.empty()) fail(mount_path, field, "must not be empty");
    if (cam.frame_id == rig.base_frame) {
      fail(mount_path, field, "frame '" + cam.frame_id + "' is the base frame; each camera needs its own frame");
    }
    const auto taken = camera_of_frame.find(cam.frame_id);
    if (taken != camera_of_frame.end()) {
      fail(mount_path, field, "frame '" + cam.frame_id + "' is also " + taken->second +
                                  "'s; each camera needs its own tf frame");
    }
    camera_of_frame[cam.frame_id] = name;
    rig.cameras.push_back(cam);
  }
  for (const auto& kv : frame_of) {
    if (rig.indexOf(kv.first) < 0) fail(mount_path, "frame_ids." + kv.first, "no such camera in the camchain");
  }
  return rig;
}

// Runs `parse`, turning any yaml-cpp error that escaped the readers (a node of
// an unexpected kind deep in the file) into a CalibrationError naming `file`.
template <typename F>
auto namingFile(const std::string& file, F parse) -> decltype(parse()) {
  try {
    return parse();
  } catch (const CalibrationError&) {
    throw;
  } catch (const YAML::Exception& e) {
    fail(file, "", std::string("malformed calibration: ") + e.what());
  }
}

}  // namespace

Rig loadKalibrRig(const std::string& camchain_path, const std::string& mount_path) {
  const std::string chain_text = readCalibrationFile(camchain_path);
  const std::string mount_text = readCalibrationFile(mount_path);
  return loadKalibrRigFromStrings(chain_text, mount_text, camchain_path, mount_path);
}

Rig loadKalibrRigFromStrings(const std::string& camchain_yaml, const std::string& mount_yaml,
                             const std::string& camchain_name, const std::string& mount_name) {
  const YAML::Node chain = parseYaml(camchain_yaml, camchain_name);
  const YAML::Node mount = parseYaml(mount_yaml, mount_name);
  return namingFile(camchain_name + " / " + mount_name,
                    [&] { return parseKalibrRig(chain, mount, camchain_name, mount_name); });
}

Rig loadPslCalibration(const std::string& calib_path, int width, int height,
                       const std::string& camera_name) {
  return loadPslCalibrationFromString(readCalibrationFile(calib_path), calib_path, width, height, camera_name);
}

Rig loadPslCalibrationFromString(const std::string& text, const std::string& calib_path, int width, int height,
                                 const std::string& camera_name) {
  if (text.size() > kMaxCalibrationFileBytes) fail(calib_path, "", "too large for a calibration file");
  std::istringstream f(text);
  std::vector<std::vector<double>> lines;
  std::string line;
  int line_no = 0;
  while (std::getline(f, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (lines.size() == 4) {
      fail(calib_path, "line " + std::to_string(line_no),
           "expected 4 non-empty lines (intrinsics, then a 3x4 [R | C]), got more");
    }
    std::istringstream ss(line);
    std::vector<double> values;
    std::string tok;
    while (ss >> tok) {
      char* end = nullptr;
      const double v = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0' || !std::isfinite(v)) {
        fail(calib_path, "line " + std::to_string(line_no), "not a number: '" + tok.substr(0, 40) +
                                                                 (tok.size() > 40 ? "...'" : "'"));
      }
      if (values.size() == 10) {
        fail(calib_path, "line " + std::to_string(line_no), "too many values (at most 10 on a line)");
      }
      values.push_back(v);
    }
    lines.push_back(values);
  }
  if (lines.size() != 4) {
    fail(calib_path, "", "expected 4 non-empty lines (intrinsics, then a 3x4 [R | C]), got " +
                             std::to_string(lines.size()));
  }
  if (lines[0].size() != 10) {
    fail(calib_path, "intrinsics (fx skew cx fy cy xi k1 k2 p1 p2)",
         "expected 10 values, got " + std::to_string(lines[0].size()));
  }
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 3; ++r) {
    if (lines[r + 1].size() != 4) {
      fail(calib_path, "[R | C] row " + std::to_string(r),
           "expected 4 values, got " + std::to_string(lines[r + 1].size()));
    }
    for (int c = 0; c < 4; ++c) T(r, c) = lines[r + 1][c];
  }
  checkRigidTransform(T, calib_path + ": [R | C]");
  const auto& k = lines[0];
  Intrinsics in;
  in.width = width;
  in.height = height;
  in.fx = k[0], in.skew = k[1], in.cx = k[2], in.fy = k[3], in.cy = k[4];
  RigCamera cam;
  cam.name = camera_name;
  cam.frame_id = camera_name;
  try {
    cam.model = CameraModel::unified(in, k[5], k[6], k[7], k[8], k[9]);
  } catch (const std::invalid_argument& e) {
    fail(calib_path, "intrinsics", e.what());
  }
  cam.T_base_cam.linear() =
      Eigen::Quaterniond(Eigen::Matrix3d(T.topLeftCorner<3, 3>())).normalized().toRotationMatrix();
  cam.T_base_cam.translation() = T.topRightCorner<3, 1>();
  Rig rig;
  rig.base_frame = "system";
  rig.cameras.push_back(cam);
  return rig;
}

KalibrRigText kalibrRigText(const Rig& rig) {
  if (rig.cameras.empty()) throw CalibrationError("writeKalibrRig: the rig has no camera");
  YAML::Emitter chain;
  chain.SetDoublePrecision(17);
  chain << YAML::BeginMap;
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    const RigCamera& cam = rig.cameras[i];
    const FmCameraT<double>& p = cam.model.params();
    chain << YAML::Key << "cam" + std::to_string(i) << YAML::Value << YAML::BeginMap;
    std::vector<double> intr, dist;
    std::string model, dist_model;
    switch (cam.model.type()) {
      case CameraModelType::kUnified:
        model = "omni", dist_model = "radtan";
        intr = {p.xi, p.fx, p.fy, p.cx, p.cy};
        dist = {p.k1, p.k2, p.p1, p.p2};
        break;
      case CameraModelType::kDoubleSphere:
        model = "ds", dist_model = "none";
        intr = {p.xi, p.alpha, p.fx, p.fy, p.cx, p.cy};
        break;
      case CameraModelType::kPinhole:
        model = "pinhole", dist_model = "radtan";
        intr = {p.fx, p.fy, p.cx, p.cy};
        dist = {p.k1, p.k2, p.p1, p.p2};
        break;
      case CameraModelType::kKannalaBrandt:
        model = "pinhole", dist_model = "equidistant";
        intr = {p.fx, p.fy, p.cx, p.cy};
        dist = {p.k1, p.k2, p.k3, p.k4};
        break;
    }
    if (p.skew != 0.0) throw CalibrationError("writeKalibrRig: " + cam.name + " has skew, which Kalibr cannot store");
    chain << YAML::Key << "camera_model" << YAML::Value << model;
    chain << YAML::Key << "intrinsics" << YAML::Value << YAML::Flow << intr;
    chain << YAML::Key << "distortion_model" << YAML::Value << dist_model;
    chain << YAML::Key << "distortion_coeffs" << YAML::Value << YAML::Flow << dist;
    chain << YAML::Key << "resolution" << YAML::Value << YAML::Flow
          << std::vector<int>{p.width, p.height};
    chain << YAML::Key << "rostopic" << YAML::Value << cam.rostopic;
    if (i > 0) {
      const Eigen::Isometry3d T_cn_cnm1 =
          cam.T_cam0_cam.inverse() * rig.cameras[i - 1].T_cam0_cam;
      chain << YAML::Key << "T_cn_cnm1" << YAML::Value;
      writeMatrix(chain, T_cn_cnm1);
    }
    chain << YAML::EndMap;
  }
  chain << YAML::EndMap;

  YAML::Emitter mount;
  mount.SetDoublePrecision(17);
  mount << YAML::BeginMap;
  mount << YAML::Key << "base_frame" << YAML::Value << rig.base_frame;
  mount << YAML::Key << "T_base_cam0" << YAML::Value;
  writeMatrix(mount, rig.cameras[0].T_base_cam * rig.cameras[0].T_cam0_cam.inverse());
  mount << YAML::Key << "frame_ids" << YAML::Value << YAML::BeginMap;
  for (const auto& cam : rig.cameras) mount << YAML::Key << cam.name << YAML::Value << cam.frame_id;
  mount << YAML::EndMap << YAML::EndMap;

  return {std::string(chain.c_str()) + "\n", std::string(mount.c_str()) + "\n"};
}

void writeKalibrRig(const Rig& rig, const std::string& camchain_path, const std::string& mount_path) {
  const KalibrRigText text = kalibrRigText(rig);
  writeFileSafely(camchain_path, text.camchain);
  writeFileSafely(mount_path, text.mount);
}

void checkImageSize(const RigCamera& camera, int width, int height) {
  if (width != camera.model.width() || height != camera.model.height()) {
    std::ostringstream msg;
    msg << camera.name << ".resolution: image is " << width << "x" << height
        << " but the calibration says " << camera.model.width() << "x" << camera.model.height();
    throw CalibrationError(msg.str());
  }
}

}  // namespace fisheye_mapping
