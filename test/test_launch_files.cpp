// The launch files as a user meets them: every argument a user may set is
// documented (doc=, listed by `roslaunch --ros-args`), and vehicle.launch
// stops at once, naming the file, when the bag, camchain or mount is missing
// (instead of starting idle nodelets). `roslaunch --nodes` evaluates the
// arguments without starting anything (no master needed).
#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "tool_run.h"

namespace {

using fisheye_mapping::test::runTool;

const std::string kLaunchDir = std::string(FM_TEST_DIR) + "/../launch";
const std::string kRig = std::string(FM_CONFIG_DIR) + "/rig";

std::string readFile(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// `roslaunch --nodes` on vehicle.launch with the given arguments.
fisheye_mapping::test::ToolRun nodes(const std::string& args) {
  return runTool("roslaunch --nodes " + kLaunchDir + "/vehicle.launch " + args);
}

TEST(LaunchFiles, EveryUserArgumentHasADoc) {
  const std::regex arg_tag(R"re(<arg\s[^>]*>)re");
  const std::regex name_attr(R"re(name="([^"]+)")re");
  for (const char* file : {"vehicle.launch", "depth.launch", "tsdf.launch", "dynamic_objects.launch"}) {
    const std::string text = readFile(kLaunchDir + "/" + file);
    ASSERT_FALSE(text.empty()) << file;
    int user_args = 0;
    for (std::sregex_iterator it(text.begin(), text.end(), arg_tag), end; it != end; ++it) {
      const std::string tag = it->str();
      std::smatch name;
      ASSERT_TRUE(std::regex_search(tag, name, name_attr)) << file << ": " << tag;
      // value= args are computed inside the file (checks, derived names), not set by a user.
      if (tag.find(" value=") != std::string::npos || tag.find("\n       value=") != std::string::npos) continue;
      ++user_args;
      EXPECT_NE(tag.find("doc=\""), std::string::npos) << file << ": argument '" << name[1] << "' has no doc=";
    }
    EXPECT_GT(user_args, 3) << file;
  }
}

TEST(LaunchFiles, VehicleLaunchStopsOnAMissingBagOrCalibration) {
  const std::string rig = " camchain:=" + kRig + "/default_camchain.yaml mount:=" + kRig + "/default_mount.yaml";
  // The good case first: the arguments evaluate and the nodes are listed.
  auto r = nodes("bag:=none rviz:=false" + rig);
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/fisheye_mapping/depth"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("/fisheye_mapping/tsdf"), std::string::npos) << r.out;

  r = nodes("bag:=/nonexistent/drive.bag rviz:=false" + rig);
  EXPECT_NE(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("No such file or directory: '/nonexistent/drive.bag'"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("the_bag_file_must_exist"), std::string::npos) << r.out;

  r = nodes("bag:=none rviz:=false camchain:=/nonexistent/camchain.yaml mount:=" + kRig + "/default_mount.yaml");
  EXPECT_NE(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/nonexistent/camchain.yaml"), std::string::npos) << r.out;

  r = nodes("bag:=none rviz:=false camchain:=" + kRig + "/default_camchain.yaml mount:=/nonexistent/mount.yaml");
  EXPECT_NE(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/nonexistent/mount.yaml"), std::string::npos) << r.out;

  // The rig from camera_info topics: no calibration files needed.
  r = nodes("bag:=none rviz:=false rig_source:=camera_info camchain:=/nonexistent/c.yaml mount:=/nonexistent/m.yaml");
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/fisheye_mapping/sync"), std::string::npos) << r.out;

  // An unknown detector name: the registry (detector_model) stops roslaunch, listing the known ones.
  r = nodes("bag:=none rviz:=false detector:=yolo" + rig);
  EXPECT_NE(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("detector_model: unknown detector 'yolo' (known: nanodet, finetuned, darknet, "),
            std::string::npos)
      << r.out;
}

// detector:=finetuned loads the model YAML that scripts/tools/train_vehicle_detector
// writes into the cache (finetuned_model); without it the launch stops saying
// how to make it.
TEST(LaunchFiles, FinetunedDetectorNeedsItsModelInTheCache) {
  const std::string rig = " camchain:=" + kRig + "/default_camchain.yaml mount:=" + kRig + "/default_mount.yaml";
  char tmpl[] = "/tmp/fm_launch_cache.XXXXXX";
  ASSERT_NE(mkdtemp(tmpl), nullptr);
  const std::string cache = tmpl;
  const std::string yaml = cache + "/models/finetuned/nanodet-fisheye.yaml";
  const std::string env = "FISHEYE_MAPPING_CACHE=" + cache + " ";
  auto r = runTool(env + "roslaunch --nodes " + kLaunchDir + "/vehicle.launch bag:=none rviz:=false detector:=finetuned" + rig);
  EXPECT_NE(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("detector_model: detector finetuned: " + yaml +
                       " does not exist (make it with scripts/tools/train_vehicle_detector)"),
            std::string::npos)
      << r.out;

  ASSERT_EQ(std::system(("mkdir -p " + cache + "/models/finetuned && touch " + yaml).c_str()), 0);
  r = runTool(env + "roslaunch --dump-params " + kLaunchDir + "/vehicle.launch bag:=none rviz:=false detector:=finetuned" + rig);
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/fisheye_mapping/detector/model_config: " + yaml), std::string::npos) << r.out;
  // The default stays the COCO model of the tree.
  r = runTool(env + "roslaunch --dump-params " + kLaunchDir + "/vehicle.launch bag:=none rviz:=false" + rig);
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("config/detector/nanodet.yaml"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("models/finetuned"), std::string::npos) << r.out;
  // finetuned_model:= replaces the cache's model.
  r = runTool(env + "roslaunch --dump-params " + kLaunchDir + "/vehicle.launch bag:=none rviz:=false detector:=finetuned" +
              " finetuned_model:=" + kRig + "/default_mount.yaml" + rig);
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/fisheye_mapping/detector/model_config: " + kRig + "/default_mount.yaml"), std::string::npos)
      << r.out;
  std::system(("rm -rf " + cache).c_str());
}

// dynamic_objects.launch: the registry's model of the name (darknet: the
// YOLOv3-tiny YAML), a model YAML path as the detector, or model_config:= over
// any name.
TEST(LaunchFiles, DynamicObjectsLaunchTakesANameOrAModel) {
  const std::string launch = "roslaunch --dump-params " + kLaunchDir + "/dynamic_objects.launch";
  auto r = runTool(launch + " detector:=darknet");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/detector/model_config: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("config/detector/yolov3-tiny.yaml"), std::string::npos) << r.out;
  const std::string own = std::string(FM_CONFIG_DIR) + "/detector/yolov8n.yaml";
  r = runTool(launch + " detector:=" + own);
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/detector/model_config: " + own), std::string::npos) << r.out;
  r = runTool(launch + " detector:=nanodet model_config:=" + own);
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/detector/model_config: " + own), std::string::npos) << r.out;
  // --nodes: --dump-params exits 0 even when the file cannot be loaded.
  r = runTool("roslaunch --nodes " + kLaunchDir + "/dynamic_objects.launch detector:=/nonexistent/model.yaml");
  EXPECT_NE(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("detector_model: detector /nonexistent/model.yaml does not exist"), std::string::npos) << r.out;
}

TEST(LaunchFiles, NamespaceAndFramesReachTheStagesAndRviz) {
  const std::string rig = " camchain:=" + kRig + "/default_camchain.yaml mount:=" + kRig + "/default_mount.yaml";
  // --args prints a node's command line: rviz (outside the stages' namespace)
  // gets the fixed frame, which follows world_frame.
  auto r = runTool("roslaunch --args /rviz " + kLaunchDir + "/vehicle.launch bag:=none ns:=fisheye world_frame:=odom" + rig);
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("-f odom"), std::string::npos) << r.out;
  r = runTool("roslaunch --dump-params " + kLaunchDir + "/vehicle.launch bag:=none ns:=fisheye world_frame:=odom" + rig);
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/fisheye/tsdf/world_frame: odom"), std::string::npos) << r.out;
  r = nodes("bag:=none rviz:=false ns:=fisheye" + rig);
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("/fisheye/tsdf"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("/fisheye_mapping/"), std::string::npos) << r.out;
}

}  // namespace
