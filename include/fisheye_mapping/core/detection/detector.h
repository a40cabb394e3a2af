// YOLO-family object detection through OpenCV's DNN module (no ROS).
//
// A model YAML (config/detector/*.yaml) names the file format (Darknet cfg +
// weights, or ONNX), the network input size, the class names, the output head
// (darknet, yolov5, yolov8, nanodet), the score and NMS thresholds, the input
// normalisation and which classes count as potentially moving. Images (mono8
// fisheye frames are replicated to three channels) are letterboxed into the
// network input, the outputs decoded by the head's decoder, suppressed per
// class, and the boxes mapped back to image pixels.
#ifndef FISHEYE_MAPPING_CORE_DETECTION_DETECTOR_H_
#define FISHEYE_MAPPING_CORE_DETECTION_DETECTOR_H_

#include <opencv2/core.hpp>

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace fisheye_mapping {

class ParamSource;

/// One detection in image pixels (x right, y down, origin at the top-left pixel's corner).
struct Detection {
  int class_id = -1;
  std::string class_name;
  float score = 0.f;
  float x_min = 0.f, y_min = 0.f, x_max = 0.f, y_max = 0.f;
};

enum class ModelFormat { Darknet, Onnx };
/// darknet: cv::dnn's [yolo]/[region] output rows (cx, cy, w, h normalised to the input,
///          objectness, class scores already multiplied by the objectness).
/// yolov5:  one output [1, N, 5 + C]: cx, cy, w, h in input pixels, objectness, class scores.
/// yolov8:  one output [1, 4 + C, N] (or [1, N, 4 + C]): cx, cy, w, h in input pixels, class scores.
/// nanodet: GFL head: per stride class scores [1, N_s, C] and distance bins
///          [1, N_s, 4 * (reg_max + 1)], or both concatenated in one [1, sum N_s, C + 4 * (reg_max + 1)].
enum class DetectorHead { Darknet, YoloV5, YoloV8, NanoDet };

struct DetectorModelConfig {
  ModelFormat format = ModelFormat::Onnx;
  std::string model_path;    ///< .onnx, or the Darknet .weights
  std::string darknet_cfg;   ///< Darknet .cfg (format darknet only)
  int input_width = 416;
  int input_height = 416;
  std::vector<std::string> class_names;
  DetectorHead head = DetectorHead::NanoDet;
  float score_threshold = 0.35f;
  float nms_threshold = 0.5f;
  /// Non-maximum suppression over all classes (one box per object, for a model
  /// whose classes are kinds of one thing, e.g. car / van / truck / bus: the
  /// same vehicle scored as two kinds is one detection); false: within a class.
  bool nms_across_classes = false;
  /// Classes whose boxes are published (and masked): the potentially moving ones.
  std::vector<std::string> moving_classes = {"bicycle", "car", "motorbike", "bus", "train", "truck"};
  /// Input normalisation, in the network's channel order: (pixel - mean) / std, pixel in 0..255.
  cv::Scalar mean = cv::Scalar(0, 0, 0);
  cv::Scalar std = cv::Scalar(255, 255, 255);
  bool swap_rb = true;          ///< network wants RGB (input images are BGR or grey)
  bool letterbox = true;        ///< keep the aspect ratio, pad; false: stretch to the input size
  float pad_value = 114.f;      ///< letterbox border grey level
  // nanodet head
  std::vector<int> strides = {8, 16, 32};
  int reg_max = 10;             ///< distance bins per side minus one
  float center_offset = 0.5f;   ///< anchor centre (i + offset) * stride (0.5: NanoDet GFL; 0: NanoDet-Plus)
};

/// Reads a model YAML. Relative paths are relative to the YAML's folder; `~`,
/// `${VAR}` and `${VAR:-default}` are expanded. Throws std::runtime_error naming
/// the file and the key for anything missing or malformed (among them
/// score_threshold outside (0, 1) and nms_threshold outside (0, 1]).
DetectorModelConfig loadDetectorConfig(const std::string& yaml_path);

/// Expands a leading `~`, `${VAR}` and `${VAR:-default}` (nested defaults allowed).
std::string expandPath(const std::string& path);

const char* headName(DetectorHead head);
DetectorHead parseHead(const std::string& name);  ///< throws on unknown names

/// The image -> network input mapping of a letterbox (or stretch).
struct Letterbox {
  float scale_x = 1.f, scale_y = 1.f;  ///< input pixels per image pixel
  float pad_x = 0.f, pad_y = 0.f;      ///< input pixels left / top of the image
  static Letterbox compute(int image_w, int image_h, int input_w, int input_h, bool keep_aspect);
  float toImageX(float x) const { return (x - pad_x) / scale_x; }
  float toImageY(float y) const { return (y - pad_y) / scale_y; }
};

/// Converts mono8 / bgr8 / bgra8 to the normalised NCHW float blob the network takes.
/// Throws std::invalid_argument for an empty image or an unsupported type.
cv::Mat makeInputBlob(const cv::Mat& image, const DetectorModelConfig& cfg, Letterbox* lb);

/// A candidate before suppression: box in network-input pixels.
struct Candidate {
  int class_id;
  float score;
  float x_min, y_min, x_max, y_max;
};

/// Head decoders: network outputs -> candidates above cfg.score_threshold (best class per anchor).
/// They throw std::runtime_error when the outputs do not have the head's layout.
std::vector<Candidate> decodeDarknet(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg);
std::vector<Candidate> decodeYoloV5(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg);
std::vector<Candidate> decodeYoloV8(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg);
std::vector<Candidate> decodeNanoDet(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg);
std::vector<Candidate> decodeHead(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg);

/// Non-maximum suppression within each class (different classes never suppress each other).
std::vector<Candidate> nmsPerClass(const std::vector<Candidate>& cands, float iou_threshold);
/// Non-maximum suppression over all classes: the best-scored box of overlapping
/// ones stays, with its class.
std::vector<Candidate> nmsAcrossClasses(const std::vector<Candidate>& cands, float iou_threshold);

/// Intersection over union of two boxes.
float boxIoU(const Detection& a, const Detection& b);

/// Candidates (input pixels) -> detections in image pixels, clipped to the image; keeps only
/// moving classes when `only_moving` (class names from cfg).
std::vector<Detection> toDetections(const std::vector<Candidate>& cands, const Letterbox& lb,
                                    const DetectorModelConfig& cfg, int image_w, int image_h,
                                    bool only_moving);

/// Draws boxes with class name and score on a BGR copy of `image`.
cv::Mat annotateDetections(const cv::Mat& image, const std::vector<Detection>& dets);

/// cv::dnn backend / target by name: backend "opencv" | "default"; target "cpu" | "opencl" | "opencl_fp16".
struct DnnDevice {
  std::string backend = "opencv";
  std::string target = "cpu";
};

/// The same as enumerations, parsed once from the parameters dnn_backend and
/// dnn_target: parseX throws std::invalid_argument naming the parameter, the
/// allowed values and the bad one; toString gives the name back.
enum class DnnBackend { OpenCv, Default };           ///< "opencv" | "default"
enum class DnnTarget { Cpu, OpenCl, OpenClFp16 };    ///< "cpu" | "opencl" | "opencl_fp16"
DnnBackend parseDnnBackend(const std::string& s);
DnnTarget parseDnnTarget(const std::string& s);
std::string toString(DnnBackend b);
std::string toString(DnnTarget t);

/// The detector stage's parameters (the detector nodelet's, and the detector
/// section of the offline tools' configuration).
template <class Config>
class ParamTable;  // fisheye_mapping/core/common/param_table.h

struct DetectorStageConfig {
  /// Path of a model YAML (config/detector/*.yaml; loadDetectorConfig). Empty:
  /// not set (loadModel() throws; the stage runs without a model).
  std::string model_config;
  /// Override the model YAML's thresholds when set: score_threshold in (0, 1)
  /// (as the model YAML's), nms_threshold in (0, 1].
  std::optional<float> score_threshold;
  std::optional<float> nms_threshold;
  DnnBackend dnn_backend = DnnBackend::OpenCv;  ///< parameter dnn_backend: "opencv" | "default"
  DnnTarget dnn_target = DnnTarget::Cpu;        ///< parameter dnn_target: "cpu" | "opencl" | "opencl_fp16"
  bool only_moving = true;        ///< publish (and mask) the model's moving classes only
  bool publish_annotated = true;  ///< also publish the image with the boxes drawn

  /// Throws std::invalid_argument naming the parameter and the bad value.
  void validate() const;
  /// The declaration of every parameter (docs/parameters.md).
  static const ParamTable<DetectorStageConfig>& params();
  /// `base` overlaid with the parameters of the same names in `p`
  /// (dnn_backend / dnn_target as their names, parsed here); validated. The
  /// run-time subset (score_threshold, nms_threshold, only_moving,
  /// publish_annotated: no model reload) is cfg/DetectorReconfigure.cfg's, read
  /// through this same function.
  static DetectorStageConfig fromParams(const ParamSource& p, DetectorStageConfig base);
  static DetectorStageConfig fromParams(const ParamSource& p) { return fromParams(p, DetectorStageConfig()); }
  /// dnn_backend and dnn_target as the Detector takes them.
  DnnDevice device() const;
  /// The model YAML (loadDetectorConfig) with the thresholds overridden.
  /// Throws std::runtime_error when model_config is empty or the YAML is bad.
  DetectorModelConfig loadModel() const;
};

class Detector {
 public:
  /// Loads the network; throws std::runtime_error with the path and OpenCV's reason when the
  /// model file is missing or cannot be parsed.
  Detector(const DetectorModelConfig& cfg, const DnnDevice& device = DnnDevice());
  ~Detector();
  Detector(const Detector&) = delete;
  Detector& operator=(const Detector&) = delete;

  /// Detections in image pixels. `only_moving`: keep the config's moving classes only.
  std::vector<Detection> detect(const cv::Mat& image, bool only_moving = true);
  const DetectorModelConfig& config() const { return cfg_; }
  /// New score / NMS thresholds for the next detect() (the network stays).
  /// Throws std::invalid_argument naming the field unless score_threshold is
  /// in (0, 1) and nms_threshold in (0, 1].
  void setThresholds(float score_threshold, float nms_threshold);

 private:
  DetectorModelConfig cfg_;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::vector<cv::Mat> outs_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DETECTION_DETECTOR_H_
