// The rotation-aware solve against analytic large deformations: a box bent 90 degrees into a circular arc and a
// box twisted 90 degrees about its axis, in voxels of the volume they were voxelized into.
#include "test_helpers.h"

#include <voxwarp/deform.h>
#include <voxwarp/edit_file.h>
#include <voxwarp/errors.h>
#include <voxwarp/rigid.h>
#include <voxwarp/foldover.h>
#include <voxwarp/surface_distance.h>
#include <voxwarp/warp.h>

#include <gtest/gtest.h>

#include <tbb/global_control.h>

#include <chrono>
#include <functional>
#include <numbers>

namespace voxwarp {
namespace {

using test::Bar;
using test::Map;

struct Outcome {
    DistanceStats distance; // voxels
    double volume_change;   // fraction
    double seconds_solve;
    MeshTopology topology;
    DeformReport report;
};

/// An edit script's deform of the bar (one face per side, voxel size `voxel_size`), measured against `map`.
Outcome run_script(const test::Bar& bar, const Map& map, const EditScript& script, double voxel_size) {
    DeformOptions options;
    options.voxelize.voxel_size = voxel_size;
    Outcome o;
    const TriangleMesh out = deform_mesh(test::box_mesh(bar.lo(), bar.hi(), 1), script, options, o.report);
    o.distance = symmetric_distance(out, bar.exact(map, 160), {.samples = 100000});
    o.distance.mean /= voxel_size, o.distance.p99 /= voxel_size, o.distance.max /= voxel_size;
    o.volume_change = o.report.volume_after / o.report.volume_before - 1.0;
    o.seconds_solve = o.report.seconds_solve;
    o.topology = topology(out);
    return o;
}

/// The bar's ten end points (Bar::end_constraints) on `lattice`, through run_script.
Outcome run(const Bar& bar, const Map& map, Solver solver, const std::array<int, 3>& lattice, double voxel_size, bool preserve_volume = false) {
    EditScript script;
    script.lattice.size = lattice;
    script.edits.push_back(bar.end_constraints(map, solver));
    script.edits.back().preserve_volume = preserve_volume;
    return run_script(bar, map, script, voxel_size);
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

/// Bounds for one configuration: about 1.5 x its measured figures (voxels; volume change as a fraction).
struct Bounds {
    double mean, max, volume;
};

/// The deformation's own figures for one configuration, against its bounds.
void expect_natural(const Outcome& o, const Bounds& b) {
    EXPECT_LE(o.distance.mean, b.mean);
    EXPECT_LE(o.distance.max, b.max);
    EXPECT_LE(std::abs(o.volume_change), b.volume);
    expect_closed_manifold(o);
    EXPECT_FALSE(o.report.edits[0].folds_remain);
    for (const auto& c : o.report.edits[0].constraints) EXPECT_LE(c.residual_voxels, 1e-6) << c.name;
}

TEST(Rigid, NinetyDegreeBendLandsOnTheCircularArc) {
    struct Config {
        test::Bar bar;
        std::array<int, 3> lattice;
        double h;
        const char* name;
        Bounds bounds; // measured: mean 0.815 / 0.376 / 0.271, max 3.45 / 1.90 / 1.48 voxels, volume +0.65 / +0.57 / +0.33 %
    };
    for (const Config& c : {Config{{4, 1}, {9, 9, 9}, 1.0 / 32, "4x1x1, 9x9x9, h 1/32", {1.0, 4.5, 0.01}},
                            Config{{4, 1}, {9, 5, 5}, 1.0 / 32, "4x1x1, 9x5x5, h 1/32", {0.6, 3.0, 0.01}},
                            Config{{6, 0.75}, {12, 6, 6}, 1.0 / 48, "6x.75x.75, 12x6x6, h 1/48", {0.45, 2.3, 0.006}}}) {
        SCOPED_TRACE(c.name);
        const Map bend = c.bar.bend(std::numbers::pi / 2);
        const Outcome rigid = run(c.bar, bend, Solver::rigid, c.lattice, c.h);
        const Outcome min_norm = run(c.bar, bend, Solver::min_norm, c.lattice, c.h);
        print((std::string("bend rigid    ") + c.name).c_str(), rigid);
        print((std::string("bend min-norm ") + c.name).c_str(), min_norm);
        expect_natural(rigid, c.bounds);
        EXPECT_LT(rigid.distance.mean, min_norm.distance.mean / 3); // min-norm crumples: the rigid answer is the bend
    }
}

TEST(Rigid, NinetyDegreeTwistTurnsTheCrossSections) {
    for (const auto& [bar, h] : {std::pair{test::Bar{4, 1}, 1.0 / 32}, std::pair{test::Bar{5, 1.25}, 1.0 / 24}}) {
        const Map twist = bar.twist(std::numbers::pi / 2);
        const Outcome rigid = run(bar, twist, Solver::rigid, {9, 9, 9}, h);
        const Outcome min_norm = run(bar, twist, Solver::min_norm, {9, 9, 9}, h);
        print("twist rigid    9x9x9", rigid);
        print("twist min-norm 9x9x9", min_norm);
        expect_natural(rigid, {0.5, 2.3, 0.004}); // measured: mean 0.33 / 0.31, max 1.53 / 1.51 voxels, volume +0.16 / +0.13 %
        EXPECT_LT(rigid.distance.mean, min_norm.distance.mean / 2);
    }
}

std::string json_point(const Eigen::Vector3d& p) {
    char text[128];
    std::snprintf(text, sizeof text, "[%.17g, %.17g, %.17g]", p.x(), p.y(), p.z());
    return text;
}

TEST(Rigid, TwoFrameHandlesBendAndTwistTheBox) {
    // The handles issue's frame bend and twist: one end's frame held, the other end's moved to where the exact map
    // takes it and turned 90 degrees; two entries of an edit file against ten point constraints.
    const test::Bar bar{4, 1};
    const double h = 1.0 / 32;
    const Map bend = bar.bend(std::numbers::pi / 2), twist = bar.twist(std::numbers::pi / 2);
    const Eigen::Vector3d end(2, 0, 0);
    struct Case {
        const char* name;
        const Map& map;
        std::string axis;
        Bounds bounds;
    };
    // A lattice whose cells are about as wide as long across the bar: a frame fixes the map's Jacobian at its point
    // and holds the end face flat around it, and the finer 9 x 9 x 9 lattice lets the end faces' corners drift
    // (bend mean 0.98, max 3.9 voxels).
    // The twist's volume bound is 0.3 %: since snapping puts the box's edges back where marching cubes rounds
    // them (refinement's crease points across a rim), the output holds the lattice map's own small gain in volume
    // (+0.14 % before, +0.20 % after, every distance to the exact twist the same or less).
    for (const Case& c : {Case{"bend", bend, "[0, 0, 1]", {0.4, 2.0, 0.008}}, Case{"twist", twist, "[1, 0, 0]", {0.35, 2.0, 0.003}}}) {
        SCOPED_TRACE(c.name);
        const std::string edit = R"({"lattice": {"size": [9, 5, 5]}, "edits": [{"solver": "rigid", "constraints": [{"frame": [-2, 0, 0]}, {"frame": )" +
                                 json_point(end) + R"(, "to": )" + json_point(c.map(end)) + R"(, "rotate": {"axis": )" + c.axis + R"(, "degrees": 90}}]}]})";
        const EditScript script = parse_edit_script(edit, "edit");
        const Outcome frames = run_script(bar, c.map, script, h);
        // The same frames without their plates (the point and the Jacobian only): the end faces' corners drift more.
        EditScript loose = script;
        std::erase_if(loose.edits[0].constraints, [](const Constraint& k) { return k.kind == ConstraintKind::plate; });
        const Outcome points_and_turns = run_script(bar, c.map, loose, h);
        const Outcome points = run(bar, c.map, Solver::rigid, {9, 5, 5}, h);
        print((std::string(c.name) + ", two frames").c_str(), frames);
        print((std::string(c.name) + ", frames without plates").c_str(), points_and_turns);
        print((std::string(c.name) + ", ten points").c_str(), points);
        // The issue's bars: mean <= 0.5, max <= 2 voxels, volume within 2 %. Ours, about 1.3x the measured means and
        // the issue's max (bend mean 0.285, max 1.92, volume +0.52 %; twist 0.264, 1.93, +0.07 %). Without the plates
        // the bend's max was over the issue's 2 (0.340 / 2.14).
        EXPECT_LE(frames.distance.mean, c.bounds.mean);
        EXPECT_LE(frames.distance.max, c.bounds.max);
        EXPECT_LE(std::abs(frames.volume_change), c.bounds.volume);
        EXPECT_LT(frames.distance.mean, points_and_turns.distance.mean);
        if (std::string(c.name) == "bend") { // the twist's: 1.93 against 1.88
            EXPECT_LT(frames.distance.max, points_and_turns.distance.max);
        }
        expect_closed_manifold(frames);
        // Every entry is met: the points to within round-off, the turns to within a thousandth of a degree, the
        // plates (the end faces' flatness along their tangent planes) to within round-off.
        const auto& report = frames.report.edits[0].constraints;
        ASSERT_EQ(report.size(), 10u); // two frames: a move, three turns and a plate each
        int plates = 0;
        for (const auto& r : report) {
            EXPECT_EQ(r.entry, "frame");
            plates += r.kind == "plate";
            if (r.kind == "turn") EXPECT_LE(r.residual_degrees, 1e-3) << r.name;
            else EXPECT_LE(r.residual_voxels, 1e-6) << r.name;
        }
        EXPECT_EQ(plates, 2);
    }
}

/// A box voxelized on a 9^3 lattice: the solver's inputs.
struct Solve {
    WarpDomain domain;
    LatticeMaterial material;
};

Solve box_solve(const test::Bar& bar, double h) {
    WarpDomain domain = make_domain(voxelize_sparse(test::box_mesh(bar.lo(), bar.hi(), 1), {.voxel_size = h}), LatticeSpec{});
    LatticeMaterial material = lattice_material(domain);
    return {std::move(domain), std::move(material)};
}

/// Largest distance, over points of the bar, between the solved map and `expected`, world units.
double map_error(const Solve& s, const Lattice& solved, const test::Bar& bar, const Map& expected) {
    double worst = 0;
    for (int i = 0; i <= 16; ++i)
        for (int j = 0; j <= 4; ++j)
            for (int k = 0; k <= 4; ++k) {
                const Eigen::Vector3d p = bar.lo() + (bar.hi() - bar.lo()).cwiseProduct(Eigen::Vector3d(i / 16.0, j / 4.0, k / 4.0));
                worst = std::max(worst, (solved.evaluate(s.domain.lattice.parameter_of(p)) - expected(p)).norm());
            }
    return worst;
}

TEST(Rigid, RigidMotionsAreReproduced) {
    const test::Bar bar{4, 1};
    const Solve s = box_solve(bar, 1.0 / 16);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(1.1, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
    const Eigen::Vector3d shift(0.3, -0.2, 0.5);
    const Map motion = [&](const Eigen::Vector3d& p) -> Eigen::Vector3d { return R * p + shift; };
    std::vector<Constraint> cs;
    for (const Eigen::Vector3d& p : {Eigen::Vector3d(-2, -0.5, -0.5), Eigen::Vector3d(2, 0.5, -0.5), Eigen::Vector3d(0, 0.5, 0.5), Eigen::Vector3d(1, -0.5, 0.5)}) {
        Constraint c;
        c.kind = ConstraintKind::move, c.point = p, c.to = motion(p);
        cs.push_back(c);
    }
    const RigidSolution solved = solve_rigid(s.domain.lattice, cs, s.material);
    const double h = 1.0 / 16;
    EXPECT_LE(map_error(s, solved.lattice, bar, motion) / h, 0.01); // voxels; the iterations stop at 1e-4 of a spacing
    // One move alone: the least-motion rigid answer is the translation.
    const Eigen::Vector3d d(0.2, 0.1, -0.3);
    Constraint one = cs[0];
    one.to = one.point + d;
    const RigidSolution moved = solve_rigid(s.domain.lattice, {one}, s.material);
    EXPECT_LE(map_error(s, moved.lattice, bar, [&](const Eigen::Vector3d& p) -> Eigen::Vector3d { return p + d; }) / h, 0.01);
}

TEST(Rigid, BeatsTheControlPointGraphBaseline) {
    // The same bend through the design card's first sketch (ARAP between control points, Ceres): its map lands
    // farther from the circular arc than the solve on the map's own Jacobian.
    const test::Bar bar{4, 1};
    const Solve s = box_solve(bar, 1.0 / 32);
    const Map bend = bar.bend(std::numbers::pi / 2);
    const auto constraints = bar.end_constraints(bend, Solver::rigid).constraints;
    const RigidSolution ours = solve_rigid(s.domain.lattice, constraints, s.material);
    const RigidSolution graph = solve_rigid_graph_ceres(s.domain.lattice, constraints, s.material);
    const double h = 1.0 / 32, e_ours = map_error(s, ours.lattice, bar, bend) / h, e_graph = map_error(s, graph.lattice, bar, bend) / h;
    const double v0 = mapped_material_volume(s.domain.lattice, s.material);
    std::printf("bend, worst map error: ours %.2f voxels (volume %+.2f %%), graph ARAP in Ceres %.2f voxels (volume %+.2f %%)\n", e_ours,
                100 * (mapped_material_volume(ours.lattice, s.material) / v0 - 1), e_graph, 100 * (mapped_material_volume(graph.lattice, s.material) / v0 - 1));
    EXPECT_LT(e_ours, e_graph);
    EXPECT_LE(e_ours, 4.0);
}

TEST(Rigid, SameAnswerForAnyThreadCount) {
    const test::Bar bar{4, 1};
    const Solve s = box_solve(bar, 1.0 / 24);
    const auto constraints = bar.end_constraints(bar.twist(std::numbers::pi / 2), Solver::rigid).constraints;
    auto solve_with = [&](int threads) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        return solve_rigid(s.domain.lattice, constraints, s.material, {.preserve_volume = true}).lattice.points();
    };
    EXPECT_EQ(solve_with(1), solve_with(2));
}

TEST(Rigid, WeightedMovesMeetHalfWay) {
    // Two weighted moves of one point to different targets: weights 1 and 3 put it three quarters of the way.
    const test::Bar bar{4, 1};
    const Solve s = box_solve(bar, 1.0 / 16);
    Constraint a, b, pin;
    a.kind = b.kind = ConstraintKind::move;
    a.point = b.point = Eigen::Vector3d(2, 0, 0);
    a.to = Eigen::Vector3d(2, 0.4, 0), a.weight = 1.0;
    b.to = Eigen::Vector3d(2, 0, 0), b.weight = 3.0;
    pin.kind = ConstraintKind::pin, pin.point = pin.to = Eigen::Vector3d(-2, 0, 0);
    const RigidSolution r = solve_rigid(s.domain.lattice, {a, b, pin}, s.material);
    EXPECT_TRUE(r.least_squares);
    const Eigen::Vector3d landed = r.lattice.evaluate(s.domain.lattice.parameter_of(a.point));
    EXPECT_NEAR(landed.y(), 0.1, 0.01);
    EXPECT_LE(r.residuals[2], 1e-9); // the pin holds exactly
}

TEST(Rigid, ConflictingMovesWithoutPinsMeetHalfWay) {
    // Two moves of one point to different targets and no pin: least squares with no row held exactly (this solve
    // once decomposed an empty matrix for the hard rows and crashed; ten frames on the box reached it too).
    const test::Bar bar{4, 1};
    const Solve s = box_solve(bar, 1.0 / 16);
    Constraint a, b;
    a.kind = b.kind = ConstraintKind::move;
    a.point = b.point = Eigen::Vector3d(2, 0, 0);
    a.to = Eigen::Vector3d(2, 0.4, 0), b.to = Eigen::Vector3d(2, 0, 0);
    const RigidSolution r = solve_rigid(s.domain.lattice, {a, b}, s.material);
    EXPECT_TRUE(r.least_squares);
    EXPECT_NEAR(r.lattice.evaluate(s.domain.lattice.parameter_of(a.point)).y(), 0.2, 0.01);
}

TEST(Rigid, ClampedPlacementHoldsItsPins) {
    const test::Bar bar{4, 1};
    WarpDomain domain = make_domain(voxelize_sparse(test::box_mesh(bar.lo(), bar.hi(), 1), {.voxel_size = 1.0 / 16}),
                                    LatticeSpec{.size = {10, 8, 8}, .placement = Placement::clamped});
    const auto constraints = bar.end_constraints(bar.bend(std::numbers::pi / 4), Solver::rigid).constraints;
    const RigidSolution r = solve_rigid(domain.lattice, constraints, lattice_material(domain));
    for (double res : r.residuals) EXPECT_LE(res, 1e-9);
    EXPECT_TRUE(find_folds(r.lattice).empty());
}

TEST(Rigid, CancelsThroughItsProgressCallback) {
    const test::Bar bar{4, 1};
    const Solve s = box_solve(bar, 1.0 / 16);
    int calls = 0;
    RigidSolveOptions options;
    options.progress = [&](std::string_view, double) { return ++calls < 3; };
    EXPECT_THROW(solve_rigid(s.domain.lattice, bar.end_constraints(bar.bend(1.5), Solver::rigid).constraints, s.material, options), Cancelled);
}

TEST(Rigid, RefusesMoreUnknownsThanItTakes) {
    const test::Bar bar{4, 1};
    // 64^3 control points, 17,680 of which shape the bar (40^3 took fewer than 5,000 once make_domain kept the
    // regions across the bar at least half as long as along it).
    WarpDomain domain = make_domain(voxelize_sparse(test::box_mesh(bar.lo(), bar.hi(), 1), {.voxel_size = 1.0 / 16}), LatticeSpec{.size = {64, 64, 64}});
    try {
        solve_rigid(domain.lattice, bar.end_constraints(bar.bend(1.0), Solver::rigid).constraints, lattice_material(domain));
        FAIL() << "expected InvalidInput";
    } catch (const InvalidInput& e) {
        EXPECT_NE(std::string(e.what()).find("smaller lattice.size"), std::string::npos) << e.what();
    }
}

TEST(PreserveVolume, KeepsAStretchWithinOnePercent) {
    // Pulling one end of the bar out by 30 %: min-norm adds more than 10 % volume, preserve_volume keeps it.
    const test::Bar bar{4, 1};
    const Map stretch = [](const Eigen::Vector3d& p) -> Eigen::Vector3d { return {p.x() > 0 ? p.x() + 1.2 : p.x(), p.y(), p.z()}; };
    for (Solver solver : {Solver::min_norm, Solver::rigid}) {
        const Outcome plain = run(bar, stretch, solver, {9, 9, 9}, 1.0 / 24, false);
        const Outcome kept = run(bar, stretch, solver, {9, 9, 9}, 1.0 / 24, true);
        std::printf("%s stretch: volume %+.2f %%, with preserve_volume %+.2f %%\n", to_string(solver).c_str(), 100 * plain.volume_change, 100 * kept.volume_change);
        if (solver == Solver::min_norm) {
            EXPECT_GT(plain.volume_change, 0.10);
        }
        EXPECT_LE(std::abs(kept.volume_change), 0.01);
        EXPECT_TRUE(kept.topology.watertight());
        for (const auto& c : kept.report.edits[0].constraints) EXPECT_LE(c.residual_voxels, 1e-6) << c.name;
    }
}

} // namespace
} // namespace voxwarp
