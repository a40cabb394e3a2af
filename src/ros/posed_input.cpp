#include "fisheye_mapping/ros/posed_input.h"

#include "fisheye_mapping/ros/conversions.h"

namespace fisheye_mapping {

PosedImageInput::PosedImageInput(ros::NodeHandle& nh, const std::string& topic, const std::string& world_frame,
                                 uint32_t queue_size, std::function<void(const Image&)> received,
                                 std::function<void(const Image&)> ready, Failed failed)
    : world_frame_(world_frame),
      buffer_(ros::Duration(30.0)),
      listener_(buffer_, nh),
      sub_(nh, topic, queue_size),
      filter_(sub_, buffer_, world_frame, queue_size, nh) {
  sub_.registerCallback([received](const Image& msg) { received(msg); });
  filter_.registerCallback([ready](const Image& msg) { ready(msg); });
  filter_.registerFailureCallback(
      [this, failed](const Image& msg, tf2_ros::filter_failure_reasons::FilterFailureReason reason) {
        const std::string at = std::to_string(msg->header.stamp.toSec());
        if (reason == tf2_ros::filter_failure_reasons::EmptyFrameID) {
          return failed(msg, "bad image", "image at " + at + " has no frame_id");
        }
        const std::string why = reason == tf2_ros::filter_failure_reasons::OutTheBack
                                    ? "older than the tf buffer"
                                    : "tf never arrived (or queue full)";
        failed(msg, "no pose", "no transform '" + msg->header.frame_id + "' -> '" + world_frame_ + "' at " + at + ": " + why);
      });
}

Eigen::Isometry3d PosedImageInput::pose(const std::string& frame, const ros::Time& stamp) const {
  return toIsometry(buffer_.lookupTransform(world_frame_, frame, stamp));
}

}  // namespace fisheye_mapping
