// Geometric summaries of cameras and rigs: fields of view and pairwise overlap.
#ifndef FISHEYE_MAPPING_CORE_CAMERA_RIG_GEOMETRY_H_
#define FISHEYE_MAPPING_CORE_CAMERA_RIG_GEOMETRY_H_

#include "fisheye_mapping/core/camera/rig.h"

namespace fisheye_mapping {

struct FieldOfView {
  // Between the extreme valid rays of the image row (column) through the
  // principal point; the nearest one of the image when the principal point
  // lies outside it (a crop), so only the image's own pixels count.
  double horizontal_deg = 0.0;
  double vertical_deg = 0.0;
  double max_off_axis_deg = 0.0;  // largest angle of any valid pixel's ray to the axis
};

// Field of view covered by the image (its pixels that unproject validly).
FieldOfView computeFieldOfView(const CameraModel& model);

// Share, in [0, 1], of camera a's pixels (sampled every `step` pixels) whose
// ray, at `range_m` metres from a, is seen inside camera b's image.
double computeOverlap(const RigCamera& a, const RigCamera& b, double range_m = 20.0,
                      int step = 8);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_CAMERA_RIG_GEOMETRY_H_
