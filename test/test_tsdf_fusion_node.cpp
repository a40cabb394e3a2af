// rostest: the TsdfFusion nodelet fuses analytic fisheye depth frames whose
// poses come over tf; mesh and cloud arrive in the map frame and lie on the
// true surfaces; bad frames are skipped; the services save, load and clear.
#include <sys/stat.h>

#include <fstream>
#include <set>

#include <cv_bridge/cv_bridge.h>
#include <gtest/gtest.h>
#include <pcl_conversions/pcl_conversions.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include "fisheye_mapping/FilePath.h"
#include "fisheye_mapping/core/sim/analytic_scene.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "ros_test_utils.h"

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
std::set<int> on_screen;    // marker ids added and not deleted, as rviz holds them
int mesh_protocol_errors = 0;


class TsdfFusionNode : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string dir = ros::package::getPath("fisheye_mapping") + "/test/data/";
    rig_ = fm::loadKalibrRig(dir + "small_fisheye_camchain.yaml", dir + "small_fisheye_mount.yaml");
    depth_pub_ = nh_.advertise<sensor_msgs::Image>("depth_masked", 50);
    cloud_sub_ = nh_.subscribe<sensor_msgs::PointCloud2>(
        "cloud", 2, boost::function<void(const sensor_msgs::PointCloud2ConstPtr&)>([](const auto& m) {
          last_cloud = m;
        }));
    mesh_sub_ = nh_.subscribe<visualization_msgs::MarkerArray>(
        "mesh", 20, boost::function<void(const visualization_msgs::MarkerArrayConstPtr&)>([](const auto& m) {
          // What rviz would hold: every marker id at most once per message,
          // a DELETE only for an id added before (else rviz warns).
          std::set<int> in_message;
          for (const auto& marker : m->markers) {
            if (marker.action == visualization_msgs::Marker::DELETEALL) {
              on_screen.clear();
              continue;
            }
            if (!in_message.insert(marker.id).second) ++mesh_protocol_errors;
            if (marker.action == visualization_msgs::Marker::DELETE && !on_screen.erase(marker.id)) {
              ++mesh_protocol_errors;
            }
            if (marker.action == visualization_msgs::Marker::ADD) on_screen.insert(marker.id);
          }
          for (const auto& marker : m->markers) {
            if (marker.action == visualization_msgs::Marker::ADD) {
              last_mesh = m;
              break;
            }
          }
        }));
    ASSERT_TRUE(waitFor([this] { return depth_pub_.getNumSubscribers() > 0; }, 30.0)) << "TsdfFusion never subscribed";
  }

  // Publishes the vehicle pose (map -> base_link) and the depth the camera sees.
  void playFrame(const Eigen::Isometry3d& T_W_C, const ros::Time& stamp, const std::string& encoding = "32FC1") {
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
    depth_pub_.publish(img.toImageMsg());
  }

  ros::NodeHandle nh_;
  ros::Publisher depth_pub_;
  ros::Subscriber cloud_sub_, mesh_sub_;
  tf2_ros::TransformBroadcaster tf_;
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

  // The cloud lies on the true surfaces (within a voxel, but at box edges).
  pcl::PointCloud<pcl::PointXYZ> cloud;
  pcl::fromROSMsg(*last_cloud, cloud);
  EXPECT_EQ(last_cloud->header.frame_id, "map");
  const fm::analytic::Scene s = scene();
  size_t near = 0;
  for (const auto& p : cloud) near += std::abs(s.sdf(Eigen::Vector3d(p.x, p.y, p.z))) < 0.05;
  std::cout << cloud.size() << " cloud points, " << near << " within 5 cm of the surface\n";
  EXPECT_GE(near, cloud.size() * 98 / 100);

  ASSERT_TRUE(last_mesh != nullptr);
  EXPECT_EQ(mesh_protocol_errors, 0) << "mesh updates repeated a marker id or deleted one never added";
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
      "mesh", 1, boost::function<void(const visualization_msgs::MarkerArrayConstPtr&)>([&late](const auto& m) {
        if (!late) late = m;
      }));
  ASSERT_TRUE(waitFor([&late] { return late != nullptr; }, 10.0)) << "a late subscriber got no mesh";
  size_t late_triangles = 0;
  EXPECT_EQ(late->markers.front().action, visualization_msgs::Marker::DELETEALL);
  for (const auto& m : late->markers) late_triangles += m.points.size() / 3;
  EXPECT_GE(late_triangles, triangles);
  late_sub.shutdown();

  // Services.
  char tmpl[] = "/tmp/fm_tsdf_node_XXXXXX";
  const std::string dir = mkdtemp(tmpl);
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

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_tsdf_fusion_node");
  return RUN_ALL_TESTS();
}
