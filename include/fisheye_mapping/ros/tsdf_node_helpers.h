// Node-level policy of the Tsdf nodelet kept out of its class
// (header-only, used by the Tsdf and Depth nodelets): where
// the save services write (the save folder) and SIGTERM handling.
#ifndef FISHEYE_MAPPING_ROS_TSDF_NODE_HELPERS_H_
#define FISHEYE_MAPPING_ROS_TSDF_NODE_HELPERS_H_

#include <signal.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>

#include <opencv2/core.hpp>
#include <ros/init.h>

#include "fisheye_mapping/core/common/paths.h"
#include "fisheye_mapping/core/common/safe_write.h"
#include "fisheye_mapping/ros/node_options.h"

namespace fisheye_mapping {
namespace tsdf_node {

// The folder relative output paths are taken against: $ROS_HOME, else
// $HOME/.ros (where roslaunch and rosout put their files too, and the
// working directory of a node started by roslaunch). Throws
// std::invalid_argument when neither ROS_HOME nor HOME is set.
inline std::string rosHome() {
  const char* ros_home = std::getenv("ROS_HOME");
  if (ros_home && *ros_home) return ros_home;
  const char* home = std::getenv("HOME");
  if (!home || !*home) throw std::invalid_argument("neither ROS_HOME nor HOME is set: cannot resolve a relative path");
  return std::string(home) + "/.ros";
}

// The save folder of ~save_directory / ~allow_any_save_path: relative
// against rosHome(). Throws std::invalid_argument when it is empty.
inline SaveFolder saveFolder(const SaveOptions& options) {
  if (options.save_directory.empty()) {
    throw std::invalid_argument("~save_directory is empty: give the folder saves may write into");
  }
  const std::filesystem::path dir(options.save_directory);
  return SaveFolder{(dir.is_absolute() ? dir : std::filesystem::path(rosHome()) / dir).lexically_normal().string(),
                    options.allow_any_save_path};
}

// A file to read (load_map) named in a request: absolute, or relative to the
// save folder (where a save with the same name wrote it).
inline std::string inputPath(const std::string& path, const SaveFolder& folder) {
  return resolveOutputPath(path, folder.directory);
}

// SIGTERM. roscpp installs a handler for SIGINT only; a SIGTERM (kill,
// systemd, docker stop, roslaunch's escalation) ended a nodelet manager at
// once, without unloading its nodelets: no map saved. While a Tsdf lives
// in the process and SIGTERM still has its default action, SIGTERM asks roscpp
// to shut down exactly as its own SIGINT handler does (ros::requestShutdown
// only sets a flag, which roscpp's poll thread acts on: async-signal-safe).
// The manager then unloads its nodelets and their destructors save. The
// last Tsdf to go puts the previous disposition back.
struct SigtermState {
  std::mutex mutex;
  int users = 0;
  bool installed = false;
  struct sigaction previous;
};
inline SigtermState& sigtermState() {
  static SigtermState state;
  return state;
}
inline void onSigterm(int) { ros::requestShutdown(); }

// Returns a description of what was done.
inline std::string acquireSigterm() {
  SigtermState& s = sigtermState();
  std::lock_guard<std::mutex> lock(s.mutex);
  ++s.users;
  if (s.installed) return "SIGTERM handler already installed";
  struct sigaction current;
  if (sigaction(SIGTERM, nullptr, &current) != 0) return std::string("cannot read SIGTERM's handler: ") + std::strerror(errno);
  if ((current.sa_flags & SA_SIGINFO) || current.sa_handler != SIG_DFL) {
    return "SIGTERM already has a handler in this process; left as it is";
  }
  struct sigaction sa;
  std::memset(&sa, 0, sizeof(sa));
  sa.sa_handler = &onSigterm;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  if (sigaction(SIGTERM, &sa, &s.previous) != 0) return std::string("cannot install a SIGTERM handler: ") + std::strerror(errno);
  s.installed = true;
  return "SIGTERM shuts down like SIGINT (the map is saved)";
}

inline void releaseSigterm() {
  SigtermState& s = sigtermState();
  std::lock_guard<std::mutex> lock(s.mutex);
  if (--s.users > 0 || !s.installed) return;
  struct sigaction current;
  if (sigaction(SIGTERM, nullptr, &current) == 0 && !(current.sa_flags & SA_SIGINFO) &&
      current.sa_handler == &onSigterm) {
    sigaction(SIGTERM, &s.previous, nullptr);
  }
  s.installed = false;
}

}  // namespace tsdf_node
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_TSDF_NODE_HELPERS_H_
