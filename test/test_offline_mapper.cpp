// offline_mapper: runs the core pipeline over a synthetic drive without roscore
// and writes the map and one timing row per frame set; a bag without poses or
// a missing bag gives a clear error.
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Image.h>

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

namespace {

std::string run(const std::string& cmd, int* rc) {
  std::string out;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  char buf[512];
  while (fgets(buf, sizeof(buf), p)) out += buf;
  *rc = pclose(p);
  return out;
}

int lines(const std::string& path) {
  std::ifstream f(path);
  int n = 0;
  for (std::string l; std::getline(f, l);) ++n;
  return n;
}

const std::string kDir = "/tmp/fm_test_offline_mapper_" + std::to_string(getpid());
const std::string kRig = std::string(" --camchain ") + FM_TEST_DATA_DIR + "/small_rig_camchain.yaml --mount " +
                         FM_TEST_DATA_DIR + "/small_rig_mount.yaml";

}  // namespace

TEST(OfflineMapper, MapsADriveAndWritesTimings) {
  int rc = 0;
  std::string out = run(std::string(FM_MAKE_DRIVE) + " --out " + kDir + "/drive" + kRig +
                            " --preset urban --seed 2 --duration 2 --rate 2",
                        &rc);
  ASSERT_EQ(rc, 0) << out;
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/drive/drive.bag" + kRig + " --out " + kDir +
                "/map --quiet --config " + FM_TEST_DATA_DIR + "/vehicle_small_rig.yaml",
            &rc);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("4 frame sets mapped"), std::string::npos) << out;
  EXPECT_EQ(lines(kDir + "/map/timings.csv"), 1 + 4);
  EXPECT_GT(lines(kDir + "/map/timings.md"), 5);
  std::ifstream mesh(kDir + "/map/mesh.ply"), cloud(kDir + "/map/cloud.pcd");
  EXPECT_TRUE(mesh.good());
  EXPECT_TRUE(cloud.good());
  const std::string full_run = out;

  // One frame set into the same folder: no voxel is seen often enough for a
  // mesh, so the earlier mesh and cloud stay, and the run does not claim them.
  const auto size = [](const std::string& p) {
    std::ifstream f(p, std::ios::binary | std::ios::ate);
    return f ? static_cast<long>(f.tellg()) : -1L;
  };
  const long mesh_size = size(kDir + "/map/mesh.ply"), cloud_size = size(kDir + "/map/cloud.pcd");
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/drive/drive.bag" + kRig + " --out " + kDir +
                "/map --quiet --frames 1 --config " + FM_TEST_DATA_DIR + "/vehicle_small_rig.yaml",
            &rc);
  // Exit status 1: the run did not produce its map. It names what it wrote
  // (cloud_all.pcd needs one observation) and what it did not.
  EXPECT_EQ(WEXITSTATUS(rc), 1) << out;
  EXPECT_NE(out.find("offline_mapper: mesh.ply not written: the map has no triangle yet (nothing observed 3 times)"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("offline_mapper: cloud.pcd not written: "), std::string::npos) << out;
  EXPECT_NE(out.find("wrote " + kDir + "/map/cloud_all.pcd, timings.csv, timings.md\n"), std::string::npos) << out;
  EXPECT_NE(out.find("not written (earlier files of that name left as they were): mesh.ply, cloud.pcd\n"),
            std::string::npos)
      << out;
  EXPECT_EQ(size(kDir + "/map/mesh.ply"), mesh_size);
  EXPECT_EQ(size(kDir + "/map/cloud.pcd"), cloud_size);
  EXPECT_EQ(lines(kDir + "/map/timings.csv"), 1 + 1);
  EXPECT_NE(full_run.find("wrote " + kDir + "/map/mesh.ply, cloud.pcd, cloud_all.pcd, timings.csv, timings.md\n"),
            std::string::npos)
      << full_run;
  // No temporary file is left behind.
  EXPECT_EQ(run("ls " + kDir + "/map | grep -c partial", &rc), "0\n");

  // Bad options: named, exit status 2, nothing mapped and the earlier outputs untouched.
  const std::string base = std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/drive/drive.bag" + kRig + " --quiet";
  const struct {
    std::string args, expected;
  } bad[] = {
      {" --out " + kDir + "/map --frames abc", "offline_mapper: --frames needs a whole number, got 'abc'\n"},
      {" --out " + kDir + "/map --frames 0", "offline_mapper: --frames must lie in [1, 10000000], got 0\n"},
      {" --out " + kDir + "/map --every -3", "offline_mapper: --every must lie in [1, 1000000], got -3\n"},
      {" --out " + kDir + "/map --every 2x", "offline_mapper: --every needs a whole number, got '2x'\n"},
      {" --out " + kDir + "/map --every", "offline_mapper: --every needs a value\n"},
      {" --out " + kDir + "/map --depth lidar", "offline_mapper: --depth must be sweep or gt, got 'lidar'\n"},
      {" --out " + kDir + "/map --config /tmp", "offline_mapper: --config: /tmp is a directory, expected a file\n"},
      {" --out " + kDir + "/map/timings.csv", "offline_mapper: --out: " + kDir + "/map/timings.csv exists and is not a folder\n"},
      {" --out " + kDir + "/map --bogus", "offline_mapper: unknown argument '--bogus'\n"},
  };
  for (const auto& c : bad) {
    out = run(base + c.args, &rc);
    EXPECT_EQ(WEXITSTATUS(rc), 2) << c.args << "\n" << out;
    EXPECT_EQ(out.substr(0, c.expected.size()), c.expected) << c.args << "\n" << out;
  }
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + " --camchain /tmp --mount /tmp --out " + kDir + "/m", &rc);
  EXPECT_EQ(WEXITSTATUS(rc), 2);
  EXPECT_NE(out.find("offline_mapper: --bag: " + kDir + " is a directory, expected a file"), std::string::npos) << out;
  EXPECT_EQ(size(kDir + "/map/mesh.ply"), mesh_size);
  EXPECT_EQ(lines(kDir + "/map/timings.csv"), 1 + 1);

  // The same images without /tf: a clear error naming the problem.
  {
    rosbag::Bag in(kDir + "/drive/drive.bag"), notf(kDir + "/notf.bag", rosbag::bagmode::Write);
    for (const auto& m : rosbag::View(in, rosbag::TopicQuery({"/cam0/image_raw", "/cam1/image_raw", "/cam2/image_raw"})))
      notf.write(m.getTopic(), m.getTime(), m.instantiate<sensor_msgs::Image>());
  }
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/notf.bag" + kRig + " --out " + kDir + "/map2 --quiet", &rc);
  EXPECT_NE(rc, 0);
  EXPECT_NE(out.find("has no /tf"), std::string::npos) << out;
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/missing.bag" + kRig + " --out " + kDir + "/map3 --quiet", &rc);
  EXPECT_EQ(WEXITSTATUS(rc), 2);
  EXPECT_NE(out.find("offline_mapper: --bag: " + kDir + "/missing.bag: no such file"), std::string::npos) << out;
  // A file that is not a bag.
  std::ofstream(kDir + "/junk.bag") << "not a bag\n";
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/junk.bag" + kRig + " --out " + kDir + "/map3 --quiet", &rc);
  EXPECT_EQ(WEXITSTATUS(rc), 1);
  EXPECT_NE(out.find("cannot open bag " + kDir + "/junk.bag"), std::string::npos) << out;
  std::system(("rm -rf " + kDir).c_str());
}
