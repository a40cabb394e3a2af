// map_accuracy: how close a map cloud is to ground truth, for several t.
//
//   map_accuracy --cloud MAP.pcd [--mesh SCENE.ply] [--ref REF.pcd]
//                [--t 0.05,0.1,0.25,0.5] [--trail-tol M] [--csv OUT.csv]
//
// --mesh  share of the map's points within t of a scene mesh (exact
//         point-to-triangle distances), and with --trail-tol the number of map
//         points farther than that from the scene ("trail voxels": occupied in
//         the map where the static scene is empty; one surface point per voxel)
// --ref   the paper's protocol against a reference cloud (e.g. the map fused
//         from ground-truth depth): accuracy = share of the map's points within
//         t of the reference, completeness = share of the reference's points
//         within t of the map (nearest neighbours by PCL's kd-tree)
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "fisheye_mapping/core/mesh_distance.h"

namespace fm = fisheye_mapping;

namespace {

using Cloud = pcl::PointCloud<pcl::PointXYZ>;

Cloud::Ptr load(const std::string& path) {
  Cloud::Ptr c(new Cloud);
  if (pcl::io::loadPCDFile(path, *c) != 0) throw std::runtime_error("cannot read " + path);
  return c;
}

std::vector<Eigen::Vector3f> points(const Cloud& c) {
  std::vector<Eigen::Vector3f> v;
  v.reserve(c.size());
  for (const auto& p : c) v.emplace_back(p.x, p.y, p.z);
  return v;
}

double share(const std::vector<float>& d, float t) { return fm::shareWithin(d, t); }

void usage() {
  std::cerr << "usage: map_accuracy --cloud MAP.pcd [--mesh SCENE.ply] [--ref REF.pcd] [--t 0.05,0.1,...]\n"
               "                    [--trail-tol M] [--csv OUT.csv]\n";
}

}  // namespace

int main(int argc, char** argv) {
  std::string cloud_path, mesh_path, ref_path, csv_path, ts = "0.05,0.1,0.25,0.5";
  float trail_tol = 0.f;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--cloud") cloud_path = argv[i + 1];
    else if (a == "--mesh") mesh_path = argv[i + 1];
    else if (a == "--ref") ref_path = argv[i + 1];
    else if (a == "--t") ts = argv[i + 1];
    else if (a == "--trail-tol") trail_tol = std::stof(argv[i + 1]);
    else if (a == "--csv") csv_path = argv[i + 1];
    else {
      usage();
      return 2;
    }
  }
  if (cloud_path.empty() || (mesh_path.empty() && ref_path.empty())) {
    usage();
    return 2;
  }
  try {
    std::vector<float> thresholds;
    std::stringstream ss(ts);
    for (std::string t; std::getline(ss, t, ',');) thresholds.push_back(std::stof(t));
    float tmax = trail_tol;
    for (float t : thresholds) tmax = std::max(tmax, t);
    const Cloud::Ptr map = load(cloud_path);
    std::vector<float> acc_mesh, acc_ref, comp_ref;
    std::size_t trails = 0;
    if (!mesh_path.empty()) {
      const auto gt = fm::MeshDistance::fromPly(mesh_path, tmax);
      acc_mesh.resize(map->size());
#pragma omp parallel for
      for (long i = 0; i < long(map->size()); ++i) {
        const auto& p = (*map)[i];
        acc_mesh[i] = gt.distance(Eigen::Vector3f(p.x, p.y, p.z));
      }
      if (trail_tol > 0)
        for (float d : acc_mesh) trails += d > trail_tol;
    }
    Cloud::Ptr ref;
    if (!ref_path.empty()) {
      ref = load(ref_path);
      const auto m = points(*map), r = points(*ref);
      acc_ref = fm::nearestDistances(m, r);
      comp_ref = fm::nearestDistances(r, m);
    }
    std::printf("%zu map points%s%s\n", map->size(), ref ? (", " + std::to_string(ref->size()) + " reference points").c_str() : "",
                trail_tol > 0 ? (", " + std::to_string(trails) + " points farther than " + std::to_string(trail_tol) +
                                 " m from the scene (trail voxels)").c_str()
                              : "");
    std::printf("| t (m) |%s%s\n|---|%s%s\n", acc_mesh.empty() ? "" : " within t of the scene |",
                ref ? " accuracy | completeness |" : "", acc_mesh.empty() ? "" : "---:|", ref ? "---:|---:|" : "");
    std::ofstream csv;
    if (!csv_path.empty()) {
      csv.open(csv_path);
      csv << "t,scene_within,accuracy,completeness,points,ref_points,trails\n";
    }
    for (float t : thresholds) {
      std::printf("| %.2f |", t);
      if (!acc_mesh.empty()) std::printf(" %.1f %% |", 100 * share(acc_mesh, t));
      if (ref) std::printf(" %.1f %% | %.1f %% |", 100 * share(acc_ref, t), 100 * share(comp_ref, t));
      std::printf("\n");
      if (csv.is_open())
        csv << t << "," << (acc_mesh.empty() ? NAN : share(acc_mesh, t)) << "," << (ref ? share(acc_ref, t) : NAN) << ","
            << (ref ? share(comp_ref, t) : NAN) << "," << map->size() << "," << (ref ? ref->size() : 0) << "," << trails
            << "\n";
    }
  } catch (const std::exception& e) {
    std::cerr << "map_accuracy: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
