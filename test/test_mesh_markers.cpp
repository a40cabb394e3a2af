// MeshMarkerStream (include/fisheye_mapping/ros/mesh_markers.h): the mesh
// updates it makes, fed to a simulator of rviz's MarkerDisplay that flags
// what rviz warns about, and compared with the mesh they stand for. No roscore.
#include <gtest/gtest.h>

#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "fisheye_mapping/ros/mesh_markers.h"

namespace fm = fisheye_mapping;
using visualization_msgs::Marker;
using visualization_msgs::MarkerArray;

namespace {

const char* const kFrame = "map";

// rviz's view of one marker topic: what it shows (id -> points) and the
// problems it reports for an array (rviz's validateMarkerArray warnings, and
// deletes of what is not shown, which rviz drops silently).
class RvizSim {
 public:
  // Applies `a`; returns its problems, "" when none.
  std::string apply(const MarkerArray& a) {
    std::string problems;
    std::set<int> in_array;
    for (size_t i = 0; i < a.markers.size(); ++i) {
      const Marker& m = a.markers[i];
      const std::string at = "marker " + std::to_string(i) + " (id " + std::to_string(m.id) + "): ";
      if (m.header.frame_id != kFrame) problems += at + "frame '" + m.header.frame_id + "'; ";
      if (m.action == Marker::DELETEALL) {
        if (!in_array.empty()) problems += at + "DELETEALL after markers of the same array; ";
        in_array.clear();
        shown_.clear();
        continue;
      }
      if (m.ns != "tsdf_mesh") problems += at + "namespace '" + m.ns + "'; ";
      const bool again = !in_array.insert(m.id).second;
      if (m.action == Marker::DELETE) {
        if (again) problems += at + "deleting just added / listed twice; ";
        if (shown_.erase(m.id) == 0) problems += at + "DELETE of an id not shown; ";
      } else if (m.action == Marker::ADD) {
        if (again) problems += at + "added twice in one array; ";
        problems += badTriangleList(m, at);
        shown_[m.id] = m.points;
      } else {
        problems += at + "unknown action " + std::to_string(m.action) + "; ";
      }
    }
    return problems;
  }
  const std::map<int, std::vector<geometry_msgs::Point>>& shown() const { return shown_; }

 private:
  // What rviz's checkMarkerMsg reports for a TRIANGLE_LIST.
  static std::string badTriangleList(const Marker& m, const std::string& at) {
    std::string p;
    if (m.type != Marker::TRIANGLE_LIST) p += at + "not a TRIANGLE_LIST; ";
    if (m.points.empty() || m.points.size() % 3 != 0) p += at + std::to_string(m.points.size()) + " points; ";
    if (!m.colors.empty() && m.colors.size() != m.points.size()) p += at + "colours != points; ";
    if (m.pose.orientation.w != 1.0) p += at + "not the identity pose; ";
    if (m.scale.x == 0.0 || m.scale.y == 0.0 || m.scale.z == 0.0) p += at + "zero scale; ";
    return p;
  }
  std::map<int, std::vector<geometry_msgs::Point>> shown_;
};

struct Counts {
  int add = 0, del = 0, delete_all = 0;
};
Counts count(const MarkerArray& a) {
  Counts c;
  for (const Marker& m : a.markers) {
    c.add += m.action == Marker::ADD;
    c.del += m.action == Marker::DELETE;
    c.delete_all += m.action == Marker::DELETEALL;
  }
  return c;
}

// `n` triangles of block `b`, different for each `version`.
fm::BlockOutput blockMesh(const fm::BlockIndex& b, int version, int n) {
  fm::BlockOutput out;
  const Eigen::Vector3f origin = 0.8f * b.cast<float>();
  for (int t = 0; t < n; ++t) {
    const float s = 0.01f * float(version % 50) + 0.1f * float(t);
    out.triangles.push_back(origin + Eigen::Vector3f(s, 0, 0));
    out.triangles.push_back(origin + Eigen::Vector3f(0, s + 0.1f, 0));
    out.triangles.push_back(origin + Eigen::Vector3f(0, 0, s + 0.2f));
  }
  out.surface_points.push_back(origin);
  return out;
}

// The blocks with triangles (what rviz should show after an update).
fm::MeshBlocks nonEmpty(const fm::MeshBlocks& blocks) {
  fm::MeshBlocks out;
  for (const auto& kv : blocks)
    if (!kv.second.triangles.empty()) out.insert(kv);
  return out;
}

// Shown state == the non-empty blocks: one distinct id per block, its points
// the block's triangles, nothing else shown.
void expectShows(const RvizSim& sim, const fm::MeshMarkerStream& stream, const fm::MeshBlocks& blocks,
                 const std::string& when) {
  const fm::MeshBlocks want = nonEmpty(blocks);
  std::set<int> ids;
  for (const auto& kv : want) {
    const int id = stream.markerId(kv.first);
    ASSERT_GE(id, 0) << when << ": block " << kv.first.transpose() << " has no id";
    EXPECT_TRUE(ids.insert(id).second) << when << ": id " << id << " of two blocks";
    const auto it = sim.shown().find(id);
    ASSERT_NE(it, sim.shown().end()) << when << ": block " << kv.first.transpose() << " (id " << id << ") not shown";
    const auto& tri = kv.second.triangles;
    ASSERT_EQ(it->second.size(), tri.size()) << when << ": id " << id;
    for (size_t v = 0; v < tri.size(); ++v) {
      EXPECT_FLOAT_EQ(float(it->second[v].x), tri[v].x()) << when << ": id " << id << " vertex " << v;
      EXPECT_FLOAT_EQ(float(it->second[v].z), tri[v].z()) << when << ": id " << id << " vertex " << v;
    }
  }
  EXPECT_EQ(sim.shown().size(), want.size()) << when << ": shown ids that no block has";
  EXPECT_EQ(stream.numShown(), want.size()) << when;
}

// The collision of the old marker id, the 31-bit block hash.
int oldMarkerId(const fm::BlockIndex& b) { return static_cast<int>(fm::BlockIndexHash()(b) & 0x7fffffff); }

const ros::Time kStamp(1700000100, 0);

}  // namespace

TEST(MeshMarkers, OneBlockByHand) {
  fm::MeshMarkerStream stream(kFrame);
  fm::MeshBlocks blocks;
  const fm::BlockIndex b(2, -1, 0);
  blocks[b].triangles = {Eigen::Vector3f(1, 2, 3), Eigen::Vector3f(4, 5, 6), Eigen::Vector3f(7, 8, 9),
                         Eigen::Vector3f(1, 1, 0), Eigen::Vector3f(2, 1, 0), Eigen::Vector3f(1, 2, 0)};
  const MarkerArray a = stream.update(blocks, {b}, kStamp);
  ASSERT_EQ(a.markers.size(), 1u);
  const Marker& m = a.markers[0];
  EXPECT_EQ(m.action, Marker::ADD);
  EXPECT_EQ(m.type, Marker::TRIANGLE_LIST);
  EXPECT_EQ(m.header.frame_id, "map");
  EXPECT_EQ(m.header.stamp, kStamp);
  EXPECT_EQ(m.ns, "tsdf_mesh");
  EXPECT_EQ(m.id, 0);  // the first block seen
  EXPECT_EQ(stream.markerId(b), 0);
  ASSERT_EQ(m.points.size(), 6u);  // 3 x 2 triangles
  EXPECT_EQ(m.colors.size(), 6u);
  EXPECT_EQ(m.points[1].x, 4.0);
  EXPECT_EQ(m.points[1].y, 5.0);
  EXPECT_EQ(m.points[1].z, 6.0);
  EXPECT_EQ(m.points[5].y, 2.0);
  EXPECT_EQ(stream.numShown(), 1u);
  EXPECT_EQ(stream.markerId(fm::BlockIndex(0, 0, 0)), -1);  // never seen
}

TEST(MeshMarkers, ScriptedSequence) {
  fm::MeshMarkerStream stream(kFrame);
  RvizSim rviz;
  fm::MeshBlocks blocks;
  const fm::BlockIndex A(0, 0, 0), B(1, 0, 0), C(0, 5, -2), D(-3, 2, 1);
  auto step = [&](const std::vector<fm::BlockIndex>& changed, int adds, int deletes, const std::string& what) {
    const MarkerArray a = stream.update(blocks, changed, kStamp);
    EXPECT_EQ(rviz.apply(a), "") << what;
    const Counts c = count(a);
    EXPECT_EQ(c.add, adds) << what;
    EXPECT_EQ(c.del, deletes) << what;
    EXPECT_EQ(c.delete_all, 0) << what;
    expectShows(rviz, stream, blocks, what);
  };

  blocks[A] = blockMesh(A, 0, 2);
  blocks[B] = blockMesh(B, 0, 1);
  blocks[C] = fm::BlockOutput();  // recomputed, no triangles, never shown
  step({A, B, C}, 2, 0, "A and B appear, C empty");
  const int id_b = stream.markerId(B);
  EXPECT_EQ(stream.markerId(C), -1);

  blocks[A] = blockMesh(A, 1, 3);
  step({A, B, C}, 1, 0, "A changes; B and C recomputed unchanged");
  step({A, A, B}, 0, 0, "all recomputed the same (A listed twice)");

  blocks.erase(B);
  step({B, C}, 0, 1, "B vanishes");
  step({B}, 0, 0, "B still gone: not deleted twice");

  blocks[B] = blockMesh(B, 2, 4);
  step({B}, 1, 0, "B reappears");
  EXPECT_EQ(stream.markerId(B), id_b) << "a block keeps its id";

  blocks[A].triangles.clear();  // surface points left, no triangles
  step({A}, 0, 1, "A becomes empty");

  // Changes noted between publishes (a mesh saved meanwhile) are not lost.
  blocks[C] = blockMesh(C, 0, 1);
  stream.markChanged({C});
  step({}, 1, 0, "C noted by markChanged");

  // A late subscriber: DELETEALL, then what the others show.
  RvizSim late;
  const MarkerArray all = stream.republishAll(blocks, kStamp);
  ASSERT_FALSE(all.markers.empty());
  EXPECT_EQ(all.markers[0].action, Marker::DELETEALL);
  EXPECT_EQ(count(all).add, 2);  // B and C
  EXPECT_EQ(late.apply(all), "");
  expectShows(late, stream, blocks, "late subscriber");
  EXPECT_EQ(rviz.apply(all), "") << "republishAll also valid for those who had everything";
  expectShows(rviz, stream, blocks, "after republishAll");

  // clear_map: one DELETEALL, ids restart.
  const MarkerArray cleared = stream.clear();
  ASSERT_EQ(cleared.markers.size(), 1u);
  EXPECT_EQ(cleared.markers[0].action, Marker::DELETEALL);
  EXPECT_EQ(rviz.apply(cleared), "");
  blocks.clear();
  EXPECT_TRUE(rviz.shown().empty());
  EXPECT_EQ(stream.numShown(), 0u);
  EXPECT_EQ(stream.markerId(B), -1);
  step({B}, 0, 0, "B reported after clear, gone: no DELETE");
  blocks[D] = blockMesh(D, 0, 2);
  step({D}, 1, 0, "D after clear");
  EXPECT_EQ(stream.markerId(D), 0);
}

TEST(MeshMarkers, IdsOfBlocksWhoseHashesCollide) {
  // Found by search over [-40, 40]^3; checked here, not assumed.
  const fm::BlockIndex p(-40, -1, 39), q(-40, 1, -39);
  ASSERT_EQ(oldMarkerId(p), oldMarkerId(q)) << "the pair must collide under the old id";
  fm::MeshMarkerStream stream(kFrame);
  RvizSim rviz;
  fm::MeshBlocks blocks;
  blocks[p] = blockMesh(p, 0, 1);
  blocks[q] = blockMesh(q, 0, 2);
  const MarkerArray a = stream.update(blocks, {p, q}, kStamp);
  EXPECT_EQ(rviz.apply(a), "");
  EXPECT_EQ(count(a).add, 2);
  EXPECT_NE(stream.markerId(p), stream.markerId(q));
  expectShows(rviz, stream, blocks, "colliding pair");
}

// 1000 seeded updates over a pool of blocks: appear, change, vanish, empty,
// recomputed unchanged, the odd clear and late subscriber. Each array is
// checked by the simulator and against the truth: exactly the blocks whose
// triangles changed are added, exactly those that lost them deleted.
TEST(MeshMarkers, RandomizedUpdates) {
  std::mt19937 rng(17);
  std::vector<fm::BlockIndex> pool = {fm::BlockIndex(-40, -1, 39), fm::BlockIndex(-40, 1, -39)};
  for (int i = 0; pool.size() < 60; ++i) pool.emplace_back(i % 5 - 2, (i / 5) % 4, i / 20 - 1);
  auto pick = [&] { return pool[std::uniform_int_distribution<size_t>(0, pool.size() - 1)(rng)]; };
  auto roll = [&](int n) { return std::uniform_int_distribution<int>(0, n - 1)(rng); };

  fm::MeshMarkerStream stream(kFrame);
  RvizSim rviz, late;
  bool late_joined = false;
  fm::MeshBlocks blocks, sent;  // sent: the non-empty blocks at the last update
  int version = 0, adds = 0, deletes = 0, clears = 0;
  for (int u = 0; u < 1000; ++u) {
    const std::string when = "update " + std::to_string(u);
    if (roll(100) == 0) {  // clear_map
      const MarkerArray c = stream.clear();
      ASSERT_EQ(c.markers.size(), 1u);
      EXPECT_EQ(rviz.apply(c), "") << when;
      if (late_joined) {
        EXPECT_EQ(late.apply(c), "") << when;
      }
      blocks.clear(), sent.clear();
      ++clears;
    }
    std::vector<fm::BlockIndex> changed, noted;
    for (int k = roll(8); k > 0; --k) {
      const fm::BlockIndex b = pick();
      switch (roll(5)) {
        case 0: case 1: blocks[b] = blockMesh(b, ++version, 1 + roll(4)); break;  // appears / changes
        case 2: blocks.erase(b); break;                                            // vanishes
        case 3: if (blocks.count(b)) blocks[b].triangles.clear(); break;           // empty
        default: break;                                                            // recomputed, same
      }
      (roll(4) == 0 ? noted : changed).push_back(b);
    }
    stream.markChanged(noted);
    const MarkerArray a = stream.update(blocks, changed, kStamp);
    EXPECT_EQ(rviz.apply(a), "") << when;
    if (late_joined) {
      EXPECT_EQ(late.apply(a), "") << when << " (late subscriber)";
    }

    const fm::MeshBlocks now = nonEmpty(blocks);
    int want_add = 0, want_del = 0;
    for (const auto& kv : now) {
      const auto it = sent.find(kv.first);
      want_add += it == sent.end() || it->second.triangles != kv.second.triangles;
    }
    for (const auto& kv : sent) want_del += now.count(kv.first) == 0;
    const Counts c = count(a);
    EXPECT_EQ(c.add, want_add) << when;
    EXPECT_EQ(c.del, want_del) << when;
    EXPECT_EQ(c.delete_all, 0) << when;
    adds += c.add, deletes += c.del;
    sent = now;
    expectShows(rviz, stream, blocks, when);
    if (late_joined) expectShows(late, stream, blocks, when + " (late subscriber)");
    if (u == 300) {
      EXPECT_EQ(late.apply(stream.republishAll(blocks, kStamp)), "");
      late_joined = true;
      expectShows(late, stream, blocks, "late subscriber joined");
    }
    if (::testing::Test::HasFailure()) return;  // one update's report, not a thousand
  }
  // The script did exercise every path.
  EXPECT_GT(adds, 500);
  EXPECT_GT(deletes, 100);
  EXPECT_GT(clears, 3);
}
