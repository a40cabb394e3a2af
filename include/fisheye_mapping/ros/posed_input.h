// A stage's image input that needs each image's pose (the TSDF's depth
// frames): a tf2 MessageFilter holds an image until the transform of its
// stamp to the world frame is in the tf buffer, as image_pipeline and
// voxblox wait for tf. An image the filter gives up on goes to `failed` with
// the drop reason the diagnostics count ("bad image": no frame id; "no
// pose": the transform never came, or is older than the buffer) and a
// description naming the frames and the stamp. The buffer answers the
// stage's own lookups (pose()).
#ifndef FISHEYE_MAPPING_ROS_POSED_INPUT_H_
#define FISHEYE_MAPPING_ROS_POSED_INPUT_H_

#include <functional>
#include <string>

#include <Eigen/Geometry>
#include <message_filters/subscriber.h>
#include <ros/node_handle.h>
#include <sensor_msgs/Image.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/message_filter.h>
#include <tf2_ros/transform_listener.h>

namespace fisheye_mapping {

class PosedImageInput {
 public:
  using Image = sensor_msgs::ImageConstPtr;
  using Failed = std::function<void(const Image&, const std::string& drop_reason, const std::string& why)>;

  // `received`: every image as it comes (for the input rate); `ready`: an
  // image whose pose is in the buffer.
  PosedImageInput(ros::NodeHandle& nh, const std::string& topic, const std::string& world_frame, uint32_t queue_size,
                  std::function<void(const Image&)> received, std::function<void(const Image&)> ready, Failed failed);

  /// T_world_frame at `stamp`; throws tf2::TransformException.
  Eigen::Isometry3d pose(const std::string& frame, const ros::Time& stamp) const;
  /// Forgets the tf cache (time went back: a bag played again).
  void clear() { buffer_.clear(); }
  const std::string& worldFrame() const { return world_frame_; }

 private:
  std::string world_frame_;
  tf2_ros::Buffer buffer_;
  tf2_ros::TransformListener listener_;
  message_filters::Subscriber<sensor_msgs::Image> sub_;
  tf2_ros::MessageFilter<sensor_msgs::Image> filter_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_POSED_INPUT_H_
