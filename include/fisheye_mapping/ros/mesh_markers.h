// The TSDF mesh as a stream of visualization_msgs/MarkerArray updates that
// rviz's MarkerDisplay takes without a warning (library fisheye_mapping_ros).
//
// One TRIANGLE_LIST marker per mesh block (meshBlockMarker, namespace
// tsdf_mesh). What rviz checks, and this class keeps to:
//  - ids: a fresh int per block index, handed out in order the first time the
//    block is shown and kept in a map (never a hash of the index: two blocks
//    with one id would hide each other);
//  - an update() carries only the blocks whose triangles differ from what was
//    last sent (ADD, which rviz treats as modify for a shown id) and a DELETE
//    only for a block that is on screen and is now empty or gone; so no id
//    twice in one array, no DELETE of an id never added or already deleted,
//    no DELETE of an id the same array adds;
//  - clear(): one DELETEALL, and everything forgotten (ids restart at 0).
//
// The mesher (TsdfMesher::update) reports every block it recomputed, most of
// them unchanged or empty and never shown; the triangles sent for each shown
// block are remembered as a fingerprint (count and a hash of the vertices and their intensities), so
// those cost nothing on the wire.
//
// Not thread-safe (the nodelet calls it under its lock).
#ifndef FISHEYE_MAPPING_ROS_MESH_MARKERS_H_
#define FISHEYE_MAPPING_ROS_MESH_MARKERS_H_

#include <cstddef>
#include <string>
#include <unordered_map>
#include <vector>

#include <ros/time.h>
#include <visualization_msgs/MarkerArray.h>

#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"

namespace fisheye_mapping {

/// The mesher's output: block index -> triangles (TsdfMesher::blocks()).
using MeshBlocks = std::unordered_map<BlockIndex, BlockOutput, BlockIndexHash>;

class MeshMarkerStream {
 public:
  /// Markers in `frame` (the map's world frame), coloured by `coloring`.
  explicit MeshMarkerStream(std::string frame, MeshColoring coloring = MeshColoring::kIntensity);
  MeshColoring coloring() const { return coloring_; }

  /// Notes blocks whose mesh may have changed (what TsdfMesher::update or
  /// rebuild returned), to be looked at by the next update(). Call it for
  /// every mesher update whose result is not passed to update() directly
  /// (e.g. a mesh saved between two publishes).
  void markChanged(const std::vector<BlockIndex>& changed);

  /// The markers for the blocks marked changed so far plus `changed`, read
  /// from `blocks`: ADD for a block whose triangles differ from those last
  /// sent, DELETE for a shown block now empty or missing, nothing for the
  /// rest. Empty when nothing changed on screen (then publish nothing).
  visualization_msgs::MarkerArray update(const MeshBlocks& blocks, const std::vector<BlockIndex>& changed,
                                         const ros::Time& stamp);

  /// One DELETEALL in the frame; forgets ids, shown blocks and pending changes.
  visualization_msgs::MarkerArray clear();

  /// For a subscriber that connects late: DELETEALL, then an ADD per shown
  /// block with its triangles from `blocks`. Changes nothing: call it right
  /// after update() (nothing pending), so that the late subscriber sees what
  /// the others see.
  visualization_msgs::MarkerArray republishAll(const MeshBlocks& blocks, const ros::Time& stamp) const;

  /// The marker id of `block`, or -1 when it has none (never shown since the
  /// last clear()).
  int markerId(const BlockIndex& block) const;
  /// Number of blocks on screen (sent with triangles and not deleted since).
  std::size_t numShown() const { return shown_.size(); }
  const std::string& frame() const { return frame_; }

 private:
  // Count and hash of the vertices: equal for equal triangles.
  struct Fingerprint {
    std::size_t vertices = 0;
    std::size_t hash = 0;
    bool operator==(const Fingerprint& o) const { return vertices == o.vertices && hash == o.hash; }
  };
  static Fingerprint fingerprint(const BlockOutput& block);
  int idFor(const BlockIndex& block);
  // The marker for one pending block (false: nothing to send).
  bool blockUpdate(const MeshBlocks& blocks, const BlockIndex& block, const ros::Time& stamp,
                   visualization_msgs::Marker& out);

  std::string frame_;
  MeshColoring coloring_;
  std::unordered_map<BlockIndex, int, BlockIndexHash> ids_;  // kept while the block is off screen too
  std::unordered_map<BlockIndex, Fingerprint, BlockIndexHash> shown_;  // what rviz has now
  BlockSet pending_;
  int next_id_ = 0;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_MESH_MARKERS_H_
