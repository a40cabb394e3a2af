// Paced playback of a logged drive (no ROS): decides, message by message in
// the bag's order, when a player has to wait for the pipeline before it
// publishes, so that every frame set is mapped at whatever speed the machine
// has.
//
// A frame set begins with a new stamp on the reference camera's image topic.
// At most `in_flight` frame sets are in the pipeline at once: before the
// reference image of set k+1 goes out, the player waits until the pipeline
// has finished set k+1-in_flight (the TSDF stage acknowledges each depth
// frame by its stamp, the reference image's). With 1, each set waits for the
// one before; with 2 (vehicle.launch's default) the depth of set k+1 is
// computed while set k is detected, masked and fused, as the stages run on
// a live car. The second set always waits for the first (the pipeline's
// first set builds its rig and starts its workers). Everything else is published in bag order: the other cameras'
// images of set k+1 (the sync holds them until the reference arrives) and the
// poses up to set k+1's time, so that the pose of set k can be interpolated
// before its depth is fused. At the end of the drive, unwaited() lists the
// sets still to wait for.
//
// Not thread-safe.
#ifndef FISHEYE_MAPPING_CORE_SYNC_FRAME_PACER_H_
#define FISHEYE_MAPPING_CORE_SYNC_FRAME_PACER_H_

#include <deque>
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
  // Throws std::invalid_argument when the reference is not one of them, a
  // topic is listed twice, or in_flight is not 1 to 16.
  FramePacer(const std::string& reference_topic, const std::vector<std::string>& image_topics, int in_flight = 1);

  // The next message of the bag: its topic and header stamp in seconds
  // (messages without a header: any stamp, only image topics are looked at).
  Step next(const std::string& topic, double stamp);

  bool isImageTopic(const std::string& topic) const { return last_.count(topic) > 0; }
  // Frame sets begun so far (reference images with a new stamp).
  int framesBegun() const { return frames_; }
  // Stamps of the sets begun and not yet waited for (at most in_flight), oldest first.
  std::vector<double> unwaited() const { return std::vector<double>(open_.begin(), open_.end()); }

 private:
  std::string reference_;
  std::map<std::string, double> last_;  // image topic -> last stamp (-inf before any)
  int frames_ = 0;
  int in_flight_;
  std::deque<double> open_;  // sets begun, not yet waited for
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_SYNC_FRAME_PACER_H_
