// offline_mapper: runs the core pipeline over a synthetic drive without roscore
// and writes the map and one timing row per frame set; a bag without poses or
// a missing bag gives a clear error. Compressed images (PNG: lossless) give
// the same masked depth as the raw ones, --topic reads other topic names, and
// approximate sync pairs stamps within its tolerance where exact does not.
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <tf2_msgs/TFMessage.h>

#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <vector>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"

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

const std::string kInputs = "/tmp/fm_test_offline_mapper_inputs_" + std::to_string(getpid());

bool isCameraImage(const std::string& topic) {
  const std::string suffix = "/image_raw";
  return topic.size() > suffix.size() && topic.compare(topic.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Copies bag `in` to `out`: camera images (/camN/image_raw) through `image`
// (which writes what it likes), everything else (/tf, ground truth) as it is.
void rewriteBag(const std::string& in, const std::string& out,
                const std::function<void(rosbag::Bag&, const std::string&, const ros::Time&,
                                         const sensor_msgs::Image&)>& image) {
  rosbag::Bag src(in), dst(out, rosbag::bagmode::Write);
  for (const rosbag::MessageInstance& m : rosbag::View(src)) {
    if (isCameraImage(m.getTopic())) image(dst, m.getTopic(), m.getTime(), *m.instantiate<sensor_msgs::Image>());
    else dst.write(m.getTopic(), m.getTime(), m);
  }
}

// The depth TIFFs of a --save-depth folder, by file name.
std::map<std::string, cv::Mat> savedDepth(const std::string& dir) {
  std::map<std::string, cv::Mat> depth;
  for (const auto& f : std::filesystem::directory_iterator(dir))
    depth[f.path().filename().string()] = cv::imread(f.path().string(), cv::IMREAD_UNCHANGED);
  return depth;
}

// Pixels where a and b differ (NaN equals NaN), and valid pixels of a.
std::pair<int, int> compareDepth(const cv::Mat& a, const cv::Mat& b) {
  int differ = 0, valid = 0;
  for (int y = 0; y < a.rows; ++y) {
    for (int x = 0; x < a.cols; ++x) {
      const float u = a.at<float>(y, x), v = b.at<float>(y, x);
      if (std::isnan(u) != std::isnan(v) || (!std::isnan(u) && u != v)) ++differ;
      if (!std::isnan(u)) ++valid;
    }
  }
  return {differ, valid};
}

std::string mapper(const std::string& bag, const std::string& out, const std::string& extra) {
  return std::string(FM_OFFLINE_MAPPER) + " --bag " + bag + kRig + " --out " + out + " --quiet --detector ground_truth" +
         " --config " + kInputs + "/config.yaml" + extra;
}

}  // namespace

TEST(OfflineMapper, ReadsCompressedImagesFromOtherTopicsAndSyncsApproximately) {
  int rc = 0;
  std::string out = run(std::string(FM_MAKE_DRIVE) + " --out " + kInputs + "/drive" + kRig +
                            " --preset urban --seed 3 --duration 2 --rate 2",
                        &rc);
  ASSERT_EQ(rc, 0) << out;
  const std::string raw_bag = kInputs + "/drive/drive.bag";
  // The small rig's settings, and a mesh from what two frame sets saw once
  // (the runs below map two), so that every run writes its map.
  std::ofstream(kInputs + "/config.yaml") << std::ifstream(std::string(FM_TEST_DATA_DIR) + "/vehicle_small_rig.yaml").rdbuf()
                                          << "\ntsdf:\n  min_observations: 1\n";

  // The same images as PNG (lossless) CompressedImages on other topics:
  // /renamed/camN/compressed.
  rewriteBag(raw_bag, kInputs + "/compressed.bag",
             [](rosbag::Bag& bag, const std::string& topic, const ros::Time& t, const sensor_msgs::Image& img) {
               ASSERT_EQ(img.encoding, "mono8");
               sensor_msgs::CompressedImage c;
               c.header = img.header;
               c.format = "mono8; png compressed";
               const cv::Mat grey(int(img.height), int(img.width), CV_8UC1, const_cast<uint8_t*>(img.data.data()),
                                  img.step);
               ASSERT_TRUE(cv::imencode(".png", grey, c.data));
               bag.write("/renamed" + topic.substr(0, topic.rfind('/')) + "/compressed", t, c);
             });
  const std::string remap = " --topic cam0=/renamed/cam0/compressed --topic cam1=/renamed/cam1/compressed"
                            " --topic cam2=/renamed/cam2/compressed";
  out = run(mapper(raw_bag, kInputs + "/raw", " --frames 2 --save-depth " + kInputs + "/raw_depth"), &rc);
  ASSERT_EQ(WEXITSTATUS(rc), 0) << out;
  out = run(mapper(kInputs + "/compressed.bag", kInputs + "/comp", remap + " --frames 2 --save-depth " + kInputs +
                                                                        "/comp_depth"),
            &rc);
  ASSERT_EQ(WEXITSTATUS(rc), 0) << out;
  EXPECT_NE(out.find("2 frame sets mapped"), std::string::npos) << out;
  const auto raw_depth = savedDepth(kInputs + "/raw_depth"), comp_depth = savedDepth(kInputs + "/comp_depth");
  ASSERT_EQ(raw_depth.size(), 2u);
  ASSERT_EQ(comp_depth.size(), 2u);
  for (const auto& [name, depth] : raw_depth) {
    ASSERT_TRUE(comp_depth.count(name)) << name;
    ASSERT_EQ(depth.type(), CV_32FC1) << name;
    ASSERT_EQ(comp_depth.at(name).size(), depth.size()) << name;
    const auto [differ, valid] = compareDepth(depth, comp_depth.at(name));
    EXPECT_EQ(differ, 0) << name;
    EXPECT_GT(valid, 1000) << name;  // a real depth map (about 2500 of 34816 pixels pass the filters), not an empty one
  }
  // plane_sweep_depth's bag mode goes through the same core stages (the
  // sync's FrameSetSync, DepthStage): the compressed bag on renamed topics
  // gives the same depth as the raw one; without --max-sets every frame set
  // of the bag is accounted for.
  {
    const std::string psd = std::string(FM_PLANE_SWEEP_DEPTH) + kRig +
                            " --set resolution=full --set min_parallax_px=0.05 --set self_calibration=false --max-sets 2";
    out = run(psd + " --bag " + raw_bag + " --out " + kInputs + "/psd_raw", &rc);
    ASSERT_EQ(WEXITSTATUS(rc), 0) << out;
    EXPECT_NE(out.find("2 depth maps written to " + kInputs + "/psd_raw (--max-sets reached)"), std::string::npos) << out;
    out = run(psd + " --bag " + kInputs + "/compressed.bag" + remap + " --out " + kInputs + "/psd_comp", &rc);
    ASSERT_EQ(WEXITSTATUS(rc), 0) << out;
    const auto psd_raw = savedDepth(kInputs + "/psd_raw"), psd_comp = savedDepth(kInputs + "/psd_comp");
    ASSERT_EQ(psd_raw.size(), 2u);
    ASSERT_EQ(psd_comp.size(), 2u);
    for (const auto& [name, depth] : psd_raw) {
      ASSERT_TRUE(psd_comp.count(name)) << name;
      EXPECT_EQ(compareDepth(depth, psd_comp.at(name)).first, 0) << name;
    }
    // Every frame set of the bag, accounted for.
    out = run(std::string(FM_PLANE_SWEEP_DEPTH) + kRig + " --set resolution=full --bag " + raw_bag + " --out " +
                  kInputs + "/psd_all",
              &rc);
    ASSERT_EQ(WEXITSTATUS(rc), 0) << out;
    EXPECT_NE(out.find("4 depth maps written to " + kInputs + "/psd_all (of the 4 frame sets in the bag: 0 incomplete"),
              std::string::npos)
        << out;
  }

  // Without --topic the renamed bag has none of the camchain's topics.
  out = run(mapper(kInputs + "/compressed.bag", kInputs + "/comp2", ""), &rc);
  EXPECT_EQ(WEXITSTATUS(rc), 1) << out;
  EXPECT_NE(out.find("has none of the topics /cam0/image_raw"), std::string::npos) << out;

  // cam1's images of every second frame set 2 ms late: exact sync completes
  // the other two sets, approximate within 5 ms all four, within 1 ms two.
  std::map<std::string, int> seen;
  rewriteBag(raw_bag, kInputs + "/late.bag",
             [&](rosbag::Bag& bag, const std::string& topic, const ros::Time& t, const sensor_msgs::Image& img) {
               sensor_msgs::Image late = img;
               if (topic == "/cam1/image_raw" && seen[topic]++ % 2 == 1) late.header.stamp += ros::Duration(0.002);
               bag.write(topic, t, late);
             });
  const struct {
    std::string sync;
    int mapped;
  } cases[] = {{"", 2}, {" --sync exact", 2}, {" --sync approximate --sync-tolerance 0.005", 4},
               {" --sync approximate --sync-tolerance 0.001", 2}};
  for (const auto& c : cases) {
    out = run(mapper(kInputs + "/late.bag", kInputs + "/late", c.sync), &rc);
    EXPECT_EQ(WEXITSTATUS(rc), 0) << c.sync << "\n" << out;
    EXPECT_NE(out.find(std::to_string(c.mapped) + " frame sets mapped"), std::string::npos) << c.sync << "\n" << out;
    EXPECT_EQ(lines(kInputs + "/late/timings.csv"), 1 + c.mapped) << c.sync;
  }
  std::system(("rm -rf " + kInputs).c_str());
}

TEST(OfflineMapper, MapsADriveAndWritesTimings) {
  int rc = 0;
  std::string out = run(std::string(FM_MAKE_DRIVE) + " --out " + kDir + "/drive" + kRig +
                            // 10 frame sets: the 3-observation rule needs a surface seen from
                            // several of them (4 at 2 Hz left the map nearly empty)
                            " --preset urban --seed 2 --duration 2 --rate 5",
                        &rc);
  ASSERT_EQ(rc, 0) << out;
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/drive/drive.bag" + kRig + " --out " + kDir +
                "/map --quiet --detector ground_truth --config " + FM_TEST_DATA_DIR + "/vehicle_small_rig.yaml",
            &rc);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("10 frame sets mapped"), std::string::npos) << out;
  EXPECT_EQ(lines(kDir + "/map/timings.csv"), 1 + 10);
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
                "/map --quiet --detector ground_truth --frames 1 --config " + FM_TEST_DATA_DIR + "/vehicle_small_rig.yaml",
            &rc);
  // Exit status 1: the run did not produce its map. It names what it wrote
  // (cloud_all.pcd needs one observation) and what it did not.
  EXPECT_EQ(WEXITSTATUS(rc), 1) << out;
  EXPECT_NE(out.find("offline_mapper: mesh.ply not written: the map has no triangle yet (nothing observed 3 times)"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("offline_mapper: cloud.pcd not written: "), std::string::npos) << out;
  EXPECT_NE(out.find("wrote " + kDir + "/map/cloud_all.pcd, map.fmtsdf, self_calibration.csv, timings.csv, timings.md\n"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("not written (earlier files of that name left as they were): mesh.ply, cloud.pcd\n"),
            std::string::npos)
      << out;
  EXPECT_EQ(size(kDir + "/map/mesh.ply"), mesh_size);
  EXPECT_EQ(size(kDir + "/map/cloud.pcd"), cloud_size);
  EXPECT_EQ(lines(kDir + "/map/timings.csv"), 1 + 1);
  EXPECT_NE(full_run.find("wrote " + kDir + "/map/mesh.ply, cloud.pcd, cloud_all.pcd, map.fmtsdf, "
                                               "self_calibration.csv, timings.csv, timings.md\n"),
            std::string::npos)
      << full_run;
  // The map file (as the nodelet's save_map) is the run's map: its geometry
  // is the config's, and it holds blocks.
  const fisheye_mapping::MapFileInfo info = fisheye_mapping::TsdfMap::readHeader(kDir + "/map/map.fmtsdf");
  EXPECT_NEAR(info.voxel_size, 0.05, 1e-9);  // config/tsdf.yaml's voxel_size
  EXPECT_GT(info.num_blocks, 10u);
  // The depth stage's online self-calibration (on by default): its time and
  // each supporting camera's state in timings.md, one CSV row per camera and
  // update (the small rig's exact calibration: nothing to correct, nothing
  // more written).
  EXPECT_NE(full_run.find("self-calibration: "), std::string::npos) << full_run;
  EXPECT_NE(full_run.find("| cam1 | 0.000 |"), std::string::npos) << full_run;
  EXPECT_EQ(full_run.find("self_calibrated_camchain.yaml"), std::string::npos) << full_run;
  // No temporary file is left behind.
  EXPECT_EQ(run("ls -A " + kDir + "/map | grep -c '\\.tmp\\.'", &rc), "0\n");

  // Bad options: named, exit status 2, nothing mapped and the earlier outputs untouched.
  const std::string base =
      std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/drive/drive.bag" + kRig + " --quiet --detector ground_truth";
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
      {" --out " + kDir + "/map --bogus", "offline_mapper: unknown option '--bogus'\n"},
      {" --out " + kDir + "/map --sync fuzzy", "offline_mapper: --sync must be exact or approximate, got 'fuzzy'\n"},
      {" --out " + kDir + "/map --sync-tolerance 2", "offline_mapper: --sync-tolerance must lie in [0, 1], got 2\n"},
      {" --out " + kDir + "/map --topic cam0", "offline_mapper: --topic needs CAM=TOPIC (e.g. cam0=/cam0/image_raw/compressed), got 'cam0'\n"},
      {" --out " + kDir + "/map --topic cam9=/x", "offline_mapper: --topic: no camera 'cam9' in the rig\n"},
      {" --out " + kDir + "/map --topic cam1=/cam0/image_raw",
       "offline_mapper: cameras cam0 and cam1 both read /cam0/image_raw (give each its own with --topic)\n"},
  };
  for (const auto& c : bad) {
    out = run(base + c.args, &rc);
    EXPECT_EQ(WEXITSTATUS(rc), 2) << c.args << "\n" << out;
    EXPECT_EQ(out.substr(0, c.expected.size()), c.expected) << c.args << "\n" << out;
  }
  // A --config key or section that no stage declares (a typo) stops the run,
  // named with the file, the section and the known names; nothing is mapped.
  std::ofstream(kDir + "/typo_key.yaml") << "depth:\n  resolution: full\ntsdf:\n  max_rnge: 15\n";
  out = run(base + " --out " + kDir + "/map --config " + kDir + "/typo_key.yaml", &rc);
  EXPECT_EQ(WEXITSTATUS(rc), 1) << out;
  EXPECT_NE(out.find("offline_mapper: " + kDir + "/typo_key.yaml: unknown parameter 'max_rnge' in section 'tsdf' (known: "),
            std::string::npos)
      << out;
  EXPECT_NE(out.find(", max_range, "), std::string::npos) << out;
  std::ofstream(kDir + "/typo_section.yaml") << "tsfd:\n  max_range: 15\n";
  out = run(base + " --out " + kDir + "/map --config " + kDir + "/typo_section.yaml", &rc);
  EXPECT_EQ(WEXITSTATUS(rc), 1) << out;
  EXPECT_NE(out.find("offline_mapper: " + kDir + "/typo_section.yaml: unknown section 'tsfd' (known: sync, depth, "
                     "detector, depth_mask, tsdf, rig_tf)"),
            std::string::npos)
      << out;
  EXPECT_EQ(size(kDir + "/map/mesh.ply"), mesh_size);
  // The fine-tuned detector's model YAML lives in the cache; a fresh cache has none.
  out = run("FISHEYE_MAPPING_CACHE=" + kDir + "/nocache " + base + " --out " + kDir + "/map --detector finetuned", &rc);
  EXPECT_EQ(WEXITSTATUS(rc), 2) << out;
  EXPECT_NE(out.find("offline_mapper: --detector finetuned: " + kDir +
                     "/nocache/models/finetuned/nanodet-fisheye.yaml does not exist (make it with "
                     "scripts/tools/train_vehicle_detector)"),
            std::string::npos)
      << out;
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
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/notf.bag" + kRig + " --out " + kDir +
                "/map2 --quiet --detector ground_truth",
            &rc);
  EXPECT_NE(rc, 0);
  EXPECT_NE(out.find("has no /tf"), std::string::npos) << out;
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/missing.bag" + kRig + " --out " + kDir +
                "/map3 --quiet --detector ground_truth",
            &rc);
  EXPECT_EQ(WEXITSTATUS(rc), 2);
  EXPECT_NE(out.find("offline_mapper: --bag: " + kDir + "/missing.bag: no such file"), std::string::npos) << out;
  // A file that is not a bag.
  std::ofstream(kDir + "/junk.bag") << "not a bag\n";
  out = run(std::string(FM_OFFLINE_MAPPER) + " --bag " + kDir + "/junk.bag" + kRig + " --out " + kDir +
                "/map3 --quiet --detector ground_truth",
            &rc);
  EXPECT_EQ(WEXITSTATUS(rc), 1);
  EXPECT_NE(out.find("cannot open bag " + kDir + "/junk.bag"), std::string::npos) << out;
  std::system(("rm -rf " + kDir).c_str());
}

namespace {

// The summary's accounting, as offline_mapper prints it.
std::string accounting(int total, int mapped, int backwards, int duplicate, int incomplete, int undecodable) {
  return "of the " + std::to_string(total) + " frame sets in the bag: " + std::to_string(mapped) + " mapped, " +
         std::to_string(total - mapped) + " not: " + std::to_string(backwards) + " stamps backwards, " +
         std::to_string(duplicate) + " duplicate stamp, " + std::to_string(incomplete) + " incomplete, " +
         std::to_string(undecodable) + " undecodable image, 0 without a pose, 0 old timeline, 0 skipped by --every";
}

// Each camera image of `in`, by camera topic: its index among that topic's images.
using ImageEdit = std::function<void(rosbag::Bag&, const std::string&, const ros::Time&, sensor_msgs::Image, int)>;
void rewriteImages(const std::string& in, const std::string& out, const ImageEdit& edit) {
  std::map<std::string, int> index;
  rewriteBag(in, out, [&](rosbag::Bag& bag, const std::string& topic, const ros::Time& t, const sensor_msgs::Image& img) {
    edit(bag, topic, t, img, index[topic]++);
  });
}

// The bag file's bytes, and writing them back cut or patched.
std::string bytesOf(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

}  // namespace

// Issue 28: every frame set of a bag accounted for, by reason, adding up to
// the frame sets in the bag; a corrupt image skips its set and the drive goes
// on; compressed camera topics (<topic>/compressed) are found by default; a
// bag cut short or never closed is refused with the rosbag reindex command
// that recovers it (run here: the recovered bag maps).
TEST(OfflineMapper, EveryFrameSetAccountedForAndBagsCutShort) {
  const std::string dir = kInputs + "_accounting";
  int rc = 0;
  std::string out = run(std::string(FM_MAKE_DRIVE) + " --out " + dir + "/drive" + kRig +
                            " --preset urban --seed 3 --duration 5 --rate 2",
                        &rc);
  ASSERT_EQ(rc, 0) << out;
  const std::string raw_bag = dir + "/drive/drive.bag";
  std::ofstream(dir + "/config.yaml") << std::ifstream(std::string(FM_TEST_DATA_DIR) + "/vehicle_small_rig.yaml").rdbuf()
                                      << "\ntsdf:\n  min_observations: 1\n";
  const auto map = [&](const std::string& bag, const std::string& name) {
    return run(std::string(FM_OFFLINE_MAPPER) + " --bag " + bag + kRig + " --out " + dir + "/" + name +
                   " --quiet --detector ground_truth --config " + dir + "/config.yaml",
               &rc);
  };
  out = map(raw_bag, "raw");
  ASSERT_EQ(WEXITSTATUS(rc), 0) << out;
  EXPECT_NE(out.find(accounting(10, 10, 0, 0, 0, 0)), std::string::npos) << out;

  // The stamps of the last five frame sets step back 0.1 .. 0.5 s from the
  // fifth's (within the 1 s time-reset threshold: late images, not a new drive).
  std::vector<ros::Time> stamps;
  {
    rosbag::Bag b(raw_bag);
    for (const auto& m : rosbag::View(b, rosbag::TopicQuery(std::string("/cam0/image_raw"))))
      stamps.push_back(m.instantiate<sensor_msgs::Image>()->header.stamp);
  }
  ASSERT_EQ(stamps.size(), 10u);
  rewriteImages(raw_bag, dir + "/backwards.bag",
                [&](rosbag::Bag& bag, const std::string& topic, const ros::Time& t, sensor_msgs::Image img, int k) {
                  if (k >= 5) img.header.stamp = stamps[4] - ros::Duration(0.1 * (k - 4));
                  bag.write(topic, t, img);
                });
  out = map(dir + "/backwards.bag", "backwards");
  EXPECT_EQ(WEXITSTATUS(rc), 0) << out;
  EXPECT_NE(out.find("5 frame sets mapped"), std::string::npos) << out;
  EXPECT_NE(out.find(accounting(10, 5, 5, 0, 0, 0)), std::string::npos) << out;

  // Every image with the first frame set's stamp.
  rewriteImages(raw_bag, dir + "/one_stamp.bag",
                [&](rosbag::Bag& bag, const std::string& topic, const ros::Time& t, sensor_msgs::Image img, int) {
                  img.header.stamp = stamps[0];
                  bag.write(topic, t, img);
                });
  out = map(dir + "/one_stamp.bag", "one_stamp");
  EXPECT_EQ(WEXITSTATUS(rc), 0) << out;
  EXPECT_NE(out.find(accounting(10, 1, 0, 9, 0, 0)), std::string::npos) << out;

  // JPEG CompressedImages on image_transport's /camN/image_raw/compressed
  // (found without --topic); cam1's image of set 3 cut short, cam2's of set 6 lost.
  rewriteImages(raw_bag, dir + "/jpeg.bag",
                [&](rosbag::Bag& bag, const std::string& topic, const ros::Time& t, sensor_msgs::Image img, int k) {
                  if (topic == "/cam2/image_raw" && k == 6) return;
                  sensor_msgs::CompressedImage c;
                  c.header = img.header;
                  c.format = "mono8; jpeg compressed bgr8";
                  const cv::Mat grey(int(img.height), int(img.width), CV_8UC1, img.data.data(), img.step);
                  ASSERT_TRUE(cv::imencode(".jpg", grey, c.data));
                  if (topic == "/cam1/image_raw" && k == 3) c.data.resize(c.data.size() / 2);
                  bag.write(topic + "/compressed", t, c);
                });
  out = map(dir + "/jpeg.bag", "jpeg");
  EXPECT_EQ(WEXITSTATUS(rc), 0) << out;
  EXPECT_NE(out.find(accounting(10, 8, 0, 0, 1, 1)), std::string::npos) << out;
  char at[32];
  std::snprintf(at, sizeof at, "%.3f", stamps[3].toSec());
  EXPECT_NE(out.find(std::string("frame set ") + at + " skipped: undecodable image: /cam1/image_raw/compressed: "),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("JPEG cut short"), std::string::npos) << out;

  // Cut mid-chunk (power lost while recording): refused with the command
  // that recovers it; after it, the complete chunks map.
  const std::string whole = bytesOf(raw_bag);
  const std::string cut = dir + "/cut.bag";
  std::ofstream(cut, std::ios::binary) << whole.substr(0, whole.size() * 6 / 10);
  out = map(cut, "cut");
  EXPECT_EQ(WEXITSTATUS(rc), 1) << out;
  EXPECT_NE(out.find("cannot read bag " + cut + ": it is cut short: its index should start at byte"), std::string::npos)
      << out;
  EXPECT_NE(out.find("`rosbag reindex '" + cut + "'`"), std::string::npos) << out;
  std::string reindex = run("/usr/bin/rosbag reindex '" + cut + "'", &rc);
  ASSERT_EQ(WEXITSTATUS(rc), 0) << reindex;
  out = map(cut, "cut");
  EXPECT_EQ(WEXITSTATUS(rc), 0) << out;
  EXPECT_NE(out.find("frame sets mapped"), std::string::npos) << out;
  EXPECT_EQ(out.find(" 10 mapped"), std::string::npos) << out;  // only what was recorded

  // Never closed (rosbag record killed): the header's index position is 0.
  std::string active = whole;
  const std::size_t field = active.find("index_pos=");
  ASSERT_NE(field, std::string::npos);
  active.replace(field + 10, 8, std::string(8, '\0'));
  std::ofstream(dir + "/drive.bag.active", std::ios::binary) << active;
  out = map(dir + "/drive.bag.active", "active");
  EXPECT_EQ(WEXITSTATUS(rc), 1) << out;
  EXPECT_NE(out.find("it has no index (a recording that was not closed"), std::string::npos) << out;
  EXPECT_NE(out.find("`rosbag reindex '" + dir + "/drive.bag.active'`"), std::string::npos) << out;
  std::system(("rm -rf " + dir).c_str());
}
