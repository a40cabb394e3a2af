// The persistence policy of a long-running map (the TSDF nodelet's
// save_map_on_shutdown, reload_map_on_start, autosave_period), without ROS:
//   - one file, saved on shutdown and by autosave, only when the map changed
//     since it was last saved to or loaded from that file;
//   - never an empty map over a non-empty file (a respawn after kill -9 starts
//     empty);
//   - the first save of a run keeps the file found there as <path>.1;
//   - on start, resume from the file, or from <path>.1 when the file is bad
//     (the next save then replaces the bad file and leaves .1 alone).
// Messages (what was saved, why nothing was) go to the caller's log function.
// Not thread-safe, except the counters and lastError(): the caller holds its
// map's lock around every other call.
#ifndef FISHEYE_MAPPING_CORE_TSDF_MAP_SESSION_H_
#define FISHEYE_MAPPING_CORE_TSDF_MAP_SESSION_H_

#include <atomic>
#include <cstddef>
#include <functional>
#include <mutex>
#include <string>

namespace fisheye_mapping {

class TsdfMap;

class MapSession {
 public:
  // error: true for failures, false for information.
  using Log = std::function<void(bool error, const std::string& message)>;

  // `path`: the map file (absolute); empty: no persistence (every call but
  // changed() does nothing).
  MapSession(std::string path, Log log);

  bool enabled() const { return !path_.empty(); }
  const std::string& path() const { return path_; }

  // At start-up, `map` empty. With `reload`: loads the file, or its .1 when
  // the file is missing or bad, and returns whether one was loaded; without:
  // says what the first save will do with a map found there, returns false.
  bool start(TsdfMap& map, bool reload);
  // The map changed (frames fused, a load or a clear through a service).
  void changed() { ++changes_; }
  // No change since the last save to / load from the file.
  bool unchanged() const { return changes_ == saved_changes_; }
  // Saves now (`why` prefixes the message); false (and logged, counted) when
  // the save failed or was refused (an empty map over a non-empty file).
  bool save(TsdfMap& map, const std::string& why);
  // Saves when the map changed and is not empty; returns whether it saved.
  bool autosave(TsdfMap& map);
  // On shutdown: saves unless unchanged (then says so).
  void shutdown(TsdfMap& map);

  size_t savesOk() const { return saves_ok_; }
  size_t savesFailed() const { return saves_failed_; }
  std::string lastError() const;

 private:
  std::string path_;
  Log log_;
  bool keep_previous_ = true;  // the first save keeps the file found there as .1
  size_t changes_ = 0;
  size_t saved_changes_ = static_cast<size_t>(-1);  // -1: never saved / loaded
  std::atomic<size_t> saves_ok_{0}, saves_failed_{0};
  mutable std::mutex error_mutex_;
  std::string last_error_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_MAP_SESSION_H_
