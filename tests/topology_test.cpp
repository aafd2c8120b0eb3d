// The warp keeps topology (issue: scans and re-used outputs came out of a warp full of holes). Over families of
// input a user feeds the tool, at two resolutions, a small and a large fold-free edit must leave the output with
// the components and Euler characteristic of the round trip (voxelize + extract, no edit), and its surface about
// as close to the exact warp (the same lattice map applied to the vertices of the input, finely subdivided) as
// the round trip is to the input.
#include "test_helpers.h"

#include <voxwarp/deform.h>
#include <voxwarp/extract.h>
#include <voxwarp/mesh_io.h>
#include <voxwarp/surface_distance.h>
#include <voxwarp/warp.h>

#include <gtest/gtest.h>


namespace voxwarp {
namespace {

Constraint constraint(ConstraintKind kind, const Eigen::Vector3d& p, const Eigen::Vector3d& to) {
    Constraint c;
    c.kind = kind, c.point = p, c.to = to, c.name = kind == ConstraintKind::pin ? "pin" : "move";
    return c;
}

/// A move of a point at 80 % of the model's width by `voxels` voxels (and half that sideways), a pin at 10 %.
EditScript edit_of(const Bounds& b, double h, double voxels) {
    const Eigen::Vector3d size = b.size(), centre = 0.5 * (b.min + b.max);
    const Eigen::Vector3d p = centre + Eigen::Vector3d(0.3 * size.x(), 0.1 * size.y(), 0), pin = centre - Eigen::Vector3d(0.4 * size.x(), 0, 0);
    EditScript script;
    script.edits.push_back({{constraint(ConstraintKind::move, p, p + h * Eigen::Vector3d(voxels, 0.5 * voxels, 0)), constraint(ConstraintKind::pin, pin, pin)}});
    return script;
}

void expect_topology_kept(const std::string& family, const TriangleMesh& mesh, int resolution) {
    SCOPED_TRACE(family + " at " + std::to_string(resolution));
    DeformOptions options;
    options.voxelize.resolution = resolution;
    options.snap = false; // the warp's topology; snapping keeps connectivity (snap_test.cpp) and would double the time under ASan
    const TriangleMesh round_trip = extract(voxelize(mesh, options.voxelize));
    const MeshTopology expected = topology(round_trip);
    const double h = voxelize_frame(mesh, options.voxelize).voxel_size;
    const double round_trip_p99 = one_sided_distance(mesh, round_trip).p99 / h;
    const TriangleMesh fine = test::subdivided(mesh, h);
    for (const double voxels : {0.5, 4.0}) {
        SCOPED_TRACE("a move of " + std::to_string(voxels) + " voxels");
        const EditScript script = edit_of(bounds(mesh), h, voxels);
        DeformReport report, exact_report;
        const TriangleMesh out = deform_mesh(mesh, script, options, report);
        ASSERT_EQ(report.edits[0].steps, 1); // one map, the one deform_vertices applies
        ASSERT_FALSE(report.edits[0].folds_remain);
        const MeshTopology t = topology(out);
        EXPECT_TRUE(t.watertight());
        EXPECT_EQ(t.components, expected.components);
        EXPECT_EQ(t.euler, expected.euler);
        const TriangleMesh exact = deform_vertices(fine, script, options, exact_report);
        const double p99 = one_sided_distance(exact, out).p99 / h;
        std::printf("%s at %d, move %.1f voxels: %lld pieces, Euler %lld (round trip %lld, %lld); exact warp to output p99 %.3f voxel (round trip %.3f)\n",
                    family.c_str(), resolution, voxels, (long long)t.components, (long long)t.euler, (long long)expected.components,
                    (long long)expected.euler, p99, round_trip_p99);
        EXPECT_LE(p99, round_trip_p99 + 0.5);
    }
}

TEST(KeepsTopology, ScansOpenMeshesThinShellsAndItsOwnOutputs) {
    const TriangleMesh scan = read_mesh(test::data_path("snowden_lo.obj")); // 7 holes, 88 non-manifold edges
    TriangleMesh open = test::sphere_mesh({0, 0, 0}, 1.0, 4);                 // its top cut off: a hole 1.6 wide
    std::erase_if(open.triangles, [&](const auto& t) {
        return (open.vertices[std::size_t(t[0])] + open.vertices[std::size_t(t[1])] + open.vertices[std::size_t(t[2])]).z() / 3 > 0.6;
    });
    // A closed box, hollow behind a wall 0.36-0.48 voxel thick.
    const TriangleMesh shell = test::joined(test::box_mesh({-1, -1, -1}, {1, 1, 1}, 4),
                                            test::inverted(test::box_mesh(Eigen::Vector3d::Constant(-0.985), Eigen::Vector3d::Constant(0.985), 4)));
    for (const int resolution : {48, 64}) {
        expect_topology_kept("scan", scan, resolution);
        expect_topology_kept("open sphere", open, resolution);
        expect_topology_kept("thin shell", shell, resolution);
        expect_topology_kept("own output", extract(voxelize(scan, {.resolution = resolution})), resolution);
    }
}

TEST(KeepsTopology, AFlatRingPulledOutByAQuarterOfItsSize) {
    // A ring 4.16 across and 0.16 thick, a point of its rim pulled out 1.04 (a quarter of its size), the opposite
    // point pinned. Fitted to the ring, the lattice's regions were 0.04 along its thickness and 1.04 across: the
    // move sheared the tube into a ribbon under a voxel thick, 9 extra handles at 128 and 8 pieces at 192. With
    // regions at most twice as long one way as another, the tube bends as a tube.
    const TriangleMesh ring = test::torus_mesh({0, 0, 0}, 2.0, 0.08, 96, 16);
    EditScript script;
    script.edits.push_back({{constraint(ConstraintKind::move, {2.08, 0, 0}, {3.12, 0, 0}), constraint(ConstraintKind::pin, {-2.08, 0, 0}, {-2.08, 0, 0})}});
    for (const int resolution : {128, 192}) {
        SCOPED_TRACE("at " + std::to_string(resolution));
        DeformOptions options;
        options.voxelize.resolution = resolution;
        DeformReport report, exact_report;
        const TriangleMesh out = deform_mesh(ring, script, options, report);
        const MeshTopology t = topology(out);
        EXPECT_TRUE(t.watertight());
        EXPECT_EQ(t.components, 1);
        EXPECT_EQ(t.euler, 0);
        // Against the exact warp (the map applied to a finely subdivided ring): nowhere a hole or a lost part.
        const double h = report.voxel_size;
        const TriangleMesh exact = deform_vertices(test::subdivided(ring, h), script, options, exact_report);
        const DistanceStats d = one_sided_distance(exact, out);
        std::printf("flat ring at %d: %lld pieces, Euler %lld; exact warp to output p99 %.3f, max %.3f voxel\n", resolution, (long long)t.components,
                    (long long)t.euler, d.p99 / h, d.max / h);
        EXPECT_LE(d.max / h, 1.0);
    }
}

/// data/snowden_nose.json on `mesh` at `resolution` (unsnapped) keeps the topology of `mesh`'s round trip with
/// `sign`.
void expect_nose_edit_keeps_topology(const TriangleMesh& mesh, int resolution, SignMethod sign) {
    DeformOptions options;
    options.voxelize.resolution = resolution;
    options.snap = false;
    VoxelizeOptions round_trip = options.voxelize;
    round_trip.sign = sign;
    const MeshTopology expected = topology(extract(voxelize(mesh, round_trip)));
    DeformReport report;
    const MeshTopology t = topology(deform_mesh(mesh, read_edit_file(test::data_path("snowden_nose.json")), options, report));
    std::printf("at %d: %lld pieces, Euler %lld (round trip %lld, %lld)\n", resolution, (long long)t.components, (long long)t.euler,
                (long long)expected.components, (long long)expected.euler);
    EXPECT_EQ(t.components, expected.components);
    EXPECT_EQ(t.euler, expected.euler);
}

TEST(KeepsTopology, TheBundledScanEditAt64And192) {
    // data/snowden_nose.json as the README runs it: the round trip's topology (4 pieces, Euler 8 at 64; 1 piece,
    // Euler -2 at 192, where the glasses' rims, turned beside the face, were bridged to it: -4 before bridges
    // were given back to the gap, resolve.h).
    const TriangleMesh scan = read_mesh(test::data_path("snowden_lo.obj"));
    expect_nose_edit_keeps_topology(scan, 64, SignMethod::automatic);
    expect_nose_edit_keeps_topology(scan, 192, SignMethod::automatic);
}

TEST(KeepsTopology, TheBundledScanEditFollowsTheExactWarpAt64) {
    // The bar: data/snowden_nose.json at 64, as the README runs it (snapped), within p99 0.5 voxel of the
    // exact warp (the lattice map applied to the scan subdivided to a voxel). The scan is a shell about half a voxel
    // thick there; where the carry thickens a wall, the thick side's vertices lie 0.5-1 voxel off the exact warp,
    // beyond a full snap: p99 0.55 before they moved half a voxel toward their images, 0.39 before the shell's faces
    // were refined (thin parts were left alone); 0.33 before the vertices snapping left behind tried again against
    // the refined output and sides were flipped toward the exact normals (steps 7b and 8); 0.23 since.
    const auto [out, exact, report, h] = test::deform_with_exact_warp("snowden_lo.obj", "snowden_nose.json", 64);
    const DistanceStats d = one_sided_distance(out, exact);
    std::printf("snowden nose edit at 64, output to exact warp: mean %.3f p99 %.3f voxel; %zu vertices snapped, %zu partly, %zu not\n", d.mean / h,
                d.p99 / h, report.snapped_vertices, report.partly_snapped_vertices, report.unsnapped_vertices);
    EXPECT_LE(d.p99 / h, 0.3);
    EXPECT_GT(report.partly_snapped_vertices, 0u);
    EXPECT_TRUE(topology(out).watertight());
}

TEST(KeepsTopology, TheScansOwnOutputEditedAgainAt128) {
    // The scan's round trip at 128, fed back (`--sign auto`) through the nose edit at 128: the topology of its
    // winding-number round trip (1 piece, Euler -2; -6 before bridges were given back to the gap).
    const TriangleMesh output = extract(voxelize(read_mesh(test::data_path("snowden_lo.obj")), {.resolution = 128}));
    expect_nose_edit_keeps_topology(output, 128, SignMethod::winding_number);
}

TEST(KeepsTopology, FogVolumesThroughTheVoxmapWarp) {
    // Voxmaps whose inside is 0.3, 0.6 or 1.0 (fog, CT data) through deform_voxmap, as `voxwarp warp` runs them:
    // the 0.5 isosurface keeps its topology (a sphere; none at all for 0.3), small edit and large.
    for (const float inside : {0.3f, 0.6f, 1.0f}) {
        Voxmap fog({40, 40, 40}, Eigen::Vector3d::Constant(-1.0), 0.05);
        for (std::int64_t k = 0; k < 40; ++k)
            for (std::int64_t j = 0; j < 40; ++j)
                for (std::int64_t i = 0; i < 40; ++i)
                    fog.at(i, j, k) = float(inside * std::clamp(0.5 - (fog.world(double(i), double(j), double(k)).norm() - 0.6) / 0.1, 0.0, 1.0));
        const Bounds b{Eigen::Vector3d::Constant(-0.6), Eigen::Vector3d::Constant(0.6)};
        for (const double voxels : {0.5, 4.0}) {
            DeformReport report;
            const SparseVoxmap out = deform_voxmap(to_sparse(fog), edit_of(b, 0.05, voxels), DeformOptions{}, report);
            const TriangleMesh surface = extract(out);
            if (inside < 0.5f) {
                EXPECT_EQ(surface.face_count(), 0u) << inside;
                continue;
            }
            const MeshTopology t = topology(surface);
            EXPECT_TRUE(t.watertight()) << inside << ", " << voxels;
            EXPECT_EQ(t.components, 1) << inside << ", " << voxels;
            EXPECT_EQ(t.euler, 2) << inside << ", " << voxels;
        }
    }
}

} // namespace
} // namespace voxwarp
