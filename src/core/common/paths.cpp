#include "fisheye_mapping/core/common/paths.h"

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

namespace fisheye_mapping {
namespace {

namespace fs = std::filesystem;

// `path` with a leading "~" or "~/" replaced by $HOME ("~user" is left alone:
// it is an ordinary relative name here, as in most config files).
fs::path expandHome(const std::string& path) {
  if (path != "~" && path.rfind("~/", 0) != 0) return fs::path(path);
  const char* home = std::getenv("HOME");
  if (!home || !*home) {
    throw std::invalid_argument("output path '" + path + "': cannot expand '~', HOME is not set");
  }
  return fs::path(home) / path.substr(path.size() > 1 ? 2 : 1);
}

}  // namespace

std::string resolveOutputPath(const std::string& path, const std::string& base_dir) {
  if (path.empty()) throw std::invalid_argument("output path is empty: give a file name (e.g. map.fmtsdf)");
  fs::path p = expandHome(path);
  if (p.is_relative()) {
    const fs::path base = base_dir.empty() ? fs::current_path() : fs::absolute(fs::path(base_dir));
    p = base / p;
  }
  p = p.lexically_normal();
  // "a/b/" or "a/.." name a directory whether or not it exists.
  if (!p.has_filename()) {
    throw std::invalid_argument("output path '" + path + "' (" + p.string() + ") names a directory, not a file");
  }
  std::error_code ec;
  if (fs::is_directory(p, ec)) {
    throw std::invalid_argument("output path '" + path + "' (" + p.string() +
                                ") is an existing directory; give a file name inside it");
  }
  return p.string();
}

}  // namespace fisheye_mapping
