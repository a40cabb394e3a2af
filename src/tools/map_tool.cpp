// map_tool: inspect, check and convert saved TSDF maps (the Tsdf
// nodelet's ~save_map / save_map_on_shutdown files) offline, through the same
// validating loader the nodelet uses.
//
//   map_tool info MAP                       header, then contents (if valid)
//   map_tool check MAP                      exit 0 valid, 1 invalid (reason on stderr)
//   map_tool convert MAP OUT.ply|OUT.pcd    mesh (PLY) or surface cloud (PCD)
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"

namespace fm = fisheye_mapping;

namespace {

const char* kUsage =
    "usage: map_tool info MAP [--max-weight W]\n"
    "       map_tool check MAP [--max-weight W]\n"
    "       map_tool convert MAP OUT.ply|OUT.pcd [--min-observations N] [--max-weight W]\n"
    "  info     prints the file's header (format version, voxel size, truncation,\n"
    "           weight cap, block count) and, if the map is valid, its extent and\n"
    "           voxel counts.\n"
    "  check    validates the whole file (checksums, block count, voxel values,\n"
    "           block indices, duplicates): exit 0 if valid, 1 if not (the\n"
    "           reason on stderr).\n"
    "  convert  writes the marching-cubes mesh (.ply) or the surface cloud\n"
    "           (.pcd) of voxels observed at least N times.\n"
    "  --min-observations N  (convert) N >= 1, default 3.\n"
    "  --max-weight W  the weight cap to check version-1 files against (they do\n"
    "           not store it; default 100, the nodelet's default). Version-2\n"
    "           files carry their own.\n"
    "Exit status: 0 done / valid, 1 invalid map or failure, 2 bad arguments.\n";

int usage(const std::string& error) {
  std::cerr << "map_tool: " << error << "\n" << kUsage;
  return 2;
}

bool parseDouble(const std::string& s, double* out) {
  try {
    size_t used = 0;
    *out = std::stod(s, &used);
    return used == s.size() && std::isfinite(*out);
  } catch (const std::exception&) {
    return false;
  }
}

bool parseInt(const std::string& s, int* out) {
  try {
    size_t used = 0;
    const long v = std::stol(s, &used);
    if (used != s.size() || v < std::numeric_limits<int>::min() || v > std::numeric_limits<int>::max()) return false;
    *out = static_cast<int>(v);
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

std::string extensionOf(const std::string& path) {
  const size_t dot = path.find_last_of('.');
  const size_t slash = path.find_last_of('/');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot + 1);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

// Loads MAP through the core loader with the file's own geometry.
std::unique_ptr<fm::TsdfMap> loadMap(const std::string& path, const fm::MapFileInfo& info, double max_weight_v1) {
  fm::TsdfConfig cfg;
  cfg.voxel_size = info.voxel_size;
  cfg.truncation_voxels = info.truncation_voxels;
  cfg.max_weight = info.version >= 2 ? info.max_weight : static_cast<float>(max_weight_v1);
  auto map = std::make_unique<fm::TsdfMap>(cfg);  // no local map centre yet: every block stays active
  map->load(path);
  return map;
}

void printHeader(const std::string& path, const fm::MapFileInfo& info) {
  std::printf("file:              %s\n", path.c_str());
  std::printf("size:              %llu bytes\n", static_cast<unsigned long long>(info.file_size));
  std::printf("format version:    %u%s\n", info.version, info.version == 1 ? " (no checksums)" : "");
  std::printf("voxel size:        %g m\n", info.voxel_size);
  std::printf("truncation:        %g voxels (%g m)\n", info.truncation_voxels, info.truncation_voxels * info.voxel_size);
  if (info.version >= 2) {
    std::printf("max weight:        %g\n", info.max_weight);
  } else {
    std::printf("max weight:        not stored\n");
  }
  std::printf("blocks (header):   %llu\n", static_cast<unsigned long long>(info.num_blocks));
}

void printContents(const fm::TsdfMap& map, int min_observations) {
  const double bs = map.config().blockSize();
  Eigen::Vector3i lo = Eigen::Vector3i::Constant(std::numeric_limits<int>::max());
  Eigen::Vector3i hi = Eigen::Vector3i::Constant(std::numeric_limits<int>::min());
  size_t observed = 0, confirmed = 0;
  double weight_sum = 0;
  for (const fm::BlockIndex& b : map.allBlocks()) {
    lo = lo.cwiseMin(b);
    hi = hi.cwiseMax(b);
    const fm::VoxelBlock* blk = map.block(b);
    if (!blk) continue;
    for (const auto& v : blk->voxels) {
      if (v.weight > 0) ++observed, weight_sum += v.weight;
      if (v.weight >= fm::minObservationWeight(min_observations)) ++confirmed;
    }
  }
  std::printf("blocks:            %zu (%.1f MB of voxels)\n", map.numBlocks(),
              map.numBlocks() * sizeof(fm::VoxelBlock) / 1e6);
  if (map.numBlocks() > 0) {
    std::printf("extent:            x %.2f .. %.2f, y %.2f .. %.2f, z %.2f .. %.2f m\n", lo.x() * bs,
                (hi.x() + 1) * bs, lo.y() * bs, (hi.y() + 1) * bs, lo.z() * bs, (hi.z() + 1) * bs);
  }
  std::printf("observed voxels:   %zu (mean weight %.2f)\n", observed, observed ? weight_sum / observed : 0.0);
  std::printf("voxels with >= %d observations: %zu\n", min_observations, confirmed);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> positional;
  double max_weight_v1 = fm::TsdfConfig().max_weight;
  int min_observations = fm::TsdfConfig().min_observations;
  bool have_min_obs = false;
  const int rc = fm::cli::parseCommandLine("map_tool", kUsage, [&] {
    fm::cli::forEachOption(argc, argv, 1, [&](const std::string& a, const fm::cli::NextValue& next) {
      if (a == "--max-weight") {
        const std::string v = next();
        if (!parseDouble(v, &max_weight_v1) || !(max_weight_v1 > 0))
          throw fm::cli::UsageError("--max-weight needs a positive number, got '" + v + "'");
      } else if (a == "--min-observations") {
        const std::string v = next();
        if (!parseInt(v, &min_observations) || min_observations < 1)
          throw fm::cli::UsageError("--min-observations needs an integer >= 1, got '" + v + "'");
        have_min_obs = true;
      } else if (a.size() <= 1 || a[0] != '-') {
        positional.push_back(a);
      } else {
        return false;
      }
      return true;
    });
  });
  if (rc >= 0) return rc;
  if (positional.empty()) return usage("no command");
  const std::string command = positional[0];
  size_t expected = 0;
  if (command == "info" || command == "check") {
    expected = 2;
  } else if (command == "convert") {
    expected = 3;
  } else {
    return usage("unknown command '" + command + "'");
  }
  if (positional.size() < expected) return usage(command + ": missing argument");
  if (positional.size() > expected) return usage(command + ": unexpected argument '" + positional[expected] + "'");
  if (have_min_obs && command != "convert") return usage("--min-observations applies to convert only");
  const std::string path = positional[1];

  std::string out, ext;
  if (command == "convert") {
    out = positional[2];
    ext = extensionOf(out);
    if (ext != "ply" && ext != "pcd") return usage("convert: the output must end in .ply (mesh) or .pcd (cloud): " + out);
    if (out == path) return usage("convert: the output would overwrite the map");
  }

  fm::MapFileInfo info;
  try {
    info = fm::TsdfMap::readHeader(path);
  } catch (const std::exception& e) {
    std::cerr << "map_tool: invalid: " << e.what() << "\n";
    if (command == "check") std::printf("invalid: %s\n", e.what());
    return 1;
  }
  if (command == "info") printHeader(path, info);
  try {
    const std::unique_ptr<fm::TsdfMap> map = loadMap(path, info, max_weight_v1);
    if (command == "check") {
      std::printf("valid: %s: format version %u, %zu blocks, voxel %g m\n", path.c_str(), info.version,
                  map->numBlocks(), info.voxel_size);
      return 0;
    }
    if (command == "info") {
      std::printf("valid:             yes\n");
      printContents(*map, min_observations);
      return 0;
    }
    fm::TsdfMesher mesher(min_observations);
    mesher.rebuild(*map);
    if (ext == "ply") {
      mesher.saveMeshPly(out);
      std::printf("wrote %zu triangles to %s\n", mesher.numTriangles(), out.c_str());
    } else {
      mesher.saveCloudPcd(out);
      std::printf("wrote %zu points to %s\n", mesher.surfaceCloud().size(), out.c_str());
    }
    return 0;
  } catch (const std::exception& e) {
    if (command == "info") std::printf("valid:             no\n");
    if (command == "check") std::printf("invalid: %s\n", e.what());
    std::cerr << "map_tool: " << (command == "convert" ? "" : "invalid: ") << e.what() << "\n";
    return 1;
  }
}
