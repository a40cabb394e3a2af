// The mesh as rviz markers, update by update (see include/fisheye_mapping/ros/mesh_markers.h).
#include "fisheye_mapping/ros/mesh_markers.h"

#include <algorithm>
#include <climits>
#include <stdexcept>
#include <string_view>
#include <utility>

#include "fisheye_mapping/ros/conversions.h"

namespace fisheye_mapping {

namespace {

// Lexicographic: the markers of one update go out in a reproducible order.
bool indexLess(const BlockIndex& a, const BlockIndex& b) {
  return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
}

}  // namespace

MeshMarkerStream::MeshMarkerStream(std::string frame, MeshColoring coloring)
    : frame_(std::move(frame)), coloring_(coloring) {}

MeshMarkerStream::Fingerprint MeshMarkerStream::fingerprint(const BlockOutput& block) {
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "vertices must be packed to be hashed as bytes");
  const std::string_view bytes(reinterpret_cast<const char*>(block.triangles.data()),
                               block.triangles.size() * sizeof(Eigen::Vector3f));
  const std::string_view grey(reinterpret_cast<const char*>(block.triangle_grey.data()), block.triangle_grey.size());
  return Fingerprint{block.triangles.size(),
                     std::hash<std::string_view>()(bytes) * 31u + std::hash<std::string_view>()(grey)};
}

int MeshMarkerStream::idFor(const BlockIndex& block) {
  const auto it = ids_.find(block);
  if (it != ids_.end()) return it->second;
  if (next_id_ == INT_MAX) throw std::overflow_error("MeshMarkerStream: marker ids exhausted (call clear())");
  ids_.emplace(block, next_id_);
  return next_id_++;
}

int MeshMarkerStream::markerId(const BlockIndex& block) const {
  const auto it = ids_.find(block);
  return it == ids_.end() ? -1 : it->second;
}

void MeshMarkerStream::markChanged(const std::vector<BlockIndex>& changed) {
  pending_.insert(changed.begin(), changed.end());
}

bool MeshMarkerStream::blockUpdate(const MeshBlocks& blocks, const BlockIndex& block, const ros::Time& stamp,
                                   visualization_msgs::Marker& out) {
  const auto it = blocks.find(block);
  const bool has_mesh = it != blocks.end() && !it->second.triangles.empty();
  const auto on_screen = shown_.find(block);
  if (!has_mesh) {
    // Only what rviz shows is deleted: the mesher reports many blocks that
    // were recomputed to nothing and never sent.
    if (on_screen == shown_.end()) return false;
    shown_.erase(on_screen);
    out = meshBlockMarker(nullptr, ids_.at(block), frame_, stamp);
    return true;
  }
  const Fingerprint now = fingerprint(it->second);
  if (on_screen != shown_.end() && on_screen->second == now) return false;  // recomputed, same triangles
  shown_[block] = now;
  out = meshBlockMarker(&it->second, idFor(block), frame_, stamp, coloring_);
  return true;
}

visualization_msgs::MarkerArray MeshMarkerStream::update(const MeshBlocks& blocks,
                                                         const std::vector<BlockIndex>& changed,
                                                         const ros::Time& stamp) {
  markChanged(changed);
  std::vector<BlockIndex> todo(pending_.begin(), pending_.end());
  pending_.clear();
  std::sort(todo.begin(), todo.end(), indexLess);
  // One marker per block at most (todo holds each block once), so no id
  // appears twice in the array.
  visualization_msgs::MarkerArray markers;
  visualization_msgs::Marker m;
  for (const BlockIndex& b : todo) {
    if (blockUpdate(blocks, b, stamp, m)) markers.markers.push_back(std::move(m));
  }
  return markers;
}

visualization_msgs::MarkerArray MeshMarkerStream::clear() {
  ids_.clear();
  shown_.clear();
  pending_.clear();
  next_id_ = 0;
  visualization_msgs::MarkerArray markers;
  markers.markers.push_back(deleteAllMarker(frame_));
  markers.markers.back().ns = kMeshMarkerNamespace;
  return markers;
}

visualization_msgs::MarkerArray MeshMarkerStream::republishAll(const MeshBlocks& blocks,
                                                               const ros::Time& stamp) const {
  std::vector<BlockIndex> on_screen;
  on_screen.reserve(shown_.size());
  for (const auto& kv : shown_) on_screen.push_back(kv.first);
  std::sort(on_screen.begin(), on_screen.end(), indexLess);
  // DELETEALL first: rviz warns about one after ADDs ("these will never show").
  visualization_msgs::MarkerArray markers;
  markers.markers.push_back(deleteAllMarker(frame_));
  markers.markers.back().ns = kMeshMarkerNamespace;
  for (const BlockIndex& b : on_screen) {
    const auto it = blocks.find(b);
    // Only with changes pending (update() not called first) can a shown block be gone.
    if (it == blocks.end() || it->second.triangles.empty()) continue;
    markers.markers.push_back(meshBlockMarker(&it->second, ids_.at(b), frame_, stamp, coloring_));
  }
  return markers;
}

}  // namespace fisheye_mapping
