// libFuzzer target: the TSDF map file loader (TsdfMap::load, public API only).
// Each input is written to a file and loaded twice: as it is (header and
// record CRCs must catch corruption), and, for a version-2 or version-3 file,
// with its CRCs recomputed from the layout documented in
// src/core/tsdf/tsdf_io.cpp, so that the checks behind the CRCs (block count
// against the file size, version 3's zlib streams and voxel masks, finite
// voxels, |tsdf| <= 1, weights, block indices, duplicates) are reached too.
// Allowed outcomes: std::runtime_error naming the file (map unchanged), or a
// map whose every voxel obeys the documented limits.
//
// With FM_FUZZ_SEED_DIR set, the first run writes fresh seeds there (a map
// saved by the current code: version 3, the same as version 2 and as
// version 1), so the corpus follows the file format.
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fm = fisheye_mapping;

#ifndef FM_FUZZ_IN_GTEST
// The OpenCL sources are not needed to load a map (the CPU integrator); the
// fuzz build compiles the core sources without the generated table.
namespace fisheye_mapping {
const std::map<std::string, std::string>& embeddedClSources() {
  static const std::map<std::string, std::string> none;
  return none;
}
}  // namespace fisheye_mapping
#endif

namespace {

constexpr size_t kHeaderV2 = 44, kHeaderV1 = 36, kRecordV1 = 12 + 512 * 8, kRecordV2 = kRecordV1 + 4;
constexpr size_t kHeadV3 = 16;  // index, compressed size

const std::string& path() {
  static const std::string p = "/tmp/fm_fuzz_tsdf_" + std::to_string(getpid()) + ".map";
  return p;
}

[[noreturn]] void finding(const std::string& what) {
  std::fprintf(stderr, "fuzz_tsdf_map_file: %s\n", what.c_str());
  std::abort();
}

void write(const std::string& p, const std::vector<uint8_t>& bytes) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

void loadAndCheck(const std::vector<uint8_t>& bytes) {
  write(path(), bytes);
  fm::TsdfConfig cfg;  // 5 cm voxels, 4 voxels truncation: the seeds' values
  cfg.max_weight = 100.0f;
  fm::TsdfMap map(cfg);
  try {
    map.load(path());
  } catch (const std::runtime_error& e) {
    if (std::string(e.what()).find(path()) == std::string::npos) finding(std::string("error without the path: ") + e.what());
    if (map.numBlocks() != 0) finding("a failed load changed the map");
    return;
  }
  for (const fm::BlockIndex& b : map.allBlocks()) {
    const fm::VoxelBlock* block = map.block(b);
    if (!block) finding("listed block missing");
    for (const fm::FmVoxel& v : block->voxels) {
      if (!std::isfinite(v.tsdf) || std::abs(v.tsdf) > 1.0f) finding("voxel tsdf out of [-1, 1]");
      if (!std::isfinite(v.weight) || v.weight < 0.0f) finding("voxel weight negative or non-finite");
    }
  }
}

// Recomputes the header and record CRCs of a version-2 or version-3 file
// (version 3: record by record while each record's size fits in the file).
std::vector<uint8_t> withFixedCrcs(std::vector<uint8_t> b) {
  if (b.size() < kHeaderV2 || std::memcmp(b.data(), "FMTSDF01", 8) != 0) return {};
  uint32_t version = 0;
  std::memcpy(&version, b.data() + 8, 4);
  if (version != 2 && version != 3) return {};
  uint32_t crc = fm::crc32(b.data(), 40);
  std::memcpy(b.data() + 40, &crc, 4);
  for (size_t at = kHeaderV2; at + kHeadV3 <= b.size();) {
    uint32_t packed = 0;
    std::memcpy(&packed, b.data() + at + 12, 4);
    const size_t payload = version == 2 ? kRecordV1 : kHeadV3 + static_cast<size_t>(packed);
    if (payload + 4 > b.size() - at) break;
    crc = fm::crc32(b.data() + at, payload);
    std::memcpy(b.data() + at + payload, &crc, 4);
    at += payload + 4;
  }
  return b;
}

[[maybe_unused]] void writeSeeds(const std::string& dir) {
  fm::TsdfConfig cfg;
  fm::TsdfMap map(cfg);
  fm::Intrinsics in;
  // One pixel: a ray through a couple of blocks, a file of a few kB.
  in.width = 1, in.height = 1, in.fx = 40, in.fy = 40, in.cx = 0, in.cy = 0;
  const fm::CameraModel cam = fm::CameraModel::pinhole(in);
  cv::Mat depth(1, 1, CV_32FC1, cv::Scalar(2.0f));
  map.integrate(depth, cam, Eigen::Isometry3d::Identity(), Eigen::Vector3d::Zero());
  map.save(dir + "/fresh_v3.map");
  const std::string v2 = dir + "/fresh_v2.map";
  fm::MapSaveOptions two;
  two.format_version = 2;
  map.save(v2, two);
  std::ifstream f(v2, std::ios::binary);
  std::vector<uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (b.size() < kHeaderV2) return;
  // Version 1: the header's first 36 bytes, records without CRCs.
  std::vector<uint8_t> v1(b.begin(), b.begin() + kHeaderV1);
  const uint32_t one = 1;
  std::memcpy(v1.data() + 8, &one, 4);
  for (size_t at = kHeaderV2; at + kRecordV2 <= b.size(); at += kRecordV2)
    v1.insert(v1.end(), b.begin() + at, b.begin() + at + kRecordV1);
  write(dir + "/fresh_v1.map", v1);
}

}  // namespace

#ifndef FM_FUZZ_IN_GTEST
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("FM_FUZZ_SEED_DIR")) {
    try {
      writeSeeds(dir);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "fuzz_tsdf_map_file: no fresh seeds: %s\n", e.what());
    }
  }
  return 0;
}
#endif

// The normal suite (test/test_fuzz_regressions.cpp) links this file with the
// entry point renamed by FM_FUZZ_ENTRY and replays test/fuzz/<target>/.
#ifndef FM_FUZZ_ENTRY
#define FM_FUZZ_ENTRY LLVMFuzzerTestOneInput
#endif
extern "C" int FM_FUZZ_ENTRY(const uint8_t* data, size_t size) {
  const std::vector<uint8_t> bytes(data, data + size);
  loadAndCheck(bytes);
  const std::vector<uint8_t> fixed = withFixedCrcs(bytes);
  if (!fixed.empty() && fixed != bytes) loadAndCheck(fixed);
  std::remove(path().c_str());
  return 0;
}
