// make_drive: renders a deterministic synthetic drive of a fisheye rig and
// writes it as a rosbag with exact ground truth.
//
//   make_drive --out DIR --camchain C --mount M [options]
//
// Writes DIR/drive.bag, DIR/camchain.yaml + DIR/mount.yaml (the rig, as read
// back by the calibration loader), DIR/static_scene.ply (the static world) and
// DIR/world.yaml (the WorldConfig and duration: what occupancy_eval rebuilds
// the world's ground truth from).
// Options make a drive as hard as a real rig's (calibration error, camera
// response differences, noise, blur, fine texture): see the usage text.
// Bag topics: /camN/image_raw (mono8), /camN/depth_gt (32FC1 range along the
// ray, NaN for sky; reference camera only unless --gt-depth all),
// /camN/detections_gt (fisheye_mapping/Detection2DArray: the visible extent
// of each moving vehicle, COCO class car / truck / bus; reference camera only
// unless --gt-boxes all), /camN/vehicles_gt (the same for every vehicle,
// parked ones too), /tf (map -> base_link at 100 Hz), /tf_static (base_link
// -> camera frames, from camchain.yaml). --dataset DIR also writes a YOLO
// training set (images/, labels/, classes.txt, boxes.csv, README.txt).
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <random>
#include <sstream>
#include <string>

#include <geometry_msgs/TransformStamped.h>
#include <opencv2/imgcodecs.hpp>
#include <rosbag/bag.h>
#include <tf2_msgs/TFMessage.h>

#include "cli.h"
#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/camera/rig_refinement.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"
#include "fisheye_mapping/core/sim/vehicle_labels.h"
#include "fisheye_mapping/ros/conversions.h"

namespace fm = fisheye_mapping;

namespace {

const char* kUsage =
    "usage: make_drive --out DIR --camchain FILE --mount FILE [options]\n"
    "  --preset urban|forest|flat  world (default urban)\n"
    "  --seed N                    random seed (default 1): same seed, same bag\n"
    "  --duration S                seconds of drive, at most 3600 (default 20)\n"
    "  --rate HZ                   camera rate, at most 100 (default 10); duration x rate:\n"
    "                              1 to 36000 frame sets\n"
    "  --speed M_PER_S             ego speed, at most 60 (default 8); speed x duration at\n"
    "                              most 50 km\n"
    "  --moving N                  moving vehicles, 0 to 100 (default 6)\n"
    "  --jitter-ms MS              per-camera stamp jitter, uniform +-MS (default 0)\n"
    "  --drop P                    probability of dropping a camera image (default 0)\n"
    "  --pose-noise M              std. dev. of GNSS/INS position noise in metres (default 0)\n"
    "  --gt-depth ref|all|none     ground-truth depth topics (default ref)\n"
    "  --gt-boxes ref|all          ground-truth boxes (/camN/detections_gt: moving vehicles,\n"
    "                              /camN/vehicles_gt: all) for cam0 or every camera (default ref)\n"
    "Training set:\n"
    "  --dataset DIR               also write every camera's image and YOLO labels of every\n"
    "                              K-th frame set to DIR (images/, labels/, classes.txt:\n"
    "                              car van truck bus; boxes.csv; README.txt)\n"
    "  --dataset-every K           frame sets between dataset frames, 1 to 1000 (default 10)\n"
    "  --dataset-min-px N          smallest visible box side to label, 1 to 100 (default 4)\n"
    "Real rigs (all off by default: an exact drive):\n"
    "  --calib-rot-deg S           calibration error: rotation of each supporting camera,\n"
    "                              normal per axis with std. dev. S degrees\n"
    "  --calib-trans-mm S          ... and translation, std. dev. S mm\n"
    "  --gain-spread F             per-camera gain uniform in 1 +- F\n"
    "  --offset-spread DN          per-camera black level uniform in +- DN\n"
    "  --gamma-spread F            per-camera gamma uniform in 1 +- F\n"
    "  --vignetting V              brightness falls by V at 90 deg off axis (default 0.3)\n"
    "  --read-noise DN             read noise std. dev. (default 1.5)\n"
    "  --shot-noise K              shot noise: variance K per DN of signal (default 0)\n"
    "  --blur PX                   optical blur, Gaussian sigma in pixels (default 0)\n"
    "  --asphalt-grain A           pixel-scale grain of the asphalt, albedo amplitude (default 0)\n"
    "  --clouds A                  low-contrast clouds, intensity amplitude (default 0)\n"
    "  --cloudy-sky                an overcast sky as contrasted as a real one: detailed\n"
    "                              clouds with soft edges, amplitude 0.3 (--clouds after it\n"
    "                              sets another)\n"
    "  --knock CAM:DEG@S           camera CAM (a supporting camera's index) is knocked at S\n"
    "                              seconds of drive: its true rotation turns by DEG degrees\n"
    "                              (about the axis (1, 1, 0)/sqrt 2 of its frame); the\n"
    "                              calibration given stays; DIR/camchain_knocked.yaml is the\n"
    "                              truth after the knock\n"
    "  --realistic                 all of the above as on a real rig: --calib-rot-deg 0.3\n"
    "                              --calib-trans-mm 5 --gain-spread 0.2 --offset-spread 4\n"
    "                              --gamma-spread 0.1 --vignetting 0.45 --read-noise 2\n"
    "                              --shot-noise 0.03 --blur 0.7 --asphalt-grain 0.08 --clouds 0.06\n"
    "                              (flags after it override single values)\n"
    "With a calibration error, DIR/camchain.yaml is the perturbed calibration (what\n"
    "the pipeline is given), DIR/camchain_true.yaml the one rendered with, and\n"
    "DIR/calibration_error.yaml each camera's error.\n";

struct Options {
  std::string out, camchain, mount, preset = "urban", gt_depth = "ref", gt_boxes = "ref", dataset;
  int dataset_every = 10, dataset_min_px = 4;
  uint32_t seed = 1;
  double duration = 20, rate = 10, speed = 8, jitter_ms = 0, drop = 0, pose_noise = 0;
  int moving = 6;
  double calib_rot_deg = 0, calib_trans_mm = 0, grain = 0, clouds = 0;
  bool overcast = false;
  int knock_camera = -1;  // none
  double knock_deg = 0, knock_at = 0;
  fm::synth::SensorSpread sensors;
};

[[noreturn]] void usageError(const std::string& what) {
  std::cerr << "make_drive: " << what << "\n" << kUsage;
  std::exit(2);
}

double number(const std::string& flag, const std::string& text) {
  try {
    return fm::cli::parseDouble(flag, text, -1e300, 1e300);
  } catch (const fm::cli::UsageError& e) {
    usageError(e.what());
  }
}

long long integer(const std::string& flag, const std::string& text, long long lo, long long hi) {
  try {
    return fm::cli::parseInt(flag, text, lo, hi);
  } catch (const fm::cli::UsageError& e) {
    usageError(e.what());
  }
}

// Bounds of a drive: beyond them a run would take hours or fill the disk.
constexpr double kMaxDuration = 3600;       // seconds
constexpr double kMaxRate = 100;            // Hz
constexpr double kMaxFrameSets = 36000;     // duration x rate
constexpr double kMaxSpeed = 60;            // m/s
constexpr double kMaxRouteLength = 50000;   // metres: speed x duration
constexpr int kMaxMoving = 100;             // moving vehicles

Options parse(int argc, char** argv) {
  Options o;
  const int rc = fm::cli::parseCommandLine("make_drive", kUsage, [&] {
    fm::cli::forEachOption(argc, argv, 1, [&](const std::string& a, const fm::cli::NextValue& next) {
      if (a == "--realistic") {
        const fm::synth::Realism r = fm::synth::Realism::realistic();
        o.calib_rot_deg = r.calib_rot_deg;
        o.calib_trans_mm = r.calib_trans_mm;
        o.sensors = r.sensors;
        o.grain = r.asphalt_grain;
        o.clouds = r.clouds;
        return true;
      }
      if (a == "--out") o.out = next();
      else if (a == "--camchain") o.camchain = next();
      else if (a == "--mount") o.mount = next();
      else if (a == "--preset") o.preset = next();
      else if (a == "--gt-depth") o.gt_depth = next();
      else if (a == "--gt-boxes") o.gt_boxes = next();
      else if (a == "--dataset") o.dataset = next();
      else if (a == "--dataset-every") o.dataset_every = static_cast<int>(integer(a, next(), 1, 1000));
      else if (a == "--dataset-min-px") o.dataset_min_px = static_cast<int>(integer(a, next(), 1, 100));
      else if (a == "--seed") o.seed = static_cast<uint32_t>(integer(a, next(), 0, 4294967295LL));
      else if (a == "--duration") o.duration = number(a, next());
      else if (a == "--rate") o.rate = number(a, next());
      else if (a == "--speed") o.speed = number(a, next());
      else if (a == "--moving") o.moving = static_cast<int>(integer(a, next(), 0, kMaxMoving));
      else if (a == "--jitter-ms") o.jitter_ms = number(a, next());
      else if (a == "--drop") o.drop = number(a, next());
      else if (a == "--pose-noise") o.pose_noise = number(a, next());
      else if (a == "--calib-rot-deg") o.calib_rot_deg = number(a, next());
      else if (a == "--calib-trans-mm") o.calib_trans_mm = number(a, next());
      else if (a == "--gain-spread") o.sensors.gain = number(a, next());
      else if (a == "--offset-spread") o.sensors.offset = number(a, next());
      else if (a == "--gamma-spread") o.sensors.gamma = number(a, next());
      else if (a == "--vignetting") o.sensors.base.vignetting = number(a, next());
      else if (a == "--read-noise") o.sensors.base.read_noise = number(a, next());
      else if (a == "--shot-noise") o.sensors.base.shot_noise = number(a, next());
      else if (a == "--blur") o.sensors.base.blur_px = number(a, next());
      else if (a == "--asphalt-grain") o.grain = number(a, next());
      else if (a == "--clouds") o.clouds = number(a, next());
      else if (a == "--cloudy-sky") {
        o.overcast = true;
        o.clouds = fm::synth::WorldConfig::kOvercastClouds;
      } else if (a == "--knock") {
        const std::string v = next();
        const size_t colon = v.find(':'), at = v.find('@');
        if (colon == std::string::npos || at == std::string::npos || at < colon)
          throw fm::cli::UsageError("--knock expects CAM:DEG@S (e.g. 2:0.5@10), got '" + v + "'");
        o.knock_camera = static_cast<int>(integer(a, v.substr(0, colon), 1, 15));
        o.knock_deg = number(a, v.substr(colon + 1, at - colon - 1));
        o.knock_at = number(a, v.substr(at + 1));
        if (!(o.knock_deg > 0 && o.knock_deg <= 10)) throw fm::cli::UsageError("--knock: DEG must lie in (0, 10], got '" + v + "'");
        if (!(o.knock_at >= 0)) throw fm::cli::UsageError("--knock: S must be >= 0, got '" + v + "'");
      }
      else return false;
      return true;
    });
  });
  if (rc >= 0) std::exit(rc);
  if (o.out.empty() || o.camchain.empty() || o.mount.empty()) usageError("--out, --camchain and --mount are required");
  if (!(o.rate > 0)) usageError("--rate must be positive, got " + std::to_string(o.rate));
  if (!(o.duration > 0)) usageError("--duration must be positive, got " + std::to_string(o.duration));
  if (o.rate > kMaxRate) usageError("--rate must be at most " + fm::cli::numberText(kMaxRate) + " Hz, got " + fm::cli::numberText(o.rate));
  if (o.duration > kMaxDuration)
    usageError("--duration must be at most " + fm::cli::numberText(kMaxDuration) + " s, got " + fm::cli::numberText(o.duration));
  if (o.duration * o.rate > kMaxFrameSets)
    usageError("--duration x --rate must give at most " + fm::cli::numberText(kMaxFrameSets) + " frame sets, got " +
               fm::cli::numberText(std::floor(o.duration * o.rate)));
  if (std::floor(o.duration * o.rate) < 1)
    usageError("--duration x --rate must give at least 1 frame set, got " + fm::cli::numberText(o.duration * o.rate));
  if (!(o.speed > 0) || o.speed > kMaxSpeed)
    usageError("--speed must lie in (0, " + fm::cli::numberText(kMaxSpeed) + "] m/s, got " + fm::cli::numberText(o.speed));
  if (o.speed * o.duration > kMaxRouteLength)
    usageError("--speed x --duration must be at most " + fm::cli::numberText(kMaxRouteLength) + " m of route, got " +
               fm::cli::numberText(o.speed * o.duration));
  if (o.jitter_ms < 0 || o.jitter_ms * 1e-3 >= 0.5 / o.rate) usageError("--jitter-ms must lie in [0, half the frame period)");
  if (o.drop < 0 || o.drop >= 1) usageError("--drop must lie in [0, 1)");
  if (o.pose_noise < 0 || o.pose_noise > 100) usageError("--pose-noise must lie in [0, 100] m");
  if (o.gt_depth != "ref" && o.gt_depth != "all" && o.gt_depth != "none") usageError("--gt-depth must be ref, all or none");
  if (o.gt_boxes != "ref" && o.gt_boxes != "all") usageError("--gt-boxes must be ref or all, got '" + o.gt_boxes + "'");
  if (o.calib_rot_deg < 0 || o.calib_rot_deg > 10) usageError("--calib-rot-deg must lie in [0, 10]");
  if (o.calib_trans_mm < 0 || o.calib_trans_mm > 500) usageError("--calib-trans-mm must lie in [0, 500]");
  if (o.sensors.gain < 0 || o.sensors.gain >= 1) usageError("--gain-spread must lie in [0, 1)");
  if (o.sensors.offset < 0 || o.sensors.offset > 100) usageError("--offset-spread must lie in [0, 100]");
  if (o.sensors.gamma < 0 || o.sensors.gamma >= 1) usageError("--gamma-spread must lie in [0, 1)");
  try {
    o.sensors.base.validate();
  } catch (const std::invalid_argument& e) {
    usageError(e.what());
  }
  if (o.grain < 0 || o.grain > 1) usageError("--asphalt-grain must lie in [0, 1]");
  if (o.clouds < 0 || o.clouds > 1) usageError("--clouds must lie in [0, 1]");
  return o;
}

// Smallest visible vehicle (pixels) given a ground-truth box in the bag.
constexpr int kMinGtPixels = 30;

// The ground-truth boxes of one image: moving vehicles only (the oracle masks
// them) or every vehicle.
std::vector<fm::Detection> truthBoxes(const fm::synth::World& world, const std::vector<fm::synth::VisibleBox>& boxes,
                                      bool moving_only) {
  std::vector<fm::Detection> dets;
  for (const auto& b : boxes) {
    if (b.pixels < kMinGtPixels || (moving_only && !world.isMoving(b.id))) continue;
    const fm::synth::VehicleKind kind = world.vehicleModel(b.id).dims().kind;
    fm::Detection d;
    d.x_min = b.box.x, d.y_min = b.box.y;
    d.x_max = b.box.x + b.box.width, d.y_max = b.box.y + b.box.height;
    d.class_id = fm::synth::cocoId(kind);
    d.class_name = fm::synth::cocoName(kind);
    d.score = 1.0f;
    dets.push_back(d);
  }
  return dets;
}

// A YOLO training set: images/NAME.png, labels/NAME.txt (one line per
// vehicle whose visible box is at least min_px on each side; an empty file for
// an image without one), classes.txt, boxes.csv (every labelled box with its
// vehicle id, whether it moves and its visible pixels) and README.txt.
class DatasetWriter {
 public:
  DatasetWriter(const Options& o, int argc, char** argv) : dir_(o.dataset), min_px_(o.dataset_min_px), seed_(o.seed) {
    for (const char* sub : {"/images", "/labels"}) std::filesystem::create_directories(dir_ + sub);
    // Every file through the checked writer (cli::writeTextAtomically);
    // boxes.csv once complete (finish()).
    fm::cli::writeTextAtomically(dir_ + "/classes.txt", [](std::ostream& classes) {
      for (int k = 0; k < fm::synth::kNumVehicleKinds; ++k)
        classes << fm::synth::kindName(fm::synth::VehicleKind(k)) << "\n";
    });
    std::ostringstream readme;
    readme << "make_drive training set: preset " << o.preset << ", seed " << o.seed << ", every " << o.dataset_every
           << " frame sets, boxes of at least " << min_px_ << " px a side\n"
           << "labels: YOLO 'class cx cy w h' normalised by the image size; classes.txt: 0 car, 1 van, 2 truck, 3 bus\n"
           << "COCO names for a COCO model: car -> car, van -> car, truck -> truck, bus -> bus\ncommand:";
    for (int i = 0; i < argc; ++i) readme << " " << argv[i];
    readme << "\n";
    fm::cli::writeTextAtomically(dir_ + "/README.txt", [&](std::ostream& f) { f << readme.str(); });
    csv_ << "image,vehicle,class,moving,x_min,y_min,x_max,y_max,pixels\n";
  }
  void add(const fm::synth::World& world, int set, size_t cam, const cv::Mat& image,
           const std::vector<fm::synth::VisibleBox>& boxes) {
    char name[64];
    std::snprintf(name, sizeof(name), "s%u_f%05d_cam%zu", seed_, set, cam);
    fm::writeImageFile(dir_ + "/images/" + name + ".png", image);
    std::ostringstream labels;
    for (const auto& b : boxes) {
      if (b.box.width < min_px_ || b.box.height < min_px_) continue;
      const int kind = static_cast<int>(world.vehicleModel(b.id).dims().kind);
      labels << fm::synth::yoloLine(kind, b.box, image.size()) << "\n";
      csv_ << name << "," << b.id << "," << fm::synth::kindName(fm::synth::VehicleKind(kind)) << ","
           << (world.isMoving(b.id) ? 1 : 0) << "," << b.box.x << "," << b.box.y << "," << b.box.x + b.box.width << ","
           << b.box.y + b.box.height << "," << b.pixels << "\n";
      ++labels_;
    }
    fm::cli::writeTextAtomically(dir_ + "/labels/" + name + ".txt", [&](std::ostream& f) { f << labels.str(); });
    ++images_;
  }
  void finish() {
    fm::cli::writeTextAtomically(dir_ + "/boxes.csv", [&](std::ostream& f) { f << csv_.str(); });
  }
  std::string summary() const {
    return std::to_string(images_) + " images, " + std::to_string(labels_) + " labelled vehicles -> " + dir_;
  }

 private:
  std::string dir_;
  int min_px_;
  uint32_t seed_;
  std::ostringstream csv_;
  size_t images_ = 0, labels_ = 0;
};

}  // namespace

int main(int argc, char** argv) {
  const Options opt = parse(argc, argv);
  try {
    const fm::Rig rig = fm::loadKalibrRig(opt.camchain, opt.mount);
    if (rig.cameras.empty()) usageError("the rig has no camera");
    fm::synth::WorldConfig wc;
    wc.preset = opt.preset;
    wc.seed = opt.seed;
    wc.speed = opt.speed;
    wc.moving_vehicles = opt.moving;
    wc.route_length = opt.speed * opt.duration + 60;
    wc.asphalt_grain = opt.grain;
    wc.clouds = opt.clouds;
    wc.overcast = opt.overcast;
    const fm::synth::World world(wc);
    const int n_cams = static_cast<int>(rig.cameras.size());
    const std::vector<fm::synth::SensorModel> sensors = fm::synth::drawSensors(opt.sensors, n_cams, opt.seed);
    const auto calib_errors = fm::synth::drawExtrinsicErrors(n_cams, opt.calib_rot_deg, opt.calib_trans_mm, opt.seed);

    // What a logged drive carries: the rig's calibration (with its error).
    const fm::Rig given = fm::synth::perturbRig(rig, calib_errors);

    std::filesystem::create_directories(opt.out);
    std::filesystem::remove(opt.out + "/camchain_true.yaml");
    std::filesystem::remove(opt.out + "/calibration_error.yaml");
    if (opt.calib_rot_deg > 0 || opt.calib_trans_mm > 0) {
      // The pipeline is given a calibration with the rig's error; the truth
      // (rendered with) stays beside it for scoring.
      fm::writeKalibrRig(given, opt.out + "/camchain.yaml", opt.out + "/mount.yaml");
      fm::writeKalibrRig(rig, opt.out + "/camchain_true.yaml", opt.out + "/mount.yaml");
      std::ostringstream err;
      err << "# make_drive: camchain.yaml = camchain_true.yaml with these errors (seed " << opt.seed
          << "): T_cam0_cam' = T_cam0_cam * (exp(rotation), translation), camera frame\n";
      for (int c = 0; c < n_cams; ++c) {
        const auto& e = calib_errors[c];
        err << rig.cameras[c].name << ": {rotation_deg: [" << e.rotation_deg.x() << ", " << e.rotation_deg.y() << ", "
            << e.rotation_deg.z() << "], translation_mm: [" << e.translation_mm.x() << ", " << e.translation_mm.y()
            << ", " << e.translation_mm.z() << "]}\n";
      }
      fm::cli::writeTextAtomically(opt.out + "/calibration_error.yaml", [&](std::ostream& f) { f << err.str(); });
    } else {
      fm::writeKalibrRig(rig, opt.out + "/camchain.yaml", opt.out + "/mount.yaml");
    }
    // A knock: the true rig from knock_at on.
    fm::Rig knocked = rig;
    std::filesystem::remove(opt.out + "/camchain_knocked.yaml");
    std::filesystem::remove(opt.out + "/knock.yaml");
    if (opt.knock_camera >= 0) {
      if (opt.knock_camera >= n_cams)
        usageError("--knock: camera " + std::to_string(opt.knock_camera) + " is not in the rig (" +
                   std::to_string(n_cams) + " cameras)");
      Eigen::Isometry3d T = rig.cameras[0].T_base_cam.inverse() * rig.cameras[opt.knock_camera].T_base_cam;
      T.linear() = T.linear() * Eigen::AngleAxisd(opt.knock_deg * M_PI / 180.0, Eigen::Vector3d(1, 1, 0).normalized())
                                    .toRotationMatrix();
      knocked = fm::withRelativePose(rig, 0, opt.knock_camera, T);
      fm::writeKalibrRig(knocked, opt.out + "/camchain_knocked.yaml", opt.out + "/mount_knocked.yaml");
      std::filesystem::remove(opt.out + "/mount_knocked.yaml");  // the mount (cam0) does not change
      std::ostringstream k;
      k << "# make_drive --knock: from at_s seconds of drive on, the camera's true rotation is turned by deg degrees\n"
        << "# about the axis (1, 1, 0)/sqrt 2 of its frame (camchain_knocked.yaml); the calibration given stays.\n"
        << "camera: cam" << opt.knock_camera << "\ndeg: " << opt.knock_deg << "\nat_s: " << opt.knock_at << "\n";
      fm::cli::writeTextAtomically(opt.out + "/knock.yaml", [&](std::ostream& f) { f << k.str(); });
    }
    world.saveStaticMeshPly(opt.out + "/static_scene.ply");
    {
      std::ostringstream w;
      w << "# make_drive: the synthetic world of this drive (fisheye_mapping::synth::WorldConfig)\n"
        << "preset: " << wc.preset << "\nseed: " << wc.seed << "\nspeed: " << wc.speed
        << "\nmoving_vehicles: " << wc.moving_vehicles << "\nroute_length: " << wc.route_length
        << "\nasphalt_grain: " << wc.asphalt_grain << "\nclouds: " << wc.clouds << "\novercast: " << (wc.overcast ? "true" : "false") << "\nduration: " << opt.duration
        << "\n";
      fm::cli::writeTextAtomically(opt.out + "/world.yaml", [&](std::ostream& f) { f << w.str(); });
    }

    const std::string bag_path = opt.out + "/drive.bag";
    rosbag::Bag bag;
    try {
      bag.open(bag_path, rosbag::bagmode::Write);
    } catch (const rosbag::BagException& e) {
      std::cerr << "make_drive: cannot write " << bag_path << ": " << e.what() << "\n";
      return 2;
    }
    bag.setCompression(rosbag::compression::LZ4);

    const ros::Time t0(1700000000, 0);  // fixed: same seed, same bag
    std::mt19937_64 rng(opt.seed * 0x9E3779B97F4A7C15ull + 1);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    std::normal_distribution<double> N(0.0, 1.0);

    // Static mounts, latched like a live /tf_static.
    tf2_msgs::TFMessage statics;
    for (const auto& cam : given.cameras) statics.transforms.push_back(fm::toTransformMsg(cam.T_base_cam, rig.base_frame, cam.frame_id, t0));
    auto latched = boost::make_shared<ros::M_string>();
    (*latched)["latching"] = "1";
    (*latched)["callerid"] = "/make_drive";
    (*latched)["type"] = ros::message_traits::datatype<tf2_msgs::TFMessage>();
    (*latched)["md5sum"] = ros::message_traits::md5sum<tf2_msgs::TFMessage>();
    (*latched)["message_definition"] = ros::message_traits::definition<tf2_msgs::TFMessage>();
    bag.write("/tf_static", t0, statics, latched);

    // GNSS/INS poses at 100 Hz, covering the whole drive.
    const int n_sets = static_cast<int>(std::floor(opt.duration * opt.rate));
    const double end_time = n_sets / opt.rate + 0.05;
    for (int k = 0; k * 0.01 <= end_time; ++k) {
      const double t = k * 0.01;
      Eigen::Isometry3d T = world.egoPose(t);
      if (opt.pose_noise > 0) T.translation() += opt.pose_noise * Eigen::Vector3d(N(rng), N(rng), N(rng));
      tf2_msgs::TFMessage m;
      m.transforms.push_back(fm::toTransformMsg(T, "map", rig.base_frame, t0 + ros::Duration(t)));
      bag.write("/tf", t0 + ros::Duration(t), m);
    }

    std::unique_ptr<DatasetWriter> dataset;
    if (!opt.dataset.empty()) dataset = std::make_unique<DatasetWriter>(opt, argc, argv);
    std::vector<std::vector<Eigen::Vector3f>> rays;
    for (const auto& cam : rig.cameras) rays.push_back(fm::pixelRays(cam.model));
    const auto wall_start = std::chrono::steady_clock::now();
    size_t images = 0, dropped = 0;
    for (int s = 0; s < n_sets; ++s) {
      const double t = s / opt.rate;
      const ros::Time stamp = t0 + ros::Duration(t);
      const Eigen::Isometry3d T_W_B = world.egoPose(t);
      const fm::Rig& truth = opt.knock_camera >= 0 && t >= opt.knock_at ? knocked : rig;
      for (size_t c = 0; c < truth.cameras.size(); ++c) {
        const auto& cam = truth.cameras[c];
        const std::string ns = "/cam" + std::to_string(c);
        double jitter = 0;
        if (opt.jitter_ms > 0) jitter = (2 * U(rng) - 1) * opt.jitter_ms * 1e-3;
        const bool drop = opt.drop > 0 && U(rng) < opt.drop;
        const auto frame = world.render(cam.model, rays[c], T_W_B * cam.T_base_cam, t + jitter,
                                        (static_cast<uint64_t>(opt.seed) << 32) ^ (s * 64 + c), sensors[c]);
        std_msgs::Header header;
        header.stamp = stamp + ros::Duration(jitter);
        header.frame_id = cam.frame_id;
        if (drop) {
          ++dropped;
        } else {
          bag.write(ns + "/image_raw", header.stamp, fm::toImageMsg(header, frame.image));  // mono8
          ++images;
        }
        if (opt.gt_depth == "all" || (opt.gt_depth == "ref" && c == 0)) {
          bag.write(ns + "/depth_gt", header.stamp, fm::toDepthMsg(header, frame.depth));
        }
        const bool boxes_here = opt.gt_boxes == "all" || c == 0;
        const bool dataset_here = dataset && s % opt.dataset_every == 0;
        if (boxes_here || dataset_here) {
          // Visible extents, from the rendered ids: occlusion and the image edge included.
          const auto boxes = fm::synth::visibleBoxes(frame.ids, world.numVehicleIds(), 1);
          if (boxes_here) {
            const int w = cam.model.width(), h = cam.model.height();
            bag.write(ns + "/detections_gt", header.stamp, fm::toDetectionArrayMsg(header, w, h, truthBoxes(world, boxes, true)));
            bag.write(ns + "/vehicles_gt", header.stamp, fm::toDetectionArrayMsg(header, w, h, truthBoxes(world, boxes, false)));
          }
          if (dataset_here) dataset->add(world, s, c, frame.image, boxes);
        }
      }
      const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
      if (isatty(STDERR_FILENO)) {
        std::fprintf(stderr, "\rmake_drive: %d/%d frame sets, %.1f s", s + 1, n_sets, elapsed);
      } else if ((s + 1) % std::max(1, n_sets / 10) == 0) {
        std::fprintf(stderr, "make_drive: %d/%d frame sets, %.1f s\n", s + 1, n_sets, elapsed);
      }
    }
    bag.close();
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
    if (isatty(STDERR_FILENO)) std::fprintf(stderr, "\n");
    std::printf("make_drive: %s preset, seed %u: %d frame sets x %zu cameras (%zu images written, %zu dropped) "
                "rendered and written in %.1f s -> %s\n",
                opt.preset.c_str(), opt.seed, n_sets, rig.cameras.size(), images, dropped, elapsed, bag_path.c_str());
    if (dataset) {
      dataset->finish();
      std::printf("make_drive: dataset: %s\n", dataset->summary().c_str());
    }
  } catch (const fm::CalibrationError& e) {
    std::cerr << "make_drive: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "make_drive: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
