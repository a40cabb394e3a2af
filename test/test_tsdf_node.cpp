// rostest: the Tsdf nodelet fuses analytic fisheye depth frames whose
// poses come over tf; mesh and cloud arrive in the map frame and lie on the
// true surfaces; bad frames are skipped and counted in /diagnostics; the
// mesh stream keeps rviz's rules over the whole run; the services save, load
// and clear, with relative paths inside the save folder ($ROS_HOME/
// fisheye_mapping) and refuse paths outside it, FIFOs, and links followed
// (issue 28); max_range changes at run
// time through dynamic_reconfigure; with ~rig_source camera_info the camera
// model comes from depth_masked/camera_info and the map is the same.
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <tuple>
#include <filesystem>
#include <atomic>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>

#include <cv_bridge/cv_bridge.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <gtest/gtest.h>
#include <pcl_conversions/pcl_conversions.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_eigen/tf2_eigen.h>
#include <nav_msgs/OccupancyGrid.h>
#include <visualization_msgs/MarkerArray.h>

#include "fisheye_mapping/FilePath.h"
#include "fisheye_mapping/FrameDone.h"
#include "fisheye_mapping/core/sim/analytic_scene.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "ros_test_utils.h"
#include "small_rig_frames.h"

namespace fm = fisheye_mapping;

namespace {

using fisheye_mapping::test::waitFor;

fm::analytic::Scene scene() {
  fm::analytic::Scene s;
  s.ground_extent = 8.0;
  s.spheres.push_back({Eigen::Vector3d(3.0, 0.9, 0.7), 0.7});
  s.boxes.push_back({Eigen::Vector3d(2.2, -1.6, 0.0), Eigen::Vector3d(3.6, -0.4, 0.8)});
  return s;
}

sensor_msgs::PointCloud2ConstPtr last_cloud;
visualization_msgs::MarkerArrayConstPtr last_mesh;

// An independent model of what rviz's MarkerDisplay holds, fed every mesh
// update of the run, counting each breach of its rules (rviz warns on them)
// and every ADD that repeats the triangles already on screen (an update must
// carry only blocks that changed).
struct RvizModel {
  std::mutex mutex;
  std::map<int, std::vector<geometry_msgs::Point>> shown;  // id -> triangles on screen
  std::set<int> deleted;                                   // deleted and not added since
  int arrays = 0, markers = 0;
  int duplicate_ids = 0, deleted_twice = 0, deleted_never_shown = 0, deleted_when_added = 0, unchanged_adds = 0;

  void take(const visualization_msgs::MarkerArray& m) {
    std::lock_guard<std::mutex> lock(mutex);
    ++arrays;
    std::set<int> in_array, added;
    for (const auto& marker : m.markers) {
      if (marker.action == visualization_msgs::Marker::ADD) added.insert(marker.id);
    }
    for (const auto& marker : m.markers) {
      if (marker.action == visualization_msgs::Marker::DELETEALL) {
        shown.clear();
        deleted.clear();
        continue;
      }
      ++markers;
      if (!in_array.insert(marker.id).second) ++duplicate_ids;
      if (marker.action == visualization_msgs::Marker::DELETE) {
        if (added.count(marker.id)) ++deleted_when_added;
        if (deleted.count(marker.id)) {
          ++deleted_twice;
        } else if (!shown.count(marker.id)) {
          ++deleted_never_shown;
        }
        shown.erase(marker.id);
        deleted.insert(marker.id);
      } else if (marker.action == visualization_msgs::Marker::ADD) {
        auto it = shown.find(marker.id);
        if (it != shown.end() && it->second == marker.points) ++unchanged_adds;
        shown[marker.id] = marker.points;
        deleted.erase(marker.id);
      }
    }
  }
  int errors() {
    std::lock_guard<std::mutex> lock(mutex);
    return duplicate_ids + deleted_twice + deleted_never_shown + deleted_when_added + unchanged_adds;
  }
  int numArrays() {
    std::lock_guard<std::mutex> lock(mutex);
    return arrays;
  }
};
RvizModel rviz;

// The TSDF node's /diagnostics values (status "tsdf: tsdf": node, stage).
std::mutex diag_mutex;
std::map<std::string, std::string> diag;
std::set<std::string> diag_names;  // every status seen (for failure messages)

std::string diagNames() {
  std::lock_guard<std::mutex> lock(diag_mutex);
  std::string names;
  for (const auto& n : diag_names) names += "'" + n + "' ";
  return names;
}

std::string diagValue(const std::string& key) {
  std::lock_guard<std::mutex> lock(diag_mutex);
  const auto it = diag.find(key);
  return it == diag.end() ? std::string() : it->second;
}

// Where ROS puts a node's relative files: $ROS_HOME, else ~/.ros (ROS's rule).
std::string rosHome() {
  const char* h = std::getenv("ROS_HOME");
  return h && *h ? std::string(h) : std::string(std::getenv("HOME")) + "/.ros";
}

// The nodes' save folder (~save_directory's default), made and resolved.
std::string saveFolder() {
  const std::filesystem::path dir = std::filesystem::path(rosHome()) / "fisheye_mapping";
  std::filesystem::create_directories(dir);
  return std::filesystem::canonical(dir).string();
}

std::string fileBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}


class TsdfFusionNode : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string dir = ros::package::getPath("fisheye_mapping") + "/test/data/";
    rig_ = fm::loadKalibrRig(dir + "small_fisheye_camchain.yaml", dir + "small_fisheye_mount.yaml");
    depth_pub_ = nh_.advertise<sensor_msgs::Image>("depth_masked/image", 50);
    cloud_sub_ = nh_.subscribe<sensor_msgs::PointCloud2>(
        "tsdf/cloud", 2, boost::function<void(const sensor_msgs::PointCloud2ConstPtr&)>([](const auto& m) {
          last_cloud = m;
        }));
    mesh_sub_ = nh_.subscribe<visualization_msgs::MarkerArray>(
        "tsdf/mesh", 20, boost::function<void(const visualization_msgs::MarkerArrayConstPtr&)>([](const auto& m) {
          rviz.take(*m);
          for (const auto& marker : m->markers) {
            if (marker.action == visualization_msgs::Marker::ADD) {
              last_mesh = m;
              break;
            }
          }
        }));
    diag_sub_ = nh_.subscribe<diagnostic_msgs::DiagnosticArray>(
        "/diagnostics", 20, boost::function<void(const diagnostic_msgs::DiagnosticArrayConstPtr&)>([](const auto& m) {
          std::lock_guard<std::mutex> lock(diag_mutex);
          for (const auto& st : m->status) {
            diag_names.insert(st.name);
            if (st.name != "tsdf: tsdf") continue;  // "<node name>: <stage>"
            for (const auto& kv : st.values) diag[kv.key] = kv.value;
          }
        }));
    ASSERT_TRUE(waitFor([this] { return depth_pub_.getNumSubscribers() > 0 && tf_.getNumSubscribers() > 0; }, 30.0))
        << "Tsdf never subscribed";
  }

  // Publishes the vehicle pose (map -> base_link) and the depth the camera sees.
  // ci: also to the ~rig_source camera_info node (its CameraInfo first, the
  // mask's order); camchain: also to the camchain node.
  void playFrame(const Eigen::Isometry3d& T_W_C, const ros::Time& stamp, const std::string& encoding = "32FC1",
                 bool ci = false, bool camchain = true) {
    const fm::RigCamera& cam = rig_.cameras[0];
    const Eigen::Isometry3d T_W_B = T_W_C * cam.T_base_cam.inverse();
    geometry_msgs::TransformStamped t = tf2::eigenToTransform(T_W_B);
    t.header.stamp = stamp;
    t.header.frame_id = "map";
    t.child_frame_id = "base_link";
    tf_.sendTransform(t);
    cv::Mat depth = scene().render(cam.model, T_W_C);
    cv_bridge::CvImage img;
    img.header.stamp = stamp;
    img.header.frame_id = cam.frame_id;
    img.encoding = encoding;
    if (encoding == "16UC1") depth.convertTo(img.image, CV_16UC1, 1000.0);
    else img.image = depth;
    if (ci) {
      ci_info_pub_.publish(cameraInfo(img.header));
      ci_depth_pub_.publish(img.toImageMsg());
    }
    if (camchain) {
      // The reference image (grey 150), whose grey the map's voxels take.
      cv_bridge::CvImage grey(img.header, "mono8", cv::Mat(depth.size(), CV_8UC1, cv::Scalar(150)));
      image_pub_.publish(grey.toImageMsg());
      ros::WallDuration(0.01).sleep();  // the image first, as the camera's comes before its depth
      depth_pub_.publish(img.toImageMsg());
    }
  }

  // small_fisheye_camchain.yaml's cam0 written out as a CameraInfo (the small rig's cameras').
  static sensor_msgs::CameraInfo cameraInfo(const std_msgs::Header& header) {
    return fisheye_mapping::test::smallRigInfo(header);
  }

  ros::NodeHandle nh_;
  ros::Publisher depth_pub_;
  ros::Publisher ci_depth_pub_ = nh_.advertise<sensor_msgs::Image>("ci/depth_masked/image", 50);
  ros::Publisher image_pub_ = nh_.advertise<sensor_msgs::Image>("image", 50);
  ros::Publisher ci_info_pub_ = nh_.advertise<sensor_msgs::CameraInfo>("ci/depth_masked/camera_info", 50);
  ros::Subscriber cloud_sub_, mesh_sub_, diag_sub_;
  fisheye_mapping::test::TfPublisher tf_;
  fm::Rig rig_;
};

TEST_F(TsdfFusionNode, FusesFramesAndServesTheMap) {
  ros::AsyncSpinner spinner(2);
  spinner.start();
  // An orbit of 16 views around the objects, 0.1 s apart.
  const ros::Time t0 = ros::Time::now();
  for (int i = 0; i < 16; ++i) {
    const double a = 2 * M_PI * i / 16;
    playFrame(fm::analytic::lookAt(Eigen::Vector3d(3 + 4.5 * std::cos(a), 4.5 * std::sin(a), 2.5),
                                   Eigen::Vector3d(3, 0, 0.3)),
              t0 + ros::Duration(0.1 * i));
    ros::WallDuration(0.05).sleep();
  }
  // Bad frames: a wrong encoding, and a stamp with no pose ever.
  playFrame(fm::analytic::lookAt(Eigen::Vector3d(0, 0, 2.5), Eigen::Vector3d(3, 0, 0)), t0 + ros::Duration(2.0), "16UC1");
  ASSERT_TRUE(waitFor([] { return last_cloud && last_cloud->width * last_cloud->height > 5000; }, 60.0))
      << "no cloud with surface points arrived";
  ros::WallDuration(1.0).sleep();  // let the last frames land

  // Nothing changes any more: later publishes carry no mesh update.
  const int arrays = rviz.numArrays();
  ros::WallDuration(1.0).sleep();  // five publish periods
  EXPECT_EQ(rviz.numArrays(), arrays) << "mesh updates without a change in the map";

  // Diagnostics: 17 frames in, 16 fused, the 16UC1 one dropped as a bad image.
  ASSERT_TRUE(waitFor([] { return diagValue("frames fused") == "16"; }, 5.0))
      << "frames fused: '" << diagValue("frames fused") << "'; statuses: " << diagNames();
  EXPECT_EQ(diagValue("inputs"), "17");
  EXPECT_EQ(diagValue("outputs"), "16");
  EXPECT_NE(diagValue("dropped: bad image").find(", 1 total"), std::string::npos) << diagValue("dropped: bad image");
  EXPECT_GT(std::atof(diagValue("input rate (Hz)").c_str()), 1.0);  // 17 frames within the 10 s window
  EXPECT_NE(diagValue("processing time last/mean/max (ms)"), "none");
  EXPECT_EQ(diagValue("exceptions in depth callbacks"), "0");

  // The cloud lies on the true surfaces (within a voxel, but at box edges).
  pcl::PointCloud<pcl::PointXYZ> cloud;
  pcl::fromROSMsg(*last_cloud, cloud);
  EXPECT_EQ(last_cloud->header.frame_id, "map");
  const fm::analytic::Scene s = scene();
  size_t near = 0;
  for (const auto& p : cloud) near += std::abs(s.sdf(Eigen::Vector3d(p.x, p.y, p.z))) < 0.05;
  std::cout << cloud.size() << " cloud points, " << near << " within 5 cm of the surface\n";
  EXPECT_GE(near, cloud.size() * 98 / 100);
  // Their intensity: the grey 150 of the images fused with the depth.
  pcl::PointCloud<pcl::PointXYZI> grey_cloud;
  pcl::fromROSMsg(*last_cloud, grey_cloud);
  size_t grey150 = 0;
  std::map<float, size_t> histogram;
  for (const auto& p : grey_cloud) grey150 += p.intensity == 150.0f, ++histogram[p.intensity];
  std::ostringstream hist;
  for (const auto& [g, n] : histogram) hist << g << ": " << n << "; ";
  EXPECT_GE(grey150, grey_cloud.size() * 95 / 100) << "points with the images' grey; intensities " << hist.str();
  EXPECT_EQ(diagValue("frames fused with intensity"), "16");

  // The obstacle grid: 40 x 40 m at 0.2 m in the map frame; its occupied
  // cells stand on the scene's objects (a solid 0.35..2 m above the ground
  // within a cell of them), and the ground around them is free.
  nav_msgs::OccupancyGridConstPtr grid;
  ros::Subscriber grid_sub = nh_.subscribe<nav_msgs::OccupancyGrid>(
      "tsdf/occupancy", 1, boost::function<void(const nav_msgs::OccupancyGridConstPtr&)>([&grid](const auto& m) { grid = m; }));
  ASSERT_TRUE(waitFor([&grid] { return grid != nullptr; }, 10.0)) << "no tsdf/occupancy";
  EXPECT_EQ(grid->header.frame_id, "map");
  EXPECT_EQ(grid->info.width, 200u);
  EXPECT_EQ(grid->info.height, 200u);
  EXPECT_FLOAT_EQ(grid->info.resolution, 0.2f);
  size_t occupied = 0, on_object = 0, free_cells = 0;
  for (uint32_t y = 0; y < grid->info.height; ++y)
    for (uint32_t x = 0; x < grid->info.width; ++x) {
      const int8_t v = grid->data[y * grid->info.width + x];
      const double wx = grid->info.origin.position.x + (x + 0.5) * grid->info.resolution;
      const double wy = grid->info.origin.position.y + (y + 0.5) * grid->info.resolution;
      if (v == 0) ++free_cells;
      if (v != 100) continue;
      ++occupied;
      double d = 1e9;
      for (double z = 0.35; z <= 2.0; z += 0.05) d = std::min(d, s.sdf(Eigen::Vector3d(wx, wy, z)));
      on_object += d < 0.2;
    }
  std::cout << occupied << " occupied cells, " << on_object << " on an object; " << free_cells << " free\n";
  EXPECT_GT(occupied, 20u);
  EXPECT_GE(on_object, occupied * 9 / 10);
  EXPECT_GT(free_cells, 500u);

  // Its distance field (tsdf/esdf): a point per known cell, intensity its
  // distance to the nearest occupied cell of the grid above (recomputed
  // here by brute force from the grid message), at most 5 m.
  sensor_msgs::PointCloud2ConstPtr esdf;
  ros::Subscriber esdf_sub = nh_.subscribe<sensor_msgs::PointCloud2>(
      "tsdf/esdf", 1, boost::function<void(const sensor_msgs::PointCloud2ConstPtr&)>([&esdf](const auto& m) { esdf = m; }));
  ASSERT_TRUE(waitFor([&esdf] { return esdf != nullptr; }, 10.0)) << "no tsdf/esdf";
  EXPECT_EQ(esdf->header.frame_id, "map");
  pcl::PointCloud<pcl::PointXYZI> field;
  pcl::fromROSMsg(*esdf, field);
  EXPECT_EQ(field.size(), occupied + free_cells);
  std::vector<Eigen::Vector2d> obstacles;
  for (uint32_t y = 0; y < grid->info.height; ++y)
    for (uint32_t x = 0; x < grid->info.width; ++x)
      if (grid->data[y * grid->info.width + x] == 100)
        obstacles.emplace_back(grid->info.origin.position.x + (x + 0.5) * grid->info.resolution,
                               grid->info.origin.position.y + (y + 0.5) * grid->info.resolution);
  size_t checked = 0, right = 0;
  for (size_t k = 0; k < field.size(); k += 37) {  // a sample of the cells
    double d = 5.0;
    for (const auto& o : obstacles) d = std::min(d, (o - Eigen::Vector2d(field[k].x, field[k].y)).norm());
    ++checked;
    right += std::abs(field[k].intensity - d) < 1e-3;
  }
  EXPECT_EQ(right, checked) << "distances that differ from the brute-force ones";

  ASSERT_TRUE(last_mesh != nullptr);
  {
    std::lock_guard<std::mutex> lock(rviz.mutex);
    std::cout << rviz.arrays << " mesh updates, " << rviz.markers << " markers, " << rviz.shown.size()
              << " blocks on screen\n";
    EXPECT_EQ(rviz.duplicate_ids, 0) << "an id twice in one update";
    EXPECT_EQ(rviz.deleted_twice, 0) << "an id deleted twice";
    EXPECT_EQ(rviz.deleted_never_shown, 0) << "an id deleted that was never shown";
    EXPECT_EQ(rviz.deleted_when_added, 0) << "an id deleted in the update that adds it";
    EXPECT_EQ(rviz.unchanged_adds, 0) << "a block re-sent with the triangles already on screen";
    EXPECT_GT(rviz.shown.size(), 10u);
  }
  size_t triangles = 0;
  for (const auto& m : last_mesh->markers) {
    EXPECT_EQ(m.header.frame_id, "map");
    if (m.action != visualization_msgs::Marker::ADD) continue;
    EXPECT_EQ(m.type, visualization_msgs::Marker::TRIANGLE_LIST);
    EXPECT_EQ(m.points.size() % 3, 0u);
    EXPECT_EQ(m.colors.size(), m.points.size());
    triangles += m.points.size() / 3;
  }
  EXPECT_GT(triangles, 100u);

  // A subscriber that arrives now gets the whole mesh at once: as many
  // triangles as the mesh saved below, and a DELETEALL first.
  // (Within one node a second subscription shares the first's connection:
  // drop it so the new one connects afresh, as another node would.)
  mesh_sub_.shutdown();
  ros::WallDuration(0.5).sleep();
  visualization_msgs::MarkerArrayConstPtr late;
  ros::Subscriber late_sub = nh_.subscribe<visualization_msgs::MarkerArray>(
      "tsdf/mesh", 1, boost::function<void(const visualization_msgs::MarkerArrayConstPtr&)>([&late](const auto& m) {
        if (!late) late = m;
      }));
  ASSERT_TRUE(waitFor([&late] { return late != nullptr; }, 10.0)) << "a late subscriber got no mesh";
  size_t late_triangles = 0;
  EXPECT_EQ(late->markers.front().action, visualization_msgs::Marker::DELETEALL);
  for (const auto& m : late->markers) late_triangles += m.points.size() / 3;
  EXPECT_GE(late_triangles, triangles);
  late_sub.shutdown();

  // Services: into a folder inside the save folder.
  std::string tmpl = saveFolder() + "/fm_tsdf_node_XXXXXX";
  const std::string dir = mkdtemp(&tmpl[0]);
  fisheye_mapping::FilePath srv;
  srv.request.path = dir + "/mesh.ply";
  ASSERT_TRUE(ros::service::call("/tsdf/save_mesh", srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  std::ifstream ply(dir + "/mesh.ply");
  std::string magic;
  ply >> magic;
  EXPECT_EQ(magic, "ply");
  srv.request.path = dir + "/cloud.pcd";
  ASSERT_TRUE(ros::service::call("/tsdf/save_cloud", srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  srv.request.path = dir + "/map.fmtsdf";
  ASSERT_TRUE(ros::service::call("/tsdf/save_map", srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  struct stat st {};
  ASSERT_EQ(stat((dir + "/map.fmtsdf").c_str(), &st), 0);
  EXPECT_GT(st.st_size, 100000);

  // An empty path is an error naming the problem (no file in a default place).
  srv.request.path = "";
  ASSERT_TRUE(ros::service::call("/tsdf/save_mesh", srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_NE(srv.response.message.find("empty"), std::string::npos) << srv.response.message;
  // A relative path lands inside the save folder ($ROS_HOME/fisheye_mapping),
  // at the absolute path the answer gives.
  const std::string relative = "fm_tsdf_node_test_" + std::to_string(getpid()) + ".ply";
  const std::string expected = saveFolder() + "/" + relative;
  srv.request.path = relative;
  ASSERT_TRUE(ros::service::call("/tsdf/save_mesh", srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  EXPECT_NE(srv.response.message.find(" " + expected + ":"), std::string::npos) << srv.response.message;
  EXPECT_EQ(stat(expected.c_str(), &st), 0) << expected;
  std::remove(expected.c_str());

  // Outside the save folder: refused by every save service, naming the
  // folder; the file there keeps its bytes, no new file appears (issue 28).
  char out_tmpl[] = "/tmp/fm_tsdf_outside_XXXXXX";
  const std::string outside = mkdtemp(out_tmpl);
  std::ofstream(outside + "/victim.ply") << "precious";
  for (const char* service : {"save_mesh", "save_cloud", "save_map"}) {
    for (const std::string& path : {outside + "/victim.ply", outside + "/new.file"}) {
      srv.request.path = path;
      ASSERT_TRUE(ros::service::call(std::string("/tsdf/") + service, srv));
      EXPECT_FALSE(srv.response.success) << service << " " << path << ": " << srv.response.message;
      EXPECT_NE(srv.response.message.find("outside the save folder " + saveFolder()), std::string::npos)
          << srv.response.message;
    }
  }
  EXPECT_EQ(fileBytes(outside + "/victim.ply"), "precious");
  EXPECT_FALSE(std::filesystem::exists(outside + "/new.file"));
  // ".." out of the folder: refused, nothing written beside it.
  const std::string escape = "fm_tsdf_escape_" + std::to_string(getpid()) + ".ply";
  srv.request.path = "../" + escape;
  ASSERT_TRUE(ros::service::call("/tsdf/save_mesh", srv));
  EXPECT_FALSE(srv.response.success) << srv.response.message;
  EXPECT_NE(srv.response.message.find("outside the save folder"), std::string::npos) << srv.response.message;
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(saveFolder()).parent_path() / escape));
  // A link inside the folder to a file outside: replaced by the mesh, never
  // followed (the file outside keeps its bytes).
  std::filesystem::create_symlink(outside + "/victim.ply", dir + "/link.ply");
  srv.request.path = dir + "/link.ply";
  ASSERT_TRUE(ros::service::call("/tsdf/save_mesh", srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  EXPECT_FALSE(std::filesystem::is_symlink(dir + "/link.ply"));
  EXPECT_EQ(fileBytes(dir + "/link.ply").substr(0, 4), "ply\n");
  EXPECT_EQ(fileBytes(outside + "/victim.ply"), "precious");
  // A FIFO at the target: refused at once (no blocking), left as it is.
  ASSERT_EQ(mkfifo((dir + "/pipe.pcd").c_str(), 0644), 0);
  srv.request.path = dir + "/pipe.pcd";
  ASSERT_TRUE(ros::service::call("/tsdf/save_cloud", srv));
  EXPECT_FALSE(srv.response.success) << srv.response.message;
  EXPECT_NE(srv.response.message.find("is a FIFO, not a regular file"), std::string::npos) << srv.response.message;
  EXPECT_TRUE(std::filesystem::is_fifo(dir + "/pipe.pcd"));
  std::filesystem::remove_all(outside);

  std_srvs::Trigger clear;
  ASSERT_TRUE(ros::service::call("/tsdf/clear_map", clear));
  EXPECT_TRUE(clear.response.success);
  ASSERT_TRUE(waitFor([] { return last_cloud && last_cloud->width * last_cloud->height == 0; }, 10.0))
      << "the cloud did not empty after clear_map";

  std::ofstream(dir + "/junk.fmtsdf") << "junk";
  srv.request.path = dir + "/junk.fmtsdf";
  ASSERT_TRUE(ros::service::call("/tsdf/load_map", srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_NE(srv.response.message.find("junk.fmtsdf"), std::string::npos) << srv.response.message;

  srv.request.path = dir + "/map.fmtsdf";
  ASSERT_TRUE(ros::service::call("/tsdf/load_map", srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  ASSERT_TRUE(waitFor([&] { return last_cloud && last_cloud->width * last_cloud->height == cloud.size(); }, 10.0))
      << "the loaded map does not give back the same cloud";
  std::system(("rm -rf " + dir).c_str());
}

// max_range through dynamic_reconfigure: the same frames fused again after
// ~set_parameters max_range 3.5 leave no surface beyond 3.5 m of the camera,
// where without a limit the scene reached past 4.5 m.
TEST_F(TsdfFusionNode, MaxRangeChangesAtRunTime) {
  ros::AsyncSpinner spinner(2);
  spinner.start();
  std::atomic<int> fused{0};
  ros::Subscriber done_sub = nh_.subscribe<fisheye_mapping::FrameDone>(
      "tsdf/fusion_done", 20,
      boost::function<void(const fisheye_mapping::FrameDoneConstPtr&)>([&fused](const auto& m) { fused += m->fused; }));
  ASSERT_TRUE(waitFor([&] { return done_sub.getNumPublishers() > 0; }, 10.0));
  const Eigen::Vector3d eye(-1.5, 0.0, 2.5);
  const Eigen::Isometry3d T_W_C = fm::analytic::lookAt(eye, Eigen::Vector3d(3, 0, 0.3));
  // Clears the map, fuses 4 frames from `eye` (min_observations 3) and
  // returns the farthest surface point from it and the number of points.
  auto fuseFromEye = [&](double* farthest, size_t* points) {
    std_srvs::Trigger clear;
    ASSERT_TRUE(ros::service::call("/tsdf/clear_map", clear));
    ASSERT_TRUE(waitFor([] { return last_cloud && last_cloud->width * last_cloud->height == 0; }, 10.0));
    fused = 0;
    const ros::Time t0 = ros::Time::now();
    for (int i = 0; i < 4; ++i) {
      playFrame(T_W_C, t0 + ros::Duration(0.1 * i));
      ros::WallDuration(0.05).sleep();
    }
    ASSERT_TRUE(waitFor([&] { return fused == 4; }, 10.0)) << fused << " of 4 frames fused";
    ASSERT_TRUE(waitFor([] { return last_cloud && last_cloud->width * last_cloud->height > 0; }, 10.0));
    ros::WallDuration(0.6).sleep();  // the publish after the last frame
    pcl::PointCloud<pcl::PointXYZ> cloud;
    pcl::fromROSMsg(*last_cloud, cloud);
    *farthest = 0;
    for (const auto& p : cloud) *farthest = std::max(*farthest, (Eigen::Vector3d(p.x, p.y, p.z) - eye).norm());
    *points = cloud.size();
  };
  double far_unlimited = 0, far_limited = 0;
  size_t n_unlimited = 0, n_limited = 0;
  fuseFromEye(&far_unlimited, &n_unlimited);
  EXPECT_GT(far_unlimited, 4.5);

  dynamic_reconfigure::Reconfigure rc;
  dynamic_reconfigure::DoubleParameter max_range;
  max_range.name = "max_range";
  max_range.value = 3.5;
  rc.request.config.doubles.push_back(max_range);
  ASSERT_TRUE(ros::service::call("/tsdf/set_parameters", rc));
  double applied = -1;
  for (const auto& d : rc.response.config.doubles) {
    if (d.name == "max_range") applied = d.value;
  }
  EXPECT_EQ(applied, 3.5);
  fuseFromEye(&far_limited, &n_limited);
  std::cout << "farthest surface point: " << far_unlimited << " m (" << n_unlimited << " points) without a limit, "
            << far_limited << " m (" << n_limited << " points) with max_range 3.5 m\n";
  EXPECT_LE(far_limited, 3.5 + 0.15);  // a surface point lies within a voxel or two of a measured range
  EXPECT_GT(n_limited, 100u);
  EXPECT_LT(n_limited, n_unlimited);
  EXPECT_TRUE(waitFor([] { return diagValue("max_range (m)") == "3.5"; }, 5.0)) << diagValue("max_range (m)");

  // Out of its declared range (>= 0): refused, not clamped to 0 ("no limit").
  // The answer reports the running 3.5 back, and the map keeps the limit.
  dynamic_reconfigure::Reconfigure bad;
  max_range.value = -3.0;
  bad.request.config.doubles.push_back(max_range);
  ASSERT_TRUE(ros::service::call("/tsdf/set_parameters", bad));
  double reported = -1;
  for (const auto& d : bad.response.config.doubles) {
    if (d.name == "max_range") reported = d.value;
  }
  EXPECT_EQ(reported, 3.5);
  double far_refused = 0;
  size_t n_refused = 0;
  fuseFromEye(&far_refused, &n_refused);
  EXPECT_LE(far_refused, 3.5 + 0.15);
  EXPECT_TRUE(waitFor([] { return diagValue("max_range (m)") == "3.5"; }, 5.0)) << diagValue("max_range (m)");
}


void setMaxRange(const std::string& node, double value) {
  dynamic_reconfigure::Reconfigure rc;
  dynamic_reconfigure::DoubleParameter max_range;
  max_range.name = "max_range";
  max_range.value = value;
  rc.request.config.doubles.push_back(max_range);
  ASSERT_TRUE(ros::service::waitForService(node + "/set_parameters", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call(node + "/set_parameters", rc));
}

// ~rig_source camera_info: depth frames before any CameraInfo of their frame
// wait for it (the last eight, 2 s at most; an older one is dropped and counted); then the
// same orbit fused by both nodes, the camchain one and the one taking the
// model from depth_masked/camera_info, gives the same cloud, point for point.
TEST_F(TsdfFusionNode, RigFromCameraInfoGivesTheSameMap) {
  ros::AsyncSpinner spinner(2);
  spinner.start();
  std::mutex m;
  std::map<std::string, std::string> ci_diag;
  sensor_msgs::PointCloud2ConstPtr cloud, ci_cloud;
  int fused = 0, ci_fused = 0;
  auto diag_sub = nh_.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 20, boost::function<void(const diagnostic_msgs::DiagnosticArrayConstPtr&)>([&](const auto& a) {
        std::lock_guard<std::mutex> lock(m);
        for (const auto& st : a->status) {
          if (st.name.find("ci/tsdf") == std::string::npos) continue;
          for (const auto& kv : st.values) ci_diag[kv.key] = kv.value;
        }
      }));
  auto ciDiag = [&](const std::string& key) {
    std::lock_guard<std::mutex> lock(m);
    return ci_diag.count(key) ? ci_diag[key] : std::string();
  };
  auto cloud_sub = nh_.subscribe<sensor_msgs::PointCloud2>(
      "tsdf/cloud", 2, boost::function<void(const sensor_msgs::PointCloud2ConstPtr&)>([&](const auto& c) {
        std::lock_guard<std::mutex> lock(m);
        cloud = c;
      }));
  auto ci_cloud_sub = nh_.subscribe<sensor_msgs::PointCloud2>(
      "ci/tsdf/cloud", 2, boost::function<void(const sensor_msgs::PointCloud2ConstPtr&)>([&](const auto& c) {
        std::lock_guard<std::mutex> lock(m);
        ci_cloud = c;
      }));
  auto done_sub = nh_.subscribe<fisheye_mapping::FrameDone>(
      "tsdf/fusion_done", 20, boost::function<void(const fisheye_mapping::FrameDoneConstPtr&)>([&](const auto& d) {
        std::lock_guard<std::mutex> lock(m);
        fused += d->fused;
      }));
  auto ci_done_sub = nh_.subscribe<fisheye_mapping::FrameDone>(
      "ci/tsdf/fusion_done", 20, boost::function<void(const fisheye_mapping::FrameDoneConstPtr&)>([&](const auto& d) {
        std::lock_guard<std::mutex> lock(m);
        ci_fused += d->fused;
      }));
  ASSERT_TRUE(waitFor([&] {
    return ci_depth_pub_.getNumSubscribers() > 0 && ci_info_pub_.getNumSubscribers() > 0 &&
           done_sub.getNumPublishers() > 0 && ci_done_sub.getNumPublishers() > 0;
  }, 30.0)) << "the camera_info TSDF node never subscribed";
  // Both from an empty map with the same settings (the test before limited /tsdf's range).
  std_srvs::Trigger clear;
  ASSERT_TRUE(ros::service::call("/tsdf/clear_map", clear));
  ASSERT_TRUE(ros::service::call("/ci/tsdf/clear_map", clear));
  setMaxRange("/tsdf", 0.0);
  setMaxRange("/ci/tsdf", 0.0);

  const ros::Time t0 = ros::Time::now();
  auto orbit = [](int i) {
    const double a = 2 * M_PI * i / 8;
    return fm::analytic::lookAt(Eigen::Vector3d(3 + 4.5 * std::cos(a), 4.5 * std::sin(a), 2.5),
                                Eigen::Vector3d(3, 0, 0.3));
  };
  // Nine depth frames before any CameraInfo, to the camera_info node only
  // (the mask stage's depth and CameraInfo race): they wait for it, the last
  // eight of them; the oldest is dropped ("no camera_info yet") and none is
  // fused before the CameraInfo comes.
  const fm::RigCamera& cam0 = rig_.cameras[0];
  std::vector<sensor_msgs::ImagePtr> frames;
  for (int i = 0; i <= 8; ++i) {
    const ros::Time stamp = t0 + ros::Duration(0.1 * i);
    geometry_msgs::TransformStamped t = tf2::eigenToTransform(orbit(i) * cam0.T_base_cam.inverse());
    t.header.stamp = stamp;
    t.header.frame_id = "map";
    t.child_frame_id = "base_link";
    tf_.sendTransform(t);
    cv_bridge::CvImage img(std_msgs::Header(), "32FC1", scene().render(cam0.model, orbit(i)));
    img.header.stamp = stamp;
    img.header.frame_id = cam0.frame_id;
    frames.push_back(img.toImageMsg());
    ros::WallDuration(0.02).sleep();  // its pose first
    ci_depth_pub_.publish(frames.back());
  }
  ros::WallDuration(0.3).sleep();
  {
    std::lock_guard<std::mutex> lock(m);
    EXPECT_EQ(ci_fused, 0);
  }
  // The CameraInfo (within the 2 s a frame waits): the eight waiting frames
  // are fused. The camchain node gets the same eight.
  std_msgs::Header first;
  first.stamp = t0;
  first.frame_id = cam0.frame_id;
  ci_info_pub_.publish(cameraInfo(first));
  for (int i = 1; i <= 8; ++i) {
    cv_bridge::CvImage grey(frames[i]->header, "mono8", cv::Mat(int(frames[i]->height), int(frames[i]->width), CV_8UC1, cv::Scalar(150)));
    image_pub_.publish(grey.toImageMsg());
    ros::WallDuration(0.01).sleep();
    depth_pub_.publish(frames[i]);
    ros::WallDuration(0.05).sleep();
  }
  ASSERT_TRUE(waitFor([&] {
    std::lock_guard<std::mutex> lock(m);
    return fused == 8 && ci_fused == 8;
  }, 30.0)) << fused << " and " << ci_fused << " of 8 frames fused";
  ASSERT_TRUE(waitFor([&] { return ciDiag("dropped: no camera_info yet").find(", 1 total") != std::string::npos; }, 10.0))
      << "'" << ciDiag("dropped: no camera_info yet") << "'";
  EXPECT_EQ(ciDiag("rig source"), "camera_info");
  ros::WallDuration(1.0).sleep();  // the publishes after the last frame
  std::lock_guard<std::mutex> lock(m);
  ASSERT_TRUE(cloud && ci_cloud);
  pcl::PointCloud<pcl::PointXYZ> a, b;
  pcl::fromROSMsg(*cloud, a);
  pcl::fromROSMsg(*ci_cloud, b);
  EXPECT_GT(a.size(), 1000u);
  ASSERT_EQ(a.size(), b.size());
  auto less = [](const pcl::PointXYZ& p, const pcl::PointXYZ& q) {
    return std::tie(p.x, p.y, p.z) < std::tie(q.x, q.y, q.z);
  };
  std::sort(a.begin(), a.end(), less);
  std::sort(b.begin(), b.end(), less);
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_NEAR(a[i].x, b[i].x, 1e-4) << i;
    ASSERT_NEAR(a[i].y, b[i].y, 1e-4) << i;
    ASSERT_NEAR(a[i].z, b[i].z, 1e-4) << i;
  }
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_tsdf_node");
  return RUN_ALL_TESTS();
}
