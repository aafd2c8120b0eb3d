// Quality measures against analytic answers.
#include "test_helpers.h"

#include <voxwarp/surface_distance.h>

#include <gtest/gtest.h>

namespace voxwarp {
namespace {

TEST(SurfaceDistance, ConcentricSpheresAreTheirRadiusDifferenceApart) {
    const TriangleMesh inner = test::sphere_mesh({0, 0, 0}, 1.0, 5), outer = test::sphere_mesh({0, 0, 0}, 1.25, 5);
    const DistanceStats d = symmetric_distance(inner, outer);
    // Chordal error of the tessellations is below 2e-4 of the radius.
    EXPECT_NEAR(d.mean, 0.25, 1e-3);
    EXPECT_NEAR(d.max, 0.25, 1e-3);
}

TEST(SurfaceDistance, MeshAgainstItselfIsZero) {
    const TriangleMesh torus = test::torus_mesh({0, 0, 0}, 1.0, 0.3, 64, 32);
    const DistanceStats d = symmetric_distance(torus, torus);
    EXPECT_LE(d.max, 1e-12);
}

TEST(SurfaceDistance, PointsToSurfaceAreExact) {
    const TriangleMesh box = test::box_mesh({0, 0, 0}, {1, 1, 1}, 2);
    const auto d = distances_to_surface({{0.5, 0.5, 0.5}, {2, 0.5, 0.5}, {2, 2, 2}}, box);
    EXPECT_NEAR(d[0], 0.5, 1e-12);
    EXPECT_NEAR(d[1], 1.0, 1e-12);
    EXPECT_NEAR(d[2], std::sqrt(3.0), 1e-12);
}

TEST(Creases, CubeHasTwelveSharpEdgesWorth) {
    const int n = 4; // each cube edge is split into n mesh edges
    const CreaseStats c = count_creases(test::box_mesh({0, 0, 0}, {1, 2, 3}, n), 30.0);
    EXPECT_EQ(c.creased, 12 * n);
    const CreaseStats smooth = count_creases(test::sphere_mesh({0, 0, 0}, 1.0, 4), 30.0);
    EXPECT_EQ(smooth.creased, 0);
}

} // namespace
} // namespace voxwarp
