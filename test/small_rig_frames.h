// The small 3-camera rig of test/data/small_rig_camchain.yaml and a frame
// set rendered for it, shared by the rostest nodes that feed the depth stage.
#ifndef FISHEYE_MAPPING_TEST_SMALL_RIG_FRAMES_H_
#define FISHEYE_MAPPING_TEST_SMALL_RIG_FRAMES_H_

#include <string>
#include <vector>

#include <cv_bridge/cv_bridge.h>
#include <ros/package.h>
#include <geometry_msgs/TransformStamped.h>
#include <sensor_msgs/CameraInfo.h>
#include <tf2_eigen/tf2_eigen.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"

namespace fisheye_mapping {
namespace test {

inline Rig smallRig() {
  const std::string dir = ros::package::getPath("fisheye_mapping") + "/test/data/";
  return loadKalibrRig(dir + "small_rig_camchain.yaml", dir + "small_rig_mount.yaml");
}

// The synthetic street the frame set is rendered in.
inline synth::WorldConfig smallRigWorld() {
  synth::WorldConfig wc;
  wc.seed = 2;
  wc.route_length = 120;
  return wc;
}

// A rendered frame set of the small rig (no camera_infos) and cam0's true
// range, seen from the vehicle's pose at t = 3 s of smallRigWorld()'s drive.
inline CameraFrameSet renderedSet(const Rig& rig, cv::Mat* truth) {
  const synth::World world(smallRigWorld());
  const double t = 3.0;
  CameraFrameSet set;
  set.header.stamp = ros::Time(1700000003, 250000000);
  set.header.frame_id = rig.cameras[0].frame_id;
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    const auto& cam = rig.cameras[c];
    auto frame = world.render(cam.model, pixelRays(cam.model), world.egoPose(t) * cam.T_base_cam, t, 100 + c);
    if (c == 0) *truth = frame.depth;
    std_msgs::Header h;
    h.stamp = set.header.stamp;
    h.frame_id = cam.frame_id;
    set.camera_names.push_back(cam.name);
    set.images.push_back(*cv_bridge::CvImage(h, "mono8", frame.image).toImageMsg());
  }
  return set;
}

// The rig's mount as /tf_static carries it: base_link -> each camera's frame.
inline std::vector<geometry_msgs::TransformStamped> mountTransforms(const Rig& rig, const ros::Time& stamp) {
  std::vector<geometry_msgs::TransformStamped> mount;
  for (const auto& cam : rig.cameras) {
    geometry_msgs::TransformStamped t = tf2::eigenToTransform(cam.T_base_cam);
    t.header.stamp = stamp;
    t.header.frame_id = "base_link";
    t.child_frame_id = cam.frame_id;
    mount.push_back(t);
  }
  return mount;
}

// The CameraInfo of each small-rig camera, written out from
// test/data/small_rig_camchain.yaml (all three alike, and the same as
// small_fisheye_camchain.yaml's cam0): omni, D = [xi, k1, k2, p1, p2], K from
// [xi, fx, fy, cx, cy], 256 x 136.
inline sensor_msgs::CameraInfo smallRigInfo(const std_msgs::Header& header) {
  sensor_msgs::CameraInfo info;
  info.header = header;
  info.width = 256;
  info.height = 136;
  info.distortion_model = "omni";
  info.D = {0.98, -0.02, 0.004, 0.0002, -0.0001};
  info.K = {130.0, 0.0, 127.5, 0.0, 130.0, 67.5, 0.0, 0.0, 1.0};
  info.R = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  info.P = {130.0, 0.0, 127.5, 0.0, 0.0, 130.0, 67.5, 0.0, 0.0, 0.0, 1.0, 0.0};
  return info;
}

}  // namespace test
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_TEST_SMALL_RIG_FRAMES_H_
