// Ground-truth boxes of the vehicles a rendered frame shows, from its
// per-pixel vehicle ids (so occlusion and the image edge are accounted for:
// a box is the extent of the visible pixels, not a projected 3D box), and
// their YOLO text form for training sets ("class cx cy w h", normalised by the
// image size).
//
// Boxes are in pixels with the origin at the top-left pixel's corner (as
// Detection2D.msg): pixel (u, v) covers [u, u + 1) x [v, v + 1).
#ifndef FISHEYE_MAPPING_CORE_SIM_VEHICLE_LABELS_H_
#define FISHEYE_MAPPING_CORE_SIM_VEHICLE_LABELS_H_

#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace fisheye_mapping {
namespace synth {

struct VisibleBox {
  int id = -1;     // vehicle id
  cv::Rect box;    // visible extent: x .. x + width exclusive
  int pixels = 0;  // visible pixels
};
// Every id in [0, num_ids) with at least min_pixels pixels in `ids`
// (CV_16SC1, -1 for none), by increasing id. Throws std::invalid_argument on
// another image type.
std::vector<VisibleBox> visibleBoxes(const cv::Mat& ids, int num_ids, int min_pixels);

// "class cx cy w h" with the centre and size divided by the image's width and
// height; the corners are rounded inwards to 1e-6 of the image (far below a
// pixel), so cx -+ w / 2 stays within [0, 1].
std::string yoloLine(int class_id, const cv::Rect2d& box, const cv::Size& image);
// Reads one such line back into a pixel box. Throws std::invalid_argument
// naming what is wrong (field count, a non-number, a value outside [0, 1]).
void parseYoloLine(const std::string& line, const cv::Size& image, int* class_id, cv::Rect2d* box);

}  // namespace synth
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_SIM_VEHICLE_LABELS_H_
