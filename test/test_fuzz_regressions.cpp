// Replays every input of the fuzz corpora test/fuzz/<target>/ (the seeds and
// each crash the fuzzers found, kept as regress-* files) through the fuzz
// targets' own checks, built here with the normal compiler: a parser that
// crashes, throws the wrong exception or breaks a checked invariant on any of
// them aborts this test. scripts/checks/fuzz runs the targets themselves with clang.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern "C" int fmFuzzRigYaml(const uint8_t* data, size_t size);
extern "C" int fmFuzzPslCalib(const uint8_t* data, size_t size);
extern "C" int fmFuzzTsdfMapFile(const uint8_t* data, size_t size);
extern "C" int fmFuzzRigInfoLines(const uint8_t* data, size_t size);

namespace {

// Feeds each file of test/fuzz/<target>/ to `entry`; returns the count.
size_t replay(const std::string& target, int (*entry)(const uint8_t*, size_t)) {
  namespace fs = std::filesystem;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(std::string(FM_FUZZ_DIR) + "/" + target))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    std::ifstream in(f, std::ios::binary);
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    // Named before the call: a crash shows which input it was.
    std::fprintf(stderr, "[ replay   ] %s\n", f.filename().c_str());
    entry(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  }
  return files.size();
}

TEST(FuzzRegressions, RigYaml) { EXPECT_GE(replay("rig_yaml", fmFuzzRigYaml), 3u); }
TEST(FuzzRegressions, PslCalib) { EXPECT_GE(replay("psl_calib", fmFuzzPslCalib), 2u); }
TEST(FuzzRegressions, TsdfMapFile) { EXPECT_GE(replay("tsdf_map_file", fmFuzzTsdfMapFile), 2u); }
TEST(FuzzRegressions, RigInfoLines) { EXPECT_GE(replay("rig_info_lines", fmFuzzRigInfoLines), 4u); }

}  // namespace
