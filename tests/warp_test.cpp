// The warp engine against analytic answers (tolerances in voxels or density units) and the naive reference.
#include "test_helpers.h"

#include <voxwarp/basis.h>
#include <voxwarp/errors.h>
#include <voxwarp/extract.h>
#include <voxwarp/foldover.h>
#include <voxwarp/surface_distance.h>
#include <voxwarp/voxelize.h>
#include <voxwarp/warp.h>

#include <gtest/gtest.h>

#include <random>

#include <tbb/task_arena.h>

namespace voxwarp {
namespace {

/// Density of `v` at the voxel whose centre is world point origin + h * (i, j, k) of grid `ref`; 0 outside.
float density_on_grid(const Voxmap& v, const Voxmap& ref, std::int64_t i, std::int64_t j, std::int64_t k) {
    const Eigen::Vector3d idx = v.index_of(ref.world(double(i), double(j), double(k)));
    const std::int64_t x = std::llround(idx.x()), y = std::llround(idx.y()), z = std::llround(idx.z());
    if (x < 0 || y < 0 || z < 0 || x >= v.dims[0] || y >= v.dims[1] || z >= v.dims[2]) return 0.0f;
    return v.at(x, y, z);
}

/// Largest density difference between two voxmaps on aligned grids, over the union of their extents.
double max_difference(const Voxmap& a, const Voxmap& b) {
    double worst = 0;
    for (std::int64_t k = 0; k < a.dims[2]; ++k)
        for (std::int64_t j = 0; j < a.dims[1]; ++j)
            for (std::int64_t i = 0; i < a.dims[0]; ++i) worst = std::max(worst, double(std::abs(a.at(i, j, k) - density_on_grid(b, a, i, j, k))));
    for (std::int64_t k = 0; k < b.dims[2]; ++k)
        for (std::int64_t j = 0; j < b.dims[1]; ++j)
            for (std::int64_t i = 0; i < b.dims[0]; ++i) worst = std::max(worst, double(std::abs(b.at(i, j, k) - density_on_grid(a, b, i, j, k))));
    return worst;
}

Voxmap sphere_voxmap(int resolution = 24) { return voxelize(test::sphere_mesh({0.1, -0.2, 0.3}, 1.0, 3), {.resolution = resolution}); }

TEST(Basis, TableSumsToOneAndMatchesClosedForm) {
    const BasisTable table(7);
    for (int e = 0; e <= 7; ++e) {
        const double t = e / 7.0;
        const auto& b = table.values[std::size_t(e)];
        EXPECT_NEAR(b[0] + b[1] + b[2] + b[3], 1.0, 1e-15);
        EXPECT_NEAR(b[0], std::pow(1 - t, 3) / 6, 1e-15);
        EXPECT_NEAR(b[1], (3 * t * t * t - 6 * t * t + 4) / 6, 1e-15);
        EXPECT_NEAR(b[2], (-3 * t * t * t + 3 * t * t + 3 * t + 1) / 6, 1e-15);
        EXPECT_NEAR(b[3], t * t * t / 6, 1e-15);
        const auto d = cubic_basis_derivative(t);
        const auto p = cubic_basis(t + 1e-6), m = cubic_basis(t - 1e-6);
        for (int i = 0; i < 4; ++i) EXPECT_NEAR(d[std::size_t(i)], (p[std::size_t(i)] - m[std::size_t(i)]) / 2e-6, 1e-8);
    }
}

TEST(Lattice, UndeformedUniformMapIsTheAffineIdentity) {
    const Lattice l = Lattice::uniform({6, 5, 7}, {1, 2, 3}, {0.5, 0.25, 2});
    for (const Eigen::Vector3d& stu : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(3, 2, 4), Eigen::Vector3d(1.3, 0.7, 2.9)}) {
        EXPECT_NEAR((l.evaluate(stu) - Eigen::Vector3d(1 + 0.5 * stu.x(), 2 + 0.25 * stu.y(), 3 + 2 * stu.z())).norm(), 0.0, 1e-12);
        EXPECT_NEAR((l.parameter_of(l.evaluate(stu)) - stu).norm(), 0.0, 1e-12);
    }
    EXPECT_THROW(Lattice::uniform({3, 9, 9}, {0, 0, 0}, {1, 1, 1}), InvalidInput);
}

TEST(Lattice, ClampedImageIsExactlyTheDataBox) {
    const Eigen::Vector3d lo(-1, 0, 2), hi(3, 1, 5);
    const Lattice l = Lattice::clamped({9, 7, 6}, lo, hi);
    const auto r = l.regions();
    for (int c = 0; c < 8; ++c) {
        const Eigen::Vector3d stu((c & 1) ? r[0] : 0, (c & 2) ? r[1] : 0, (c & 4) ? r[2] : 0);
        const Eigen::Vector3d corner((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(), (c & 4) ? hi.z() : lo.z());
        EXPECT_NEAR((l.evaluate(stu) - corner).norm(), 0.0, 1e-12);
    }
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(0, 1);
    for (int n = 0; n < 1000; ++n) {
        const Eigen::Vector3d p = l.evaluate(Eigen::Vector3d(u(rng) * r[0], u(rng) * r[1], u(rng) * r[2]));
        EXPECT_TRUE((p.array() >= lo.array() - 1e-12).all() && (p.array() <= hi.array() + 1e-12).all());
    }
    // A face of the parameter box maps onto the matching face of the data box.
    EXPECT_NEAR(l.evaluate(Eigen::Vector3d(r[0], 0.37 * r[1], 0.81 * r[2])).x(), hi.x(), 1e-12);
}

TEST(Warp, UndeformedUniformLatticeIsIdentity) {
    const Voxmap input = sphere_voxmap();
    const WarpDomain domain = make_domain(input, {.size = {9, 9, 9}});
    const Voxmap out = to_dense(warp(domain, domain.lattice));
    EXPECT_LE(max_difference(input, out), 1e-5);
}

TEST(Warp, IntegerTranslationShiftsTheDataExactly) {
    const Voxmap input = sphere_voxmap();
    const WarpDomain domain = make_domain(input, {.size = {7, 8, 9}});
    Lattice moved = domain.lattice;
    const Eigen::Vector3d shift = input.voxel_size * Eigen::Vector3d(3, -2, 5);
    for (auto& p : moved.points()) p += shift;
    const Voxmap out = to_dense(warp(domain, moved));
    Voxmap shifted = input;
    shifted.origin += shift;
    EXPECT_LE(max_difference(shifted, out), 1e-6);
}

TEST(Warp, UniformScaleByTwoMultipliesVolumeByEight) {
    const Voxmap input = sphere_voxmap();
    const WarpDomain domain = make_domain(input, {});
    Lattice scaled = domain.lattice;
    const Eigen::Vector3d centre(0.1, -0.2, 0.3);
    for (auto& p : scaled.points()) p = centre + 2.0 * (p - centre);
    const Voxmap out = to_dense(warp(domain, scaled));
    EXPECT_NEAR(enclosed_volume(out), 8 * enclosed_volume(input), 0.01 * 8 * enclosed_volume(input));
    // And the surface is the analytic sphere of radius 2.
    const TriangleMesh mesh = extract(out);
    double sum = 0;
    for (const auto& v : mesh.vertices) sum += std::abs((v - centre).norm() - 2.0);
    EXPECT_LE(sum / double(mesh.vertices.size()) / input.voxel_size, 0.25);
}

TEST(Warp, AStretchPastTheMemoryLimitIsRefused) {
    // Scaled twelvefold, the sphere's band grows to some ten million target cells (about 80 MiB of accumulators)
    // although its block tables stay small: only the band's growth can tell.
    const Voxmap input = sphere_voxmap();
    const WarpDomain domain = make_domain(input, {});
    Lattice scaled = domain.lattice;
    const Eigen::Vector3d centre(0.1, -0.2, 0.3);
    for (auto& p : scaled.points()) p = centre + 12.0 * (p - centre);
    try {
        warp(domain, scaled, {.max_memory_bytes = 16u << 20});
        ADD_FAILURE() << "a warp needing more than 16 MiB went through";
    } catch (const ResourceLimit& e) {
        EXPECT_NE(std::string(e.what()).find("16.00 MiB"), std::string::npos) << e.what();
    }
    // Within a limit it can keep, the same warp goes through.
    const SparseVoxmap out = warp(domain, scaled, {.max_memory_bytes = 1ull << 30});
    EXPECT_GT(out.bytes(), std::uint64_t(1) << 20);
}

TEST(Warp, RotatedBoxMatchesTheRotatedBox) {
    const Eigen::Vector3d lo(-1, -0.6, -0.4), hi(1, 0.6, 0.4);
    const Voxmap input = voxelize(test::box_mesh(lo, hi, 8), {.resolution = 48});
    const WarpDomain domain = make_domain(input, {.padding = 0.5});
    const Eigen::Matrix3d R = Eigen::AngleAxisd(30.0 * std::numbers::pi / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    Lattice rotated = domain.lattice;
    for (auto& p : rotated.points()) p = R * p; // B-splines reproduce affine maps: the warp is this rotation exactly
    const TriangleMesh out = extract(warp(domain, rotated));
    TriangleMesh rotated_box = test::box_mesh(lo, hi, 8);
    for (auto& v : rotated_box.vertices) v = R * v;
    const TriangleMesh expected = extract(voxelize(rotated_box, {.voxel_size = input.voxel_size}));
    const DistanceStats d = symmetric_distance(out, expected);
    EXPECT_LE(d.mean / input.voxel_size, 0.25);
    EXPECT_EQ(topology(out).boundary_edges, 0);
}

/// `rest` with every control point moved by a normal random offset of deviation `sigma` (world units).
Lattice jiggled(const Lattice& rest, unsigned seed, double sigma) {
    Lattice moved = rest;
    std::mt19937 rng(seed);
    std::normal_distribution<double> n(0, sigma);
    for (auto& p : moved.points()) p += Eigen::Vector3d(n(rng), n(rng), n(rng));
    return moved;
}

TEST(Warp, FastPathMatchesTheNaiveReference) {
    const Voxmap input = sphere_voxmap(20);
    const WarpDomain domain = make_domain(input, {.size = {7, 7, 7}});
    const Lattice moved = jiggled(domain.lattice, 11, 0.8 * input.voxel_size);
    EXPECT_LE(max_difference(to_dense(warp(domain, moved)), warp_reference(domain, moved)), 1e-6);
}

TEST(Warp, SharpStepsAtBlockEdgesMatchTheNaiveReference) {
    // A binary voxmap (0 and 1 only: a sharp step, no ramp) whose solid box starts and ends on 8^3 block edges, so
    // blocks of 1 meet blocks of 0 and the band must be found from the blocks' values alone, not their contents.
    Voxmap input({40, 37, 35}, Eigen::Vector3d(0.2, -0.1, 0.3), 0.05);
    for (std::int64_t k = 8; k < 24; ++k)
        for (std::int64_t j = 8; j < 32; ++j)
            for (std::int64_t i = 8; i < 32; ++i) input.at(i, j, k) = 1.0f;
    ASSERT_EQ(to_sparse(input).stored_block_count(), 0); // every block uniform
    const WarpDomain domain = make_domain(input, {.size = {6, 6, 6}});
    const Lattice moved = jiggled(domain.lattice, 5, 0.7 * input.voxel_size);
    const Voxmap fast = to_dense(warp(domain, moved));
    EXPECT_LE(max_difference(fast, warp_reference(domain, moved)), 1e-6);
    EXPECT_NEAR(enclosed_volume(fast), enclosed_volume(input), 0.05 * enclosed_volume(input));
}

TEST(Warp, NarrowBandMatchesTheNaiveReferenceOnALargeInterior) {
    // A sphere 40 voxels across: most of it lies beyond the band (2 voxels past the fractional densities),
    // where the fast path splats nothing and fills by side; the reference splats every voxel.
    const Voxmap input = sphere_voxmap(40);
    const WarpDomain domain = make_domain(input, {.size = {6, 6, 6}});
    const Lattice moved = jiggled(domain.lattice, 3, 1.5 * input.voxel_size);
    const Voxmap fast = to_dense(warp(domain, moved));
    EXPECT_LE(max_difference(fast, warp_reference(domain, moved)), 1e-6);
    std::size_t full = 0;
    for (float d : fast.density) full += d == 1.0f;
    EXPECT_GT(full, fast.density.size() / 20); // the interior is there, not just the band
}

TEST(Warp, RotationLeavesNoDensityDipsInside) {
    // The paper's "wv if weight < 1" turns the box filter's small coverage gaps under rotation into dips of
    // density inside the solid; voxwarp fills uncovered space with the side it lies on (resolve.h).
    const Eigen::Vector3d lo(-1, -0.6, -0.4), hi(1, 0.6, 0.4);
    const Voxmap input = voxelize(test::box_mesh(lo, hi, 8), {.resolution = 48});
    const WarpDomain domain = make_domain(input, {.padding = 0.5});
    const Eigen::Matrix3d R = Eigen::AngleAxisd(30.0 * std::numbers::pi / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    Lattice rotated = domain.lattice;
    for (auto& p : rotated.points()) p = R * p;
    const Voxmap out = to_dense(warp(domain, rotated));
    const double margin = 2.5 * input.voxel_size; // beyond the reach of the surface's fractional voxels
    std::size_t deep = 0;
    float lowest = 1.0f;
    for (std::int64_t k = 0; k < out.dims[2]; ++k)
        for (std::int64_t j = 0; j < out.dims[1]; ++j)
            for (std::int64_t i = 0; i < out.dims[0]; ++i) {
                const Eigen::Vector3d p = R.transpose() * out.world(double(i), double(j), double(k));
                if (((p - lo).array() > margin).all() && ((hi - p).array() > margin).all()) ++deep, lowest = std::min(lowest, out.at(i, j, k));
            }
    EXPECT_GT(deep, 1000u);
    EXPECT_EQ(lowest, 1.0f);
}

TEST(Warp, IncrementalEqualsFullRecompute) {
    const Voxmap input = sphere_voxmap();
    const WarpDomain domain = make_domain(input, {.size = {8, 9, 7}});
    Warp progressive(domain, domain.lattice);
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> ix(0, 7), iy(0, 8), iz(0, 6);
    std::normal_distribution<double> n(0, 1.5 * input.voxel_size);
    for (int step = 0; step < 12; ++step) {
        const int i = ix(rng), j = iy(rng), k = iz(rng);
        progressive.move_control_point(i, j, k, progressive.lattice().point(i, j, k) + Eigen::Vector3d(n(rng), n(rng), n(rng)));
    }
    const Voxmap incremental = to_dense(progressive.target());
    const Voxmap full = to_dense(warp(domain, progressive.lattice()));
    // Fixed-point sums make the two bit-identical, wherever each target's bounds lie.
    EXPECT_EQ(max_difference(incremental, full), 0.0);
}

TEST(Warp, DraggingOnePointEqualsFullRecompute) {
    // A drag: one control point moved again and again. From its second move on, each puts back the other regions'
    // sums kept then and splats the point's regions once; a move beyond the kept reach keeps them afresh, a move of
    // another point forgets them. Each step against the full warp, bit for bit.
    const Voxmap input = sphere_voxmap(48);
    const WarpDomain domain = make_domain(input, {.size = {9, 9, 9}});
    Warp progressive(domain, domain.lattice);
    const double h = input.voxel_size;
    // b's regions lie beside a's (none shared: x spans 3-5 and 0-2 of 6), their splats inside the reach a's drag
    // keeps.
    const std::array<int, 3> a{6, 4, 4}, b{2, 4, 4};
    const std::vector<std::pair<std::array<int, 3>, Eigen::Vector3d>> moves{
        {a, {h, h, 0}}, {a, {9 * h, 0, 0}}, {a, {-6 * h, h, h}}, {a, {-2 * h, -h, 0}}, // a drag, within the reach
        {b, {h, h, h}}, {a, {-2 * h, 0, h}}, {a, {h, -h, 0}},    {b, {-h, 2 * h, 0}},  // another point between
        {a, {25 * h, 0, 0}}, {a, {-24 * h, h, 0}}, {a, {h, h, 0}},                     // beyond the reach, and back
    };
    for (std::size_t step = 0; step < moves.size(); ++step) {
        const auto& [at, by] = moves[step];
        progressive.move_control_point(at[0], at[1], at[2], progressive.lattice().point(at[0], at[1], at[2]) + by);
        ASSERT_EQ(max_difference(to_dense(progressive.target()), to_dense(warp(domain, progressive.lattice()))), 0.0) << "step " << step;
    }
}

TEST(Warp, SameResultForAnyThreadCount) {
    const Voxmap input = sphere_voxmap();
    const WarpDomain domain = make_domain(input, {});
    Lattice moved = domain.lattice;
    moved.set_point(4, 4, 4, moved.point(4, 4, 4) + Eigen::Vector3d(2, 1, 0) * input.voxel_size);
    const Voxmap parallel = to_dense(warp(domain, moved));
    tbb::task_arena one(1);
    Voxmap serial;
    one.execute([&] { serial = to_dense(warp(domain, moved)); });
    EXPECT_EQ(parallel.density, serial.density);
}

TEST(Warp, ClampedCaptureWarpsTheSameData) {
    const Voxmap input = sphere_voxmap();
    const WarpDomain domain = make_domain(input, {.placement = Placement::clamped});
    const Voxmap out = to_dense(warp(domain, domain.lattice));
    EXPECT_NEAR(enclosed_volume(out), enclosed_volume(input), 0.02 * enclosed_volume(input));
    const TriangleMesh mesh = extract(out);
    double sum = 0;
    for (const auto& v : mesh.vertices) sum += std::abs((v - Eigen::Vector3d(0.1, -0.2, 0.3)).norm() - 1.0);
    EXPECT_LE(sum / double(mesh.vertices.size()) / input.voxel_size, 0.25);
}

/// A plate 0.4 voxel thick (voxel 0.05), 2 x 2, turned by `turn`: the voxmap keeps it as one layer of inside
/// voxels just above 0.5 (voxelize's thin walls), the case the box filter loses.
Voxmap thin_plate(const Eigen::Matrix3d& turn) {
    TriangleMesh plate = test::box_mesh({-1, -1, -0.01}, {1, 1, 0.01}, 2);
    for (auto& v : plate.vertices) v = turn * v;
    return voxelize(plate, {.voxel_size = 0.05, .sign = SignMethod::winding_number});
}

/// `rest` moved by the affine map x -> A x + t (a B-spline lattice reproduces it exactly).
Lattice affine(const Lattice& rest, const Eigen::Matrix3d& A, const Eigen::Vector3d& t) {
    Lattice moved = rest;
    for (auto& p : moved.points()) p = A * p + t;
    return moved;
}

TEST(Warp, ThinPlateKeepsItsTopologyUnderTurnsStretchesAndSqueezes) {
    // Twelve turned plates, each turned further, stretched 1.5x or squeezed to 0.7 along its normal, and shifted by
    // a fraction of a voxel. Without carrying thin voxels (resolve.h) every one of these came apart in holes.
    for (int trial = 0; trial < 12; ++trial) {
        const Eigen::Matrix3d turn = Eigen::AngleAxisd(0.3 + 0.37 * trial, Eigen::Vector3d(1, 0.3 * trial, 0.5).normalized()).toRotationMatrix();
        const Voxmap input = thin_plate(turn);
        const MeshTopology before = topology(extract(input));
        ASSERT_EQ(before.components, 1);
        ASSERT_EQ(before.euler, 2);
        const WarpDomain domain = make_domain(input, {});
        const Eigen::Vector3d normal = turn.col(2);
        const double along_normal = trial % 3 == 0 ? 1.0 : trial % 3 == 1 ? 1.5 : 0.7;
        const Eigen::Matrix3d A = Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, 1, 0.4).normalized()).toRotationMatrix() *
                                  (Eigen::Matrix3d::Identity() + (along_normal - 1) * normal * normal.transpose());
        const Eigen::Vector3d shift(0.013 * trial, 0.021, 0.007 * trial);
        const TriangleMesh out = extract(warp(domain, affine(domain.lattice, A, shift)));
        const MeshTopology after = topology(out);
        EXPECT_TRUE(after.watertight()) << "trial " << trial;
        EXPECT_EQ(after.components, 1) << "trial " << trial;
        EXPECT_EQ(after.euler, 2) << "trial " << trial;
        // The output stays about as close to the plate's image (its mid-plane) as the round trip is to the plate:
        // the carried layer is a voxel or two thick, not more. Distances along the image of the plate's normal.
        auto farthest = [&](const TriangleMesh& mesh, const Eigen::Matrix3d& map, const Eigen::Vector3d& offset) {
            double worst = 0;
            for (const auto& v : mesh.vertices) {
                const double z = (turn.transpose() * (map.inverse() * (v - offset))).z(); // in the plate's frame
                worst = std::max(worst, (map * normal * z).norm());
            }
            return worst / input.voxel_size;
        };
        const double round_trip = farthest(extract(input), Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero());
        // (A turned layer's image box reaches up to a voxel and a half past its image when stretched.)
        EXPECT_LT(farthest(out, A, shift), along_normal * round_trip + 1.5) << "trial " << trial << ", round trip " << round_trip;
    }
}

/// Two thin plates (each about half a voxel thick) parallel, their centres `apart` voxels apart, turned by `turn`.
Voxmap plate_pair(const Eigen::Matrix3d& turn, double apart) {
    constexpr double h = 0.05;
    TriangleMesh pair = test::joined(test::box_mesh({-1, -1, -0.01}, {1, 1, 0.01}, 2), test::box_mesh({-1, -1, apart * h - 0.01}, {1, 1, apart * h + 0.01}, 2));
    for (auto& v : pair.vertices) v = turn * v;
    return voxelize(pair, {.voxel_size = h, .sign = SignMethod::winding_number});
}

/// `rest` turned by 0.055 rad and shifted by a fraction of a voxel: axis-aligned plates a voxel apart come out
/// bridged in a few cells (resolve.h, bridges).
Lattice turned_a_little(const Lattice& rest) {
    return affine(rest, Eigen::AngleAxisd(0.055, Eigen::Vector3d(1, 2, 0.3).normalized()).toRotationMatrix(), Eigen::Vector3d(0.11, 0.017, 0.05));
}

TEST(Warp, BridgesBetweenThinPlatesMatchTheNaiveReference) {
    // Two plates a voxel apart, turned: walls' carried boxes reach across the gap (resolve.h, bridges), so both
    // warps give some of those cells back to the gap, and must give back the same ones.
    const Voxmap input = plate_pair(Eigen::Matrix3d::Identity(), 2.0);
    const WarpDomain domain = make_domain(input, {});
    const Lattice moved = turned_a_little(domain.lattice);
    const Voxmap fast = to_dense(warp(domain, moved));
    EXPECT_LE(max_difference(fast, warp_reference(domain, moved)), 1e-6);
}

TEST(Warp, ThinPartsMatchTheNaiveReference) {
    const Voxmap input = thin_plate(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 0.5).normalized()).toRotationMatrix());
    const WarpDomain domain = make_domain(input, {.size = {6, 6, 6}});
    const Lattice moved = jiggled(domain.lattice, 7, 0.8 * input.voxel_size);
    const Voxmap fast = to_dense(warp(domain, moved));
    EXPECT_LE(max_difference(fast, warp_reference(domain, moved)), 1e-6);
    std::size_t carried = 0; // the plate was carried somewhere (kCarriedInside is 0.5 + 1/64)
    for (float d : fast.density) carried += d == 0.5f + 1.0f / 64.0f;
    EXPECT_GT(carried, 0u);
}

TEST(Warp, IncrementalEqualsFullRecomputeWithBridges) {
    // Moves that make and unmake bridges between two plates a voxel apart (resolve.h): an incremental update puts
    // back the cells it gave to the gap and judges them all again, as the full warp does.
    const Voxmap input = plate_pair(Eigen::Matrix3d::Identity(), 2.0);
    const WarpDomain domain = make_domain(input, {});
    Warp progressive(domain, turned_a_little(domain.lattice));
    std::mt19937 rng(3); // a bridge appears, goes and comes back
    std::uniform_int_distribution<int> index(2, 6);
    std::normal_distribution<double> n(0, input.voxel_size);
    for (int step = 0; step < 10; ++step) {
        const int i = index(rng), j = index(rng), k = index(rng);
        progressive.move_control_point(i, j, k, progressive.lattice().point(i, j, k) + Eigen::Vector3d(n(rng), n(rng), n(rng)));
        ASSERT_EQ(max_difference(to_dense(progressive.target()), to_dense(warp(domain, progressive.lattice()))), 0.0) << "step " << step;
    }
}

TEST(Warp, IncrementalEqualsFullRecomputeWithThinParts) {
    const Voxmap input = thin_plate(Eigen::AngleAxisd(0.5, Eigen::Vector3d(0.3, 1, 0.2).normalized()).toRotationMatrix());
    const WarpDomain domain = make_domain(input, {.size = {7, 7, 7}});
    Warp progressive(domain, domain.lattice);
    std::mt19937 rng(9);
    std::uniform_int_distribution<int> index(0, 6);
    std::normal_distribution<double> n(0, 1.5 * input.voxel_size);
    for (int step = 0; step < 10; ++step) {
        const int i = index(rng), j = index(rng), k = index(rng);
        progressive.move_control_point(i, j, k, progressive.lattice().point(i, j, k) + Eigen::Vector3d(n(rng), n(rng), n(rng)));
    }
    EXPECT_EQ(max_difference(to_dense(progressive.target()), to_dense(warp(domain, progressive.lattice()))), 0.0);
}

/// A fog volume: `inside` within a sphere of radius 0.8, 0 outside, a linear ramp two voxels wide between.
Voxmap fog_sphere(float inside, double h = 0.05) {
    Voxmap v({48, 48, 48}, Eigen::Vector3d::Constant(-1.2), h);
    for (std::int64_t k = 0; k < 48; ++k)
        for (std::int64_t j = 0; j < 48; ++j)
            for (std::int64_t i = 0; i < 48; ++i) {
                const double r = v.world(double(i), double(j), double(k)).norm();
                v.at(i, j, k) = float(inside * std::clamp(0.5 - (r - 0.8) / (2 * h), 0.0, 1.0));
            }
    return v;
}

TEST(Warp, FogVolumesKeepTheirDensityAndTopology) {
    // A voxmap whose inside is not full (fog, CT data): the inside keeps its value, not 1, and the 0.5 isosurface
    // keeps its topology (a sphere for 0.6 and 1.0; no surface at all for 0.3).
    for (const float inside : {0.3f, 0.6f, 1.0f}) {
        const Voxmap input = fog_sphere(inside);
        const WarpDomain domain = make_domain(input, {.size = {7, 7, 7}});
        const Lattice moved = jiggled(domain.lattice, 4, 1.2 * input.voxel_size);
        const Voxmap out = to_dense(warp(domain, moved));
        float deep_low = 2, deep_high = -1, highest = 0;
        for (std::int64_t k = 0; k < out.dims[2]; ++k)
            for (std::int64_t j = 0; j < out.dims[1]; ++j)
                for (std::int64_t i = 0; i < out.dims[0]; ++i) {
                    const float d = out.at(i, j, k);
                    highest = std::max(highest, d);
                    if (out.world(double(i), double(j), double(k)).norm() < 0.5) deep_low = std::min(deep_low, d), deep_high = std::max(deep_high, d);
                }
        EXPECT_NEAR(deep_low, inside, 1e-5) << inside;
        EXPECT_NEAR(deep_high, inside, 1e-5) << inside;
        if (inside < 0.5f) {
            EXPECT_LT(highest, 0.5f);
        } else {
            const MeshTopology t = topology(extract(out));
            EXPECT_TRUE(t.watertight()) << inside;
            EXPECT_EQ(t.components, 1) << inside;
            EXPECT_EQ(t.euler, 2) << inside;
        }
    }
}

TEST(Foldover, DeliberateFoldIsReported) {
    const Lattice rest = Lattice::uniform({9, 9, 9}, {0, 0, 0}, {1, 1, 1});
    EXPECT_TRUE(find_folds(rest).empty());
    Lattice folded = rest;
    // dx/ds near the point drops by up to 0.667 * (2/3)^2 = 0.30 per unit of displacement: 6 units fold it.
    folded.set_point(4, 4, 4, rest.point(4, 4, 4) + Eigen::Vector3d(-6, 0, 0));
    const auto folds = find_folds(folded);
    ASSERT_FALSE(folds.empty());
    for (const auto& f : folds) {
        EXPECT_LT(f.min_determinant, 0.0);
        for (int a = 0; a < 3; ++a) { // every reported region is one the moved point shapes
            EXPECT_GE(f.region[std::size_t(a)], 1);
            EXPECT_LE(f.region[std::size_t(a)], 4);
        }
    }
}

} // namespace
} // namespace voxwarp
