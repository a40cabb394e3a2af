// The mapping pipeline for one frame set at a time (paper Sec. III): depth of
// the reference camera (DepthStage), moving objects found (Detector) or given
// (e.g. a drive's ground-truth boxes) and masked out (maskDepthBoxes), and the
// masked depth fused into the TSDF (TsdfFusionStage, the TSDF nodelet's core), with per-stage
// timings. The offline tools (offline_mapper, the evaluation) run it; the
// nodelets run the same stage objects with the same configs, one stage each,
// so that what the evaluation measures is what vehicle.launch runs. No ROS.
#ifndef FISHEYE_MAPPING_CORE_MAPPING_FRAME_SET_MAPPER_H_
#define FISHEYE_MAPPING_CORE_MAPPING_FRAME_SET_MAPPER_H_

#include <atomic>
#include <future>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/depth/depth_stage.h"
#include "fisheye_mapping/core/detection/depth_mask.h"
#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/detection/held_depth.h"
#include "fisheye_mapping/core/tsdf/fusion_stage.h"

namespace fisheye_mapping {

struct FrameSetMapperConfig {
  DepthStageConfig depth;
  DetectorStageConfig detection;
  DepthMaskConfig mask;
  TsdfConfig tsdf;
  // The mesh follows the map every mesh_every frame sets (and on finish()):
  // the same mesh and cloud at the end, for a fraction of the cost.
  int mesh_every = 10;
  void validate() const;
  // Each stage from its own parameters (the sections of the nodelets'
  // parameters: depth, detector, depth_mask, tsdf); validated.
  static FrameSetMapperConfig fromParams(const ParamSource& depth, const ParamSource& detection,
                                         const ParamSource& mask, const ParamSource& tsdf);
};

// Boxes of moving objects in an image of image_width x image_height pixels
// (boxes are scaled to the depth map's size when it differs).
struct ImageBoxes {
  std::vector<Detection> boxes;
  int image_width = 0;
  int image_height = 0;
};

struct FrameSetTimings {
  double depth_ms = 0;   // plane sweep and filters (or the given depth)
  double detect_ms = 0;  // detector (0 with given boxes)
  double mask_ms = 0;
  double fuse_ms = 0;    // TSDF integration and, every mesh_every sets, the mesh update
  double total_ms = 0;
};

struct FrameSetResult {
  DepthResult depth;      // depth.depth: masked range image of the reference camera
  cv::Mat mask;           // CV_8U, 255 where a box removed depth
  size_t masked_pixels = 0;
  size_t held_frames_fused = 0;  // earlier frame sets' held depth fused after this one (VehicleDepthHold)
  IntegrationStats fusion;
  FrameSetTimings ms;
  // When the depth stage's self-calibration updated in this frame set
  // (depth.calibration_ms > 0): its state and the rig right after the update
  // (submit() hands results back a frame set late, when it may have moved on).
  std::vector<CameraCalibrationState> calibration;
  std::optional<Rig> calibrated_rig;
  // The boxes of the frame set (the detector's or the given ones) and, for
  // the detector's, whether each vehicle moves (VehicleMotionTracker; empty
  // without a stamp or with given boxes, which are all masked). Masked: the
  // moving and undecided ones (all with mask.mask_parked).
  ImageBoxes boxes;
  std::vector<VehicleMotionTracker::Decision> motion;
};

class FrameSetMapper {
 public:
  // `detector` may be null: then process() uses the boxes it is given (none:
  // nothing masked). Throws what DepthStage, TsdfMap and validate() throw.
  FrameSetMapper(const Rig& rig, const FrameSetMapperConfig& config, std::unique_ptr<Detector> detector = nullptr);

  // One frame set: images[i] of rig camera i, T_W_B the base's pose in the
  // world (map) frame at the frame set's stamp (stamp_s, seconds: what the
  // detector's vehicles are tracked by; NaN: no tracking, every detected
  // vehicle masked). `boxes` are used when there is no detector. Not
  // thread-safe.
  FrameSetResult process(const std::vector<cv::Mat>& images, const Eigen::Isometry3d& T_W_B,
                         const std::optional<ImageBoxes>& boxes = std::nullopt,
                         double stamp_s = std::numeric_limits<double>::quiet_NaN());
  // The same with a given depth map of the reference camera instead of the
  // sweep (e.g. ground-truth depth: the evaluation's reference map); `grey`
  // the reference camera's image for the map's intensity (empty: none).
  FrameSetResult processDepth(cv::Mat depth, const Eigen::Isometry3d& T_W_B,
                              const std::optional<ImageBoxes>& boxes = std::nullopt, const cv::Mat& grey = cv::Mat());
  // Pipelined: the same stages as process(), with the depth of this frame set
  // computed on the calling thread while this set's detection and the
  // previous set's masking and fusion run on other threads, so that a frame
  // set costs about its depth time. Returns the previous frame set's result
  // (none for the first), flush() the last one; results come in order, each
  // the same as process() would have given. An exception of a frame set's
  // depth is thrown by its submit(), one of its detection or fusion by the
  // next submit() or flush() (that frame set is lost, the map keeps the
  // others). process() and processDepth() flush first. Not thread-safe.
  std::optional<FrameSetResult> submit(const std::vector<cv::Mat>& images, const Eigen::Isometry3d& T_W_B,
                                       const std::optional<ImageBoxes>& boxes = std::nullopt,
                                       double stamp_s = std::numeric_limits<double>::quiet_NaN());
  std::optional<FrameSetResult> flush();
  // Brings the mesh up to date with the map (after the last frame set;
  // flushes a submitted one first).
  void finish();

  const Rig& rig() const { return depth_.rig(); }
  int reference() const { return depth_.reference(); }
  const FrameSetMapperConfig& config() const { return config_; }
  const DepthStage& depthStage() const { return depth_; }
  bool hasDetector() const { return detector_ != nullptr; }
  TsdfMap& map() { return tsdf_->map(); }
  const TsdfMesher& mesher() const { return tsdf_->mesher(); }
  size_t frameSets() const { return frame_sets_.load(); }

 private:
  // The boxes to mask: the detector's on the reference image, else `given`
  // (none: nothing masked).
  ImageBoxes boxesFor(const cv::Mat& reference_image, const std::optional<ImageBoxes>& given, double* ms);
  // Masks the boxes (with a stamp, the detector's parked vehicles are kept)
  // and fuses.
  // `image`: the reference camera's image (the map's intensity when it is CV_8UC1 of the camera's size).
  FrameSetResult maskAndFuse(FrameSetResult r, const ImageBoxes& boxes, const Eigen::Isometry3d& T_W_B,
                             const RigCamera& reference, double stamp_s, const cv::Mat& image = cv::Mat());
  // The depth stage's result for the images (T_W_B: the vehicle's pose, for
  // the self-calibration's translations), with the calibration snapshot.
  FrameSetResult depthOf(const std::vector<cv::Mat>& images, const Eigen::Isometry3d* T_W_B = nullptr);
  FrameSetMapperConfig config_;
  DepthStage depth_;
  std::unique_ptr<Detector> detector_;
  // The TSDF nodelet's core stage: map, mesh, the grey image and carve
  // regions of a frame set's stamp (no map file, no time resets: offline).
  std::unique_ptr<TsdfFusionStage> tsdf_;
  std::int64_t next_unstamped_ns_ = 0;  // stamps of frame sets given without one
  VehicleMotionTracker motion_;
  VehicleDepthHold hold_;
  std::atomic<size_t> frame_sets_{0};
  // submit(): the previous frame set's detection and masking + fusion.
  std::shared_future<ImageBoxes> detection_;
  std::future<FrameSetResult> pending_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_MAPPING_FRAME_SET_MAPPER_H_
