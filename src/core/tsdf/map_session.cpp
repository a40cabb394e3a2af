#include "fisheye_mapping/core/tsdf/map_session.h"

#include <filesystem>
#include <system_error>
#include <utility>

#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fisheye_mapping {

MapSession::MapSession(std::string path, Log log) : path_(std::move(path)), log_(std::move(log)) {
  if (!log_) log_ = [](bool, const std::string&) {};
}

bool MapSession::start(TsdfMap& map, bool reload) {
  if (!enabled()) return false;
  std::error_code ec;
  if (reload) {
    for (const std::string& p : {path_, path_ + ".1"}) {
      if (!std::filesystem::exists(p, ec)) continue;
      try {
        map.load(p);
        ++changes_;
        if (p == path_) {
          saved_changes_ = changes_;
        } else {
          keep_previous_ = false;  // the main file is bad: the next save replaces it, .1 stays
        }
        log_(false, "resumed the map from " + p + ": " + std::to_string(map.numBlocks()) + " blocks");
        return true;
      } catch (const std::exception& e) {
        log_(true, "cannot resume from " + p + ": " + e.what());
      }
    }
    log_(false, "reload_map_on_start: no loadable map at " + path_ + " (or " + path_ + ".1); starting empty");
    return false;
  }
  try {
    if (std::filesystem::exists(path_, ec)) {
      const MapFileInfo info = TsdfMap::readHeader(path_);
      if (info.num_blocks > 0) {
        log_(false, path_ + " holds a map of " + std::to_string(info.num_blocks) +
                        " blocks and reload_map_on_start is false: this map starts empty; an empty map never "
                        "replaces it, and the first save keeps it as " +
                        path_ + ".1");
      }
    }
  } catch (const std::exception& e) {
    log_(false, path_ + " is not a readable map (" + e.what() + "); the first save keeps it as " + path_ + ".1");
  }
  return false;
}

bool MapSession::save(TsdfMap& map, const std::string& why) {
  if (!enabled()) return false;
  MapSaveOptions options;
  options.refuse_empty_overwrite = true;
  options.keep_previous = keep_previous_;
  try {
    const size_t changes = changes_;
    std::error_code ec;
    const bool kept = options.keep_previous && std::filesystem::is_regular_file(path_, ec);
    map.save(path_, options);
    keep_previous_ = false;
    saved_changes_ = changes;
    ++saves_ok_;
    log_(false, why + ": map saved to " + path_ + " (" + std::to_string(map.numBlocks()) + " blocks" +
                    (kept ? ", the file found there kept as .1)" : ")"));
    return true;
  } catch (const std::exception& e) {
    ++saves_failed_;
    {
      std::lock_guard<std::mutex> lock(error_mutex_);
      last_error_ = e.what();
    }
    log_(true, why + ": map not saved: " + e.what());
    return false;
  }
}

bool MapSession::autosave(TsdfMap& map) {
  // An empty map is never worth a file (and never replaces one).
  if (!enabled() || unchanged() || map.numBlocks() == 0) return false;
  return save(map, "autosave");
}

void MapSession::shutdown(TsdfMap& map) {
  if (!enabled()) return;
  if (unchanged()) {
    log_(false, "map unchanged since it was saved to / loaded from " + path_ + ": not rewritten");
    return;
  }
  save(map, "shutdown");
}

std::string MapSession::lastError() const {
  std::lock_guard<std::mutex> lock(error_mutex_);
  return last_error_;
}

}  // namespace fisheye_mapping
