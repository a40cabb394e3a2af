// map_accuracy: share of a map cloud's points within t of a ground-truth scene
// mesh (e.g. make_drive's static_scene.ply), for several t.
//
//   map_accuracy --cloud MAP.pcd --mesh SCENE.ply [--t 0.05,0.1,0.25,0.5]
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "fisheye_mapping/core/mesh_distance.h"

namespace fm = fisheye_mapping;

int main(int argc, char** argv) {
  std::string cloud_path, mesh_path, ts = "0.05,0.1,0.25,0.5";
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--cloud") cloud_path = argv[i + 1];
    else if (a == "--mesh") mesh_path = argv[i + 1];
    else if (a == "--t") ts = argv[i + 1];
    else {
      std::cerr << "usage: map_accuracy --cloud MAP.pcd --mesh SCENE.ply [--t 0.05,0.1,...]\n";
      return 2;
    }
  }
  if (cloud_path.empty() || mesh_path.empty()) {
    std::cerr << "usage: map_accuracy --cloud MAP.pcd --mesh SCENE.ply [--t 0.05,0.1,...]\n";
    return 2;
  }
  try {
    std::vector<float> thresholds;
    std::stringstream ss(ts);
    for (std::string t; std::getline(ss, t, ',');) thresholds.push_back(std::stof(t));
    float tmax = 0;
    for (float t : thresholds) tmax = std::max(tmax, t);
    pcl::PointCloud<pcl::PointXYZ> pc;
    if (pcl::io::loadPCDFile(cloud_path, pc) != 0) throw std::runtime_error("cannot read " + cloud_path);
    std::vector<Eigen::Vector3f> pts;
    for (const auto& p : pc) pts.emplace_back(p.x, p.y, p.z);
    const auto gt = fm::MeshDistance::fromPly(mesh_path, tmax);
    std::printf("%zu map points, %zu scene triangles\n| t (m) | points within t |\n|---|---:|\n", pts.size(),
                gt.triangles());
    for (float t : thresholds) std::printf("| %.2f | %.1f %% |\n", t, 100 * gt.fractionWithin(pts, t));
  } catch (const std::exception& e) {
    std::cerr << "map_accuracy: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
