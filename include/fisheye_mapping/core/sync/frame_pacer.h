// Paced playback of a logged drive (no ROS): decides, message by message in
// the bag's order, when a player has to wait for the pipeline before it
// publishes, so that every frame set is mapped at whatever speed the machine
// has.
//
// A frame set begins with a new stamp on the reference camera's image topic.
// Before the reference image of set k+1 goes out, the player waits until the
// pipeline has finished set k (the TSDF stage acknowledges each depth frame
// by its stamp, the reference image's). Everything else is published in bag
// order: the other cameras' images of set k+1 (the sync holds them until the
// reference arrives) and the poses up to set k+1's time, so that the pose of
// set k can be interpolated before its depth is fused.
//
// Not thread-safe.
#ifndef FISHEYE_MAPPING_CORE_SYNC_FRAME_PACER_H_
#define FISHEYE_MAPPING_CORE_SYNC_FRAME_PACER_H_

#include <map>
#include <string>
#include <vector>

namespace fisheye_mapping {

class FramePacer {
 public:
  struct Step {
    enum Kind {
      kPublish,          // publish now
      kWaitThenPublish,  // wait for the pipeline to finish set `wait_for`, then publish
      kStampsBackwards,  // stop: `error` names the topic and the stamps
    };
    Kind kind = kPublish;
    double wait_for = 0.0;  // stamp (s) of the frame set to wait for
    std::string error;
  };

  // image_topics: every camera's image topic, the reference among them.
  // Throws std::invalid_argument when the reference is not one of them or a
  // topic is listed twice.
  FramePacer(const std::string& reference_topic, const std::vector<std::string>& image_topics);

  // The next message of the bag: its topic and header stamp in seconds
  // (messages without a header: any stamp, only image topics are looked at).
  Step next(const std::string& topic, double stamp);

  bool isImageTopic(const std::string& topic) const { return last_.count(topic) > 0; }
  // Frame sets begun so far (reference images with a new stamp).
  int framesBegun() const { return frames_; }

 private:
  std::string reference_;
  std::map<std::string, double> last_;  // image topic -> last stamp (-inf before any)
  int frames_ = 0;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_SYNC_FRAME_PACER_H_
