#include "test_helpers.h"

#include <voxwarp/winding_number.h>

#include <gtest/gtest.h>

#include <random>

namespace voxwarp {
namespace {

TEST(WindingNumber, ClosedSphereIsOneInsideZeroOutside) {
    const TriangleMesh sphere = test::sphere_mesh({0, 0, 0}, 1.0, 3);
    const WindingNumber w(sphere);
    // The exact sum is 1 inside and 0 outside to rounding; the hierarchy within its far-field error.
    EXPECT_NEAR(w.exact({0, 0, 0}), 1.0, 1e-9);
    EXPECT_NEAR(w.exact({1.5, 0, 0}), 0.0, 1e-9);
    EXPECT_NEAR(w({0, 0, 0}), 1.0, 0.03);
    EXPECT_NEAR(w({0.5, 0.3, -0.2}), 1.0, 0.03);
    EXPECT_NEAR(w({1.5, 0, 0}), 0.0, 0.03);
    EXPECT_NEAR(w({10, -20, 5}), 0.0, 1e-3);
}

TEST(WindingNumber, HierarchyMatchesExactSum) {
    TriangleMesh hemisphere = test::sphere_mesh({0, 0, 0}, 1.0, 4);
    // Cut the sphere open: keep the faces above z = -0.3, a hole the winding number must bridge.
    std::vector<std::array<std::int32_t, 3>> kept;
    for (const auto& f : hemisphere.triangles)
        if (hemisphere.vertices[f[0]].z() > -0.3) kept.push_back(f);
    hemisphere.triangles = kept;
    const WindingNumber w(hemisphere);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-1.5, 1.5);
    double worst = 0;
    for (int i = 0; i < 2000; ++i) {
        const Eigen::Vector3d q(u(rng), u(rng), u(rng));
        worst = std::max(worst, std::abs(w(q) - w.exact(q)));
    }
    EXPECT_LE(worst, 0.03);
    // Near the middle of the open sphere the surface still surrounds most directions.
    EXPECT_GT(w({0, 0, 0.2}), 0.5);
}

TEST(WindingNumber, NearTheSurfaceEveryTurnIsCounted) {
    // Points a hair from a closed sphere's faces, and from a box's large faces: there the nearby triangles' solid
    // angles add up to whole turns (the near field is summed as one complex product, whose turns about the origin
    // are counted), and a box face seen from right above it subtends nearly a half sphere (summed on its own).
    const TriangleMesh sphere = test::sphere_mesh({0, 0, 0}, 1.0, 3);
    const TriangleMesh box = test::box_mesh({-1, -1, -1}, {1, 1, 1}, 1);
    std::mt19937 rng(5);
    std::normal_distribution<double> g;
    for (const TriangleMesh* mesh : {&sphere, &box}) {
        const WindingNumber w(*mesh);
        for (int i = 0; i < 200; ++i) {
            const auto& t = mesh->triangles[std::size_t(i) % mesh->triangles.size()];
            const Eigen::Vector3d a = mesh->vertices[std::size_t(t[0])], b = mesh->vertices[std::size_t(t[1])], c = mesh->vertices[std::size_t(t[2])];
            const Eigen::Vector3d normal = (b - a).cross(c - a).normalized();
            const Eigen::Vector3d on = (a + b + c) / 3 + 0.05 * std::abs(g(rng)) * (b - a) + 0.05 * std::abs(g(rng)) * (c - a);
            for (const double offset : {1e-3, 1e-6}) {
                SCOPED_TRACE("triangle " + std::to_string(i) + ", offset " + std::to_string(offset));
                EXPECT_NEAR(w(on - offset * normal), 1.0, 0.03);
                EXPECT_NEAR(w(on + offset * normal), 0.0, 0.03);
                EXPECT_NEAR(w.exact(on - offset * normal), 1.0, 1e-6);
            }
        }
    }
}

TEST(WindingNumber, SegmentCrossingsAreWhereTheSegmentMeetsTheSurface) {
    const TriangleMesh box = test::box_mesh({-1, -1, -1}, {1, 1, 1}, 4);
    const WindingNumber w(box);
    // Through the box from x = -3 to x = 3, off every vertex and edge: the faces x = -1 and x = 1.
    const auto through = w.crossings({-3, 0.1, 0.3}, {3, 0.1, 0.3});
    EXPECT_EQ(through.count, 2);
    EXPECT_NEAR(through.first, 2.0 / 6.0, 1e-12);
    EXPECT_NEAR(through.last, 4.0 / 6.0, 1e-12);
    // From inside out through the face z = 1; a segment that stops short of the faces; one that passes beside the box.
    const auto out = w.crossings({0.2, 0.1, 0.3}, {0.2, 0.1, 3.3});
    EXPECT_EQ(out.count, 1);
    EXPECT_NEAR(out.first, 0.7 / 3.0, 1e-12);
    EXPECT_EQ(w.crossings({-0.5, 0.1, 0.3}, {0.5, 0.1, 0.3}).count, 0);
    EXPECT_EQ(w.crossings({-3, 1.5, 0.3}, {3, 1.5, 0.3}).count, 0);
}

} // namespace
} // namespace voxwarp
