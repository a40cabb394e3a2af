// offline_mapper: runs the core pipeline over a synthetic drive without roscore
// and writes the map and one timing row per frame set; a bag without poses or
// a missing bag gives a clear error.
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Image.h>

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
  EXPECT_NE(out.find("mesh.ply not written"), std::string::npos) << out;
  EXPECT_EQ(out.find("wrote " + kDir + "/map/mesh.ply"), std::string::npos) << out;
  EXPECT_EQ(size(kDir + "/map/mesh.ply"), mesh_size);
  EXPECT_EQ(size(kDir + "/map/cloud.pcd"), cloud_size);
  EXPECT_NE(full_run.find("wrote " + kDir + "/map/mesh.ply, cloud.pcd, cloud_all.pcd"), std::string::npos) << full_run;

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
  EXPECT_NE(rc, 0);
  EXPECT_NE(out.find("cannot open bag"), std::string::npos) << out;
  std::system(("rm -rf " + kDir).c_str());
}
