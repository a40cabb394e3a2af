// Output paths given by users (service requests, parameters, command lines):
// one place that decides what "mesh.ply" or "~/maps/a.fmtsdf" means, so that
// every stage writes where the user expects and says where it wrote.
#ifndef FISHEYE_MAPPING_CORE_COMMON_PATHS_H_
#define FISHEYE_MAPPING_CORE_COMMON_PATHS_H_

#include <string>

namespace fisheye_mapping {

// The absolute, lexically normalized path a file named `path` is written to:
// a leading "~/" (or a lone "~") is the home directory ($HOME); a relative
// path is taken relative to `base_dir` (itself made absolute against the
// current directory; empty: the current directory); "." and ".." are folded
// without touching the file system (symbolic links stay as named).
// Throws std::invalid_argument naming the path when it is empty, when it ends
// in a separator or names an existing directory (a file path is needed), or
// when "~" is used while $HOME is unset. Nothing is created.
std::string resolveOutputPath(const std::string& path, const std::string& base_dir);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_PATHS_H_
