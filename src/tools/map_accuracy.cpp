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
//
// Points with a non-finite coordinate (NaN, inf) are skipped in both clouds and
// counted in the first line of output. Exit status: 0, 1 on unreadable or empty
// input or an output that cannot be written (--csv: written under a temporary
// name, renamed once complete), 2 on bad options.
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/core/eval/mesh_distance.h"

namespace fm = fisheye_mapping;
namespace cli = fm::cli;

namespace {

using Cloud = pcl::PointCloud<pcl::PointXYZ>;

// The finite points of a PCD file, and how many were skipped.
struct Points {
  std::vector<Eigen::Vector3f> p;
  size_t skipped = 0;
};

Points load(const std::string& path) {
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(path, ec);
  if (ec) throw std::runtime_error("cannot read " + path + ": " + ec.message());
  if (bytes == 0) throw std::runtime_error(path + " is empty (0 bytes), not a PCD cloud");
  // Read as a blob first: PCL 1.13's conversion to points takes &cloud[0] of
  // an empty cloud (undefined behaviour, UBSan's report), so a file of no
  // points is answered here.
  pcl::PCLPointCloud2 blob;
  if (pcl::io::loadPCDFile(path, blob) != 0) throw std::runtime_error("cannot read " + path + " as a PCD cloud");
  if (std::uint64_t(blob.width) * blob.height == 0) throw std::runtime_error(path + " has no finite point (no point)");
  Cloud c;
  pcl::fromPCLPointCloud2(blob, c);
  Points out;
  out.p.reserve(c.size());
  for (const auto& q : c) {
    if (std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z)) out.p.emplace_back(q.x, q.y, q.z);
    else ++out.skipped;
  }
  if (out.p.empty()) {
    throw std::runtime_error(path + " has no finite point (" + std::to_string(out.skipped) + " non-finite)");
  }
  return out;
}

double share(const std::vector<float>& d, float t) { return fm::shareWithin(d, t); }

const char* kUsage =
    "usage: map_accuracy --cloud MAP.pcd [--mesh SCENE.ply] [--ref REF.pcd] [--t 0.05,0.1,...]\n"
    "                    [--trail-tol M] [--csv OUT.csv]\n"
    "  --cloud MAP.pcd   the map's cloud (required)\n"
    "  --mesh SCENE.ply  share of map points within t of this scene mesh\n"
    "  --ref REF.pcd     accuracy and completeness against this reference cloud\n"
    "                    (e.g. the map fused from ground-truth depth); at least one of\n"
    "                    --mesh, --ref\n"
    "  --t LIST          thresholds t in metres, comma-separated (default 0.05,0.1,0.25,0.5)\n"
    "  --trail-tol M     with --mesh: count map points farther than M from the scene\n"
    "                    (trail voxels; default 0: not counted)\n"
    "  --csv OUT.csv     also write the figures as CSV\n";

}  // namespace

int main(int argc, char** argv) {
  std::string cloud_path, mesh_path, ref_path, csv_path;
  std::vector<double> thresholds{0.05, 0.1, 0.25, 0.5};
  float trail_tol = 0.f;
  const int rc = cli::parseCommandLine("map_accuracy", kUsage, [&] {
    cli::forEachOption(argc, argv, 1, [&](const std::string& a, const cli::NextValue& next) {
      if (a == "--cloud") cloud_path = next();
      else if (a == "--mesh") mesh_path = next();
      else if (a == "--ref") ref_path = next();
      else if (a == "--t") thresholds = cli::parseDoubleList(a, next(), 1e-6, 1e3);
      else if (a == "--trail-tol") trail_tol = static_cast<float>(cli::parseDouble(a, next(), 0.0, 1e3));
      else if (a == "--csv") csv_path = next();
      else return false;
      return true;
    });
    if (cloud_path.empty() || (mesh_path.empty() && ref_path.empty())) {
      throw cli::UsageError("--cloud and one of --mesh, --ref are required");
    }
    cli::requireInputFile("--cloud", cloud_path);
    if (!mesh_path.empty()) cli::requireInputFile("--mesh", mesh_path);
    if (!ref_path.empty()) cli::requireInputFile("--ref", ref_path);
    if (!csv_path.empty()) cli::requireOutputFile("--csv", csv_path);
  });
  if (rc >= 0) return rc;
  try {
    float tmax = trail_tol;
    for (double t : thresholds) tmax = std::max(tmax, static_cast<float>(t));
    const Points map = load(cloud_path);
    std::vector<float> acc_mesh, acc_ref, comp_ref;
    std::size_t trails = 0;
    if (!mesh_path.empty()) {
      std::error_code ec;
      if (std::filesystem::file_size(mesh_path, ec) == 0 && !ec)
        throw std::runtime_error(mesh_path + " is empty (0 bytes), not a PLY mesh");
      const auto gt = fm::MeshDistance::fromPly(mesh_path, tmax);
      acc_mesh.resize(map.p.size());
#pragma omp parallel for
      for (long i = 0; i < long(map.p.size()); ++i) acc_mesh[i] = gt.distance(map.p[i]);
      if (trail_tol > 0)
        for (float d : acc_mesh) trails += d > trail_tol;
    }
    Points ref;
    const bool have_ref = !ref_path.empty();
    if (have_ref) {
      ref = load(ref_path);
      acc_ref = fm::nearestDistances(map.p, ref.p);
      comp_ref = fm::nearestDistances(ref.p, map.p);
    }
    std::string head = std::to_string(map.p.size()) + " map points";
    if (have_ref) head += ", " + std::to_string(ref.p.size()) + " reference points";
    if (trail_tol > 0)
      head += ", " + std::to_string(trails) + " points farther than " + std::to_string(trail_tol) +
              " m from the scene (trail voxels)";
    if (map.skipped || ref.skipped) {
      head += "; non-finite points skipped: " + std::to_string(map.skipped) + " in " + cloud_path;
      if (have_ref) head += ", " + std::to_string(ref.skipped) + " in " + ref_path;
    }
    std::printf("%s\n", head.c_str());
    std::printf("| t (m) |%s%s\n|---|%s%s\n", acc_mesh.empty() ? "" : " within t of the scene |",
                have_ref ? " accuracy | completeness |" : "", acc_mesh.empty() ? "" : "---:|",
                have_ref ? "---:|---:|" : "");
    std::ostringstream csv;
    csv << "t,scene_within,accuracy,completeness,points,ref_points,trails\n";
    for (double td : thresholds) {
      const float t = static_cast<float>(td);
      std::printf("| %.2f |", t);
      if (!acc_mesh.empty()) std::printf(" %.1f %% |", 100 * share(acc_mesh, t));
      if (have_ref) std::printf(" %.1f %% | %.1f %% |", 100 * share(acc_ref, t), 100 * share(comp_ref, t));
      std::printf("\n");
      csv << t << "," << (acc_mesh.empty() ? NAN : share(acc_mesh, t)) << "," << (have_ref ? share(acc_ref, t) : NAN)
          << "," << (have_ref ? share(comp_ref, t) : NAN) << "," << map.p.size() << "," << ref.p.size() << ","
          << trails << "\n";
    }
    if (!csv_path.empty()) {
      cli::writeTextAtomically(csv_path, [&](std::ostream& f) { f << csv.str(); });
    }
  } catch (const std::exception& e) {
    std::cerr << "map_accuracy: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
