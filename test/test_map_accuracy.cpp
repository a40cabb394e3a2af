// map_accuracy on bad input: a 0-byte PCD, NaN points in either cloud, a --csv
// into a missing folder, bad numbers; and a good run against hand-counted
// shares. Each bad input gives its exact message and exit status.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "tool_run.h"

namespace {

using fisheye_mapping::test::ToolRun;

ToolRun run(const std::string& args) { return fisheye_mapping::test::runTool(std::string(FM_MAP_ACCURACY) + " " + args); }

// An ASCII PCD of points given as "x y z" lines (nan allowed).
void writePcd(const std::string& path, const std::vector<std::string>& points) {
  std::ofstream f(path);
  f << "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " << points.size()
    << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << points.size() << "\nDATA ascii\n";
  for (const auto& p : points) f << p << "\n";
}

class MapAccuracy : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = "/tmp/fm_test_map_accuracy_" + std::to_string(getpid());
    std::system(("rm -rf " + dir_ + " && mkdir -p " + dir_).c_str());
    // Reference: 10 points on a line 1 m apart. Map: 8 of them exactly, one
    // 0.3 m off, one 2 m off.
    std::vector<std::string> ref, map;
    for (int i = 0; i < 10; ++i) ref.push_back(std::to_string(i) + " 0 0");
    for (int i = 0; i < 8; ++i) map.push_back(std::to_string(i) + " 0 0");
    map.push_back("8 0.3 0");
    map.push_back("9 2 0");
    writePcd(dir_ + "/ref.pcd", ref);
    writePcd(dir_ + "/map.pcd", map);
  }
  void TearDown() override { std::system(("rm -rf " + dir_).c_str()); }
  std::string dir_;
};

TEST_F(MapAccuracy, GoodCloudsGiveHandCountedShares) {
  const ToolRun r = run("--cloud " + dir_ + "/map.pcd --ref " + dir_ + "/ref.pcd --t 0.1,0.5 --csv " + dir_ + "/a.csv");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("10 map points, 10 reference points\n"), std::string::npos) << r.out;
  // Map -> ref: 8 exact, (8,0.3,0) at 0.3, (9,2,0) at 2: 80 % within 0.1,
  // 90 % within 0.5. Ref -> map: 0..7 exact, (8,0,0) at 0.3, (9,0,0) at
  // sqrt(1.09) from (8,0.3,0): the same shares.
  EXPECT_NE(r.out.find("| 0.10 | 80.0 % | 80.0 % |"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("| 0.50 | 90.0 % | 90.0 % |"), std::string::npos) << r.out;
  std::ifstream csv(dir_ + "/a.csv");
  std::string header, row;
  std::getline(csv, header);
  std::getline(csv, row);
  EXPECT_EQ(header, "t,scene_within,accuracy,completeness,points,ref_points,trails");
  EXPECT_EQ(row, "0.1,nan,0.8,0.8,10,10,0");
}

TEST_F(MapAccuracy, AgainstAMeshWithTrails) {
  // One triangle in z = 0 under all the map's points, and two points 1 m above it.
  std::ofstream(dir_ + "/scene.ply") << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                        "property float y\nproperty float z\nelement face 1\n"
                                        "property list uchar int vertex_indices\nend_header\n"
                                        "-1 -1 0\n20 -1 0\n-1 20 0\n3 0 1 2\n";
  std::vector<std::string> map;
  for (int i = 0; i < 8; ++i) map.push_back(std::to_string(i) + " 0 0");
  map.push_back("3 3 1");
  map.push_back("4 4 1");
  writePcd(dir_ + "/above.pcd", map);
  const ToolRun r = run("--cloud " + dir_ + "/above.pcd --mesh " + dir_ + "/scene.ply --t 0.1 --trail-tol 0.5");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("10 map points, 2 points farther than 0.500000 m from the scene (trail voxels)\n"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("| 0.10 | 80.0 % |"), std::string::npos) << r.out;
}

TEST_F(MapAccuracy, EmptyPcdIsAnErrorNotACrash) {
  std::ofstream(dir_ + "/empty.pcd").close();
  ToolRun r = run("--cloud " + dir_ + "/empty.pcd --ref " + dir_ + "/ref.pcd");
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("map_accuracy: " + dir_ + "/empty.pcd is empty (0 bytes), not a PCD cloud"), std::string::npos)
      << r.out;
  r = run("--cloud " + dir_ + "/map.pcd --ref " + dir_ + "/empty.pcd");
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find(dir_ + "/empty.pcd is empty (0 bytes)"), std::string::npos) << r.out;
  r = run("--cloud " + dir_ + "/map.pcd --mesh " + dir_ + "/empty.pcd");
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("map_accuracy: " + dir_ + "/empty.pcd is empty (0 bytes), not a PLY mesh"), std::string::npos)
      << r.out;
  // A header without points.
  writePcd(dir_ + "/none.pcd", {});
  r = run("--cloud " + dir_ + "/none.pcd --ref " + dir_ + "/ref.pcd");
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("has no finite point"), std::string::npos) << r.out;
}

TEST_F(MapAccuracy, NonFinitePointsAreSkippedAndCounted) {
  // The map with 30 NaN points added: the shares of the 10 finite points are
  // unchanged (not 10 / 40), and the count of skipped points is reported.
  std::vector<std::string> map;
  for (int i = 0; i < 8; ++i) map.push_back(std::to_string(i) + " 0 0");
  map.push_back("8 0.3 0");
  map.push_back("9 2 0");
  for (int i = 0; i < 30; ++i) map.push_back("nan nan nan");
  writePcd(dir_ + "/map_nan.pcd", map);
  std::vector<std::string> ref;
  for (int i = 0; i < 10; ++i) ref.push_back(std::to_string(i) + " 0 0");
  ref.push_back("nan 0 0");
  ref.push_back("1 nan 2");
  writePcd(dir_ + "/ref_nan.pcd", ref);
  const ToolRun r = run("--cloud " + dir_ + "/map_nan.pcd --ref " + dir_ + "/ref_nan.pcd --t 0.1");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("10 map points, 10 reference points; non-finite points skipped: 30 in " + dir_ +
                       "/map_nan.pcd, 2 in " + dir_ + "/ref_nan.pcd"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("| 0.10 | 80.0 % | 80.0 % |"), std::string::npos) << r.out;
  // Only NaN: nothing to measure.
  writePcd(dir_ + "/all_nan.pcd", {"nan nan nan", "nan 1 1"});
  const ToolRun n = run("--cloud " + dir_ + "/all_nan.pcd --ref " + dir_ + "/ref.pcd");
  EXPECT_EQ(n.status, 1) << n.out;
  EXPECT_NE(n.out.find(dir_ + "/all_nan.pcd has no finite point (2 non-finite)"), std::string::npos) << n.out;
}

TEST_F(MapAccuracy, BadOptionsAndPathsGiveExactErrors) {
  const std::string good = "--cloud " + dir_ + "/map.pcd --ref " + dir_ + "/ref.pcd";
  const struct {
    std::string args, expected;
    int status;
  } cases[] = {
      {good + " --csv " + dir_ + "/no/such/a.csv",
       "map_accuracy: --csv: " + dir_ + "/no/such/a.csv: no such folder " + dir_ + "/no/such", 2},
      {good + " --csv " + dir_, "map_accuracy: --csv: " + dir_ + " is a directory, expected a file", 2},
      {"--cloud " + dir_ + " --ref " + dir_ + "/ref.pcd",
       "map_accuracy: --cloud: " + dir_ + " is a directory, expected a file", 2},
      {"--cloud " + dir_ + "/nope.pcd --ref " + dir_ + "/ref.pcd",
       "map_accuracy: --cloud: " + dir_ + "/nope.pcd: no such file", 2},
      {good + " --t 0.1,abc", "map_accuracy: --t needs a number, got 'abc'", 2},
      {good + " --t 0.1,-1", "map_accuracy: --t must lie in [1e-06, 1000], got -1", 2},
      {good + " --t nan", "map_accuracy: --t needs a number, got 'nan'", 2},
      {good + " --trail-tol x", "map_accuracy: --trail-tol needs a number, got 'x'", 2},
      {good + " --trail-tol", "map_accuracy: --trail-tol needs a value", 2},
      {good + " --bogus 1", "map_accuracy: unknown option '--bogus'", 2},
      {"--cloud " + dir_ + "/map.pcd", "map_accuracy: --cloud and one of --mesh, --ref are required", 2},
  };
  for (const auto& c : cases) {
    const ToolRun r = run(c.args);
    EXPECT_EQ(r.status, c.status) << c.args << "\n" << r.out;
    EXPECT_NE(r.out.find(c.expected), std::string::npos) << c.args << "\n" << r.out;
  }
  // A csv that cannot be written leaves no file (and no temporary) behind.
  std::ifstream missing(dir_ + "/no/such/a.csv");
  EXPECT_FALSE(missing.good());
}

TEST_F(MapAccuracy, CsvReplacesTheOldFileOnlyWhenComplete) {
  std::ofstream(dir_ + "/a.csv") << "old\n";
  // A failing run (bad reference) leaves the old csv.
  std::ofstream(dir_ + "/empty.pcd").close();
  ToolRun r = run("--cloud " + dir_ + "/map.pcd --ref " + dir_ + "/empty.pcd --csv " + dir_ + "/a.csv");
  EXPECT_EQ(r.status, 1);
  std::ifstream old(dir_ + "/a.csv");
  std::string line;
  std::getline(old, line);
  EXPECT_EQ(line, "old");
  r = run("--cloud " + dir_ + "/map.pcd --ref " + dir_ + "/ref.pcd --csv " + dir_ + "/a.csv");
  EXPECT_EQ(r.status, 0) << r.out;
  std::ifstream now(dir_ + "/a.csv");
  std::getline(now, line);
  EXPECT_EQ(line, "t,scene_within,accuracy,completeness,points,ref_points,trails");
}

}  // namespace
