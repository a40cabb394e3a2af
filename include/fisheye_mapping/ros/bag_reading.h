// Opening the bags users give the offline tools, as they come off a car: a
// recording cut short (power loss, a full disk, a killed `rosbag record`)
// leaves a bag without its index (`<name>.bag.active`: the header's index
// position is 0) or with an index position beyond the file's end (cut mid-chunk).
// librosbag reads only indexed bags and says "wanted 4 bytes" or "Bag
// unindexed"; these say what happened and give the exact `rosbag reindex`
// command that recovers every complete chunk.
#ifndef FISHEYE_MAPPING_ROS_BAG_READING_H_
#define FISHEYE_MAPPING_ROS_BAG_READING_H_

#include <rosbag/bag.h>
#include <rosbag/message_instance.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>

#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace fisheye_mapping {

/// What the bag's file header says about its index: "" when it looks whole
/// (or is no rosbag 2.0 file: librosbag then names the problem), else e.g.
/// "it has no index (a recording that was not closed: index position 0)" or
/// "it is cut short: its index should start at byte 4211 but the file has 3000 bytes".
std::string bagIndexProblem(const std::string& path);

/// The shell command that reindexes `path` in place (rosbag keeps the original
/// as <name>.orig.<ext>), the path quoted for the shell.
std::string rosbagReindexCommand(const std::string& path);

/// Opens `path` for reading: a regular file (a FIFO or a device is refused
/// without blocking) that librosbag opens. Throws std::runtime_error naming
/// the bag: for an unindexed or truncated bag, what bagIndexProblem() found
/// and rosbagReindexCommand(); otherwise librosbag's error.
void openBagForReading(rosbag::Bag& bag, const std::string& path);

/// One camera image of a bag, raw (sensor_msgs/Image) or compressed
/// (sensor_msgs/CompressedImage); decoded only when its frame set is used.
struct BagImage {
  sensor_msgs::Image::ConstPtr raw;
  sensor_msgs::CompressedImage::ConstPtr compressed;

  /// The message as an image; nullopt for a message of another type.
  static std::optional<BagImage> of(const rosbag::MessageInstance& m);
  const std_msgs::Header& header() const { return raw ? raw->header : compressed->header; }
  /// Raw images decoded as the depth nodelet decodes them (ros/conversions.h,
  /// ImageTarget::kSweep), compressed ones to 8-bit grey. Throws
  /// std::runtime_error naming `source` for an image that does not decode.
  cv::Mat sweepImage(const std::string& source) const;
  /// 8-bit grey (mono8).
  cv::Mat greyImage(const std::string& source) const;
};

/// The bag's topic for each camera image topic: the topic itself, or
/// `<topic>/compressed` (image_transport's name) when the bag has only that.
std::vector<std::string> imageTopicsInBag(rosbag::Bag& bag, std::vector<std::string> topics);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_BAG_READING_H_
