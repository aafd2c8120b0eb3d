// The rotation-aware solve against analytic large deformations: a box bent 90 degrees into a circular arc and a
// box twisted 90 degrees about its axis, in voxels of the volume they were voxelized into.
#include "test_helpers.h"

#include <voxwarp/deform.h>
#include <voxwarp/errors.h>
#include <voxwarp/rigid.h>
#include <voxwarp/surface_distance.h>

#include <gtest/gtest.h>

#include <chrono>
#include <functional>
#include <numbers>

namespace voxwarp {
namespace {

using Map = std::function<Eigen::Vector3d(const Eigen::Vector3d&)>;

/// A box of length `length` along x (centred on the origin) and cross-section `width` x `width`.
struct Bar {
    double length, width;
    Eigen::Vector3d lo() const { return {-length / 2, -width / 2, -width / 2}; }
    Eigen::Vector3d hi() const { return {length / 2, width / 2, width / 2}; }
    /// The bar bent by `angle` into a circular arc in the x-y plane, towards +y, its centre line keeping its
    /// length, cross-sections staying planar and square to it; the end x = -length/2 stays put.
    Map bend(double angle) const {
        const double R = length / angle, L = length;
        return [=](const Eigen::Vector3d& p) {
            const double theta = (p.x() + L / 2) / R;
            return Eigen::Vector3d(-L / 2 + (R - p.y()) * std::sin(theta), R - (R - p.y()) * std::cos(theta), p.z());
        };
    }
    /// The bar twisted about its axis: cross-section x turned by angle * (x + length/2) / length.
    Map twist(double angle) const {
        const double L = length;
        return [=](const Eigen::Vector3d& p) {
            const double theta = angle * (p.x() + L / 2) / L;
            return Eigen::Vector3d(p.x(), p.y() * std::cos(theta) - p.z() * std::sin(theta), p.y() * std::sin(theta) + p.z() * std::cos(theta));
        };
    }
    /// Pins at the corners and centre of the end x = -length/2, moves of the other end's corners and centre to
    /// where `map` takes them.
    Edit end_constraints(const Map& map, Solver solver) const {
        Edit edit;
        edit.solver = solver;
        int id = 0;
        for (double x : {-length / 2, length / 2})
            for (const Eigen::Vector3d& yz : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, -1, -1), Eigen::Vector3d(0, 1, -1), Eigen::Vector3d(0, 1, 1),
                                             Eigen::Vector3d(0, -1, 1)}) {
                Constraint c;
                c.point = Eigen::Vector3d(x, 0, 0) + yz * (width / 2);
                c.name = "edits[0].constraints[" + std::to_string(id++) + "]";
                if (x < 0) {
                    c.kind = ConstraintKind::pin, c.to = c.point;
                } else {
                    c.kind = ConstraintKind::move, c.to = map(c.point);
                }
                edit.constraints.push_back(c);
            }
        return edit;
    }
    /// The exact answer: a finely tessellated box mapped through `map`.
    TriangleMesh exact(const Map& map, int n) const {
        TriangleMesh m = test::box_mesh(lo(), hi(), n);
        for (auto& v : m.vertices) v = map(v);
        return m;
    }
};

struct Outcome {
    DistanceStats distance; // voxels
    double volume_change;   // fraction
    double seconds_solve;
    MeshTopology topology;
    DeformReport report;
};

Outcome run(const Bar& bar, const Map& map, Solver solver, const std::array<int, 3>& lattice, double voxel_size, bool preserve_volume = false) {
    EditScript script;
    script.lattice.size = lattice;
    script.edits.push_back(bar.end_constraints(map, solver));
    script.edits.back().preserve_volume = preserve_volume;
    DeformOptions options;
    options.voxelize.voxel_size = voxel_size;
    Outcome o;
    const TriangleMesh out = deform_mesh(test::box_mesh(bar.lo(), bar.hi(), 1), script, options, o.report);
    const TriangleMesh exact = bar.exact(map, 160);
    o.distance = symmetric_distance(out, exact, {.samples = 100000});
    o.distance.mean /= voxel_size, o.distance.p99 /= voxel_size, o.distance.max /= voxel_size;
    o.volume_change = o.report.volume_after / o.report.volume_before - 1.0;
    o.seconds_solve = o.report.seconds_solve;
    o.topology = topology(out);
    return o;
}

void print(const char* what, const Outcome& o) {
    std::printf("%-34s mean %.3f  p99 %.3f  max %.3f voxels, volume %+.2f %%, solve %.1f ms, Euler %lld, boundary edges %lld\n", what, o.distance.mean,
                o.distance.p99, o.distance.max, 100 * o.volume_change, 1e3 * o.seconds_solve, (long long)o.topology.euler, (long long)o.topology.boundary_edges);
}

void expect_closed_manifold(const Outcome& o) {
    EXPECT_TRUE(o.topology.watertight());
    EXPECT_EQ(o.topology.components, 1);
    EXPECT_EQ(o.topology.euler, 2);
}

TEST(Rigid, NinetyDegreeBendLandsOnTheCircularArc) {
    const Bar bar{4, 1};
    const double h = 1.0 / 32;
    const Outcome rigid = run(bar, bar.bend(std::numbers::pi / 2), Solver::rigid, {9, 9, 9}, h);
    const Outcome min_norm = run(bar, bar.bend(std::numbers::pi / 2), Solver::min_norm, {9, 9, 9}, h);
    print("bend, rigid, 9x9x9", rigid);
    print("bend, min-norm, 9x9x9", min_norm);
    EXPECT_LE(rigid.distance.mean, 1.0);
    EXPECT_LE(rigid.distance.max, 4.0);
    EXPECT_LE(std::abs(rigid.volume_change), 0.02);
    expect_closed_manifold(rigid);
    EXPECT_FALSE(rigid.report.edits[0].folds_remain);
    for (const auto& c : rigid.report.edits[0].constraints) EXPECT_LE(c.residual_voxels, 1e-6) << c.name;
}

TEST(Rigid, NinetyDegreeTwistTurnsTheCrossSections) {
    const Bar bar{4, 1};
    const double h = 1.0 / 32;
    const Outcome rigid = run(bar, bar.twist(std::numbers::pi / 2), Solver::rigid, {9, 9, 9}, h);
    const Outcome min_norm = run(bar, bar.twist(std::numbers::pi / 2), Solver::min_norm, {9, 9, 9}, h);
    print("twist, rigid, 9x9x9", rigid);
    print("twist, min-norm, 9x9x9", min_norm);
    EXPECT_LE(rigid.distance.mean, 1.0);
    EXPECT_LE(rigid.distance.max, 4.0);
    EXPECT_LE(std::abs(rigid.volume_change), 0.02);
    expect_closed_manifold(rigid);
}

} // namespace
} // namespace voxwarp
