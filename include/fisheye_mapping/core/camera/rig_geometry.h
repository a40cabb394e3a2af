// Geometric summaries of cameras and rigs: fields of view and pairwise overlap.
#ifndef FISHEYE_MAPPING_CORE_CAMERA_RIG_GEOMETRY_H_
#define FISHEYE_MAPPING_CORE_CAMERA_RIG_GEOMETRY_H_

#include "fisheye_mapping/core/camera/rig.h"

namespace fisheye_mapping {

struct FieldOfView {
  double horizontal_deg = 0.0;    // between the extreme valid rays of the centre row
  double vertical_deg = 0.0;      // between the extreme valid rays of the centre column
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
