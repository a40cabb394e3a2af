// Exact point-to-mesh distances and the map metrics built on them
// (fisheye_mapping/core/eval/mesh_distance.h), checked by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "fisheye_mapping/core/eval/mesh_distance.h"

using namespace fisheye_mapping;

TEST(MeshDistance, PointToTriangleByHand) {
  // One right triangle in z = 0 with legs of 1 m along x and y, and a far one.
  MeshDistance m({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {10, 10, 10}, {11, 10, 10}, {10, 11, 10}},
                 {{0, 1, 2}, {3, 4, 5}}, 0.5f, 0.25f);
  EXPECT_NEAR(m.distance({0.2f, 0.2f, 0.3f}), 0.3f, 1e-6);                   // above the face
  EXPECT_NEAR(m.distance({-0.3f, -0.4f, 0.f}), 0.5f, 1e-6);                  // nearest the corner (0, 0)
  EXPECT_NEAR(m.distance({0.5f, -0.2f, 0.1f}), std::sqrt(0.05f), 1e-6);      // nearest the edge y = 0
  EXPECT_NEAR(m.distance({0.6f, 0.6f, 0.f}), std::sqrt(0.02f), 1e-6);        // beyond the hypotenuse
  EXPECT_TRUE(std::isinf(m.distance({0.2f, 0.2f, 0.7f})));                   // farther than 0.5
  EXPECT_NEAR(m.distance({10.2f, 10.2f, 10.1f}), 0.1f, 1e-5);
  EXPECT_DOUBLE_EQ(m.fractionWithin({{0.2f, 0.2f, 0.05f}, {0.2f, 0.2f, 0.2f}, {5, 5, 5}, {0.1f, 0.1f, -0.09f}}, 0.1f),
                   0.5);
}

TEST(MapMetrics, NearestDistancesAndSharesByHand) {
  const std::vector<Eigen::Vector3f> ours = {{0, 0, 0}, {1, 0, 0}, {0, 2, 0}};
  const std::vector<Eigen::Vector3f> ref = {{0, 0, 0.05f}, {1, 0.3f, 0}, {5, 5, 5}, {0, 2.2f, 0}};
  const auto acc = nearestDistances(ours, ref);  // 0.05, 0.3, 0.2
  ASSERT_EQ(acc.size(), 3u);
  EXPECT_NEAR(acc[0], 0.05f, 1e-6);
  EXPECT_NEAR(acc[1], 0.3f, 1e-6);
  EXPECT_NEAR(acc[2], 0.2f, 1e-6);
  const auto comp = nearestDistances(ref, ours);  // 0.05, 0.3, |(5,5,5)-(0,2,0)|, 0.2
  EXPECT_NEAR(comp[2], std::sqrt(25.f + 9.f + 25.f), 1e-5);
  EXPECT_DOUBLE_EQ(shareWithin(acc, 0.1f), 1.0 / 3);   // accuracy at 0.1 m
  EXPECT_DOUBLE_EQ(shareWithin(comp, 0.25f), 0.5);     // completeness at 0.25 m
  EXPECT_DOUBLE_EQ(shareWithin({}, 0.1f), 0.0);
  EXPECT_TRUE(std::isinf(nearestDistances(ours, {})[0]));
}
