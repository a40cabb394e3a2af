// FilePath services of a stage (the TSDF's save_mesh / save_cloud / save_map
// / load_map): the requested path is resolved against the stage's save
// folder (a save is confined to it, core/common/safe_write.h; a load is
// relative to it; empty: an error), the stage's function runs on it under the
// stage's lock, and the response and the log say what was done where, or why
// not (the OS error of a failed write among it). Failures are counted.
#ifndef FISHEYE_MAPPING_ROS_FILE_SERVICES_H_
#define FISHEYE_MAPPING_ROS_FILE_SERVICES_H_

#include <atomic>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include <ros/node_handle.h>

#include "fisheye_mapping/FilePath.h"
#include "fisheye_mapping/core/common/safe_write.h"

namespace fisheye_mapping {

class FilePathServices {
 public:
  using Log = std::function<void(bool error, const std::string& message)>;
  enum class Access { kSave, kLoad };

  // `ready`: false when the stage did not start (requests are answered so).
  FilePathServices(ros::NodeHandle pnh, SaveFolder folder, std::mutex& mutex, std::function<bool()> ready, Log log)
      : pnh_(pnh), folder_(std::move(folder)), mutex_(mutex), ready_(std::move(ready)), log_(std::move(log)) {}

  // Advertises ~name; `what` starts the messages ("save mesh to").
  void add(const std::string& name, const std::string& what, Access access,
           std::function<void(const std::string& path)> fn);

  // Advertises ~name as a std_srvs/Trigger running fn under the same lock and
  // log ("<what>: done", or "<what> failed: <error>", counted).
  void addTrigger(const std::string& name, const std::string& what, std::function<void()> fn);

  // Runs one request as the service does (also for tests and tools).
  void run(fisheye_mapping::FilePath::Response& res, const std::string& requested, const std::string& what,
           Access access, const std::function<void(const std::string&)>& fn);

  const SaveFolder& folder() const { return folder_; }
  size_t failures() const { return failures_; }

 private:
  ros::NodeHandle pnh_;
  SaveFolder folder_;
  std::mutex& mutex_;
  std::function<bool()> ready_;
  // One request under the stage's lock, if the stage started: fn returns the
  // reply on success; a failure is "<failure>: <error>", logged and counted.
  bool attempt(std::string* reply, const std::string& failure, const std::function<std::string()>& fn);

  Log log_;
  std::atomic<size_t> failures_{0};
  std::vector<ros::ServiceServer> servers_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_FILE_SERVICES_H_
