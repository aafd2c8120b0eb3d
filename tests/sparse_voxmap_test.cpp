// The block-sparse voxmap: exact against the dense one it stands for, and memory only where the surface is.
#include "test_helpers.h"

#include <voxwarp/extract.h>
#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/voxelize.h>
#include <voxwarp/warp.h>

#include <gtest/gtest.h>

#include <bit>
#include <random>

namespace voxwarp {
namespace {

/// A ball of density (1 inside, 0 outside, a random fraction in a shell a voxel thick) on a grid whose dims are
/// not multiples of 8, so border blocks are partial.
Voxmap ball(std::array<std::int64_t, 3> dims, double radius) {
    Voxmap v(dims, Eigen::Vector3d(0.5, -1, 2), 0.25);
    std::mt19937 random(7);
    std::uniform_real_distribution<float> fraction(0.01f, 0.99f);
    const Eigen::Vector3d centre = Eigen::Vector3d(double(dims[0]), double(dims[1]), double(dims[2])) / 2;
    for (std::int64_t k = 0; k < dims[2]; ++k)
        for (std::int64_t j = 0; j < dims[1]; ++j)
            for (std::int64_t i = 0; i < dims[0]; ++i) {
                const double r = (Eigen::Vector3d(double(i), double(j), double(k)) - centre).norm();
                v.at(i, j, k) = r < radius - 0.5 ? 1.0f : r > radius + 0.5 ? 0.0f : fraction(random);
            }
    return v;
}

bool bitwise_equal(const Voxmap& a, const Voxmap& b) {
    if (a.dims != b.dims || a.origin != b.origin || a.voxel_size != b.voxel_size) return false;
    for (std::size_t i = 0; i < a.density.size(); ++i)
        if (std::bit_cast<std::uint32_t>(a.density[i]) != std::bit_cast<std::uint32_t>(b.density[i])) return false;
    return true;
}

TEST(SparseVoxmap, HoldsExactlyTheDenseValues) {
    const Voxmap dense = ball({37, 29, 21}, 9.0);
    const SparseVoxmap sparse = to_sparse(dense);
    EXPECT_EQ(sparse.dims(), dense.dims);
    EXPECT_EQ(sparse.block_dims(), (std::array<std::int64_t, 3>{5, 4, 3}));
    for (std::int64_t k = -1; k <= dense.dims[2]; ++k)
        for (std::int64_t j = -1; j <= dense.dims[1]; ++j)
            for (std::int64_t i = -1; i <= dense.dims[0]; ++i) {
                const bool inside = i >= 0 && j >= 0 && k >= 0 && i < dense.dims[0] && j < dense.dims[1] && k < dense.dims[2];
                ASSERT_EQ(sparse.at(i, j, k), inside ? dense.at(i, j, k) : 0.0f) << i << " " << j << " " << k;
            }
    EXPECT_TRUE(bitwise_equal(to_dense(sparse), dense));
    std::vector<float> row(std::size_t(dense.dims[0]));
    for (std::int64_t k = 0; k < dense.dims[2]; ++k)
        for (std::int64_t j = 0; j < dense.dims[1]; ++j) {
            sparse.read_row(j, k, row.data());
            for (std::int64_t i = 0; i < dense.dims[0]; ++i) ASSERT_EQ(row[std::size_t(i)], dense.at(i, j, k));
        }
    EXPECT_NEAR(enclosed_volume(sparse), enclosed_volume(dense), 1e-9 * enclosed_volume(dense));
    const double h = dense.voxel_size;
    EXPECT_NEAR(enclosed_volume(sparse) / (h * h * h), 4.0 / 3.0 * 3.14159265 * 9 * 9 * 9, 0.05 * 3054); // the ball's volume, roughly
}

TEST(SparseVoxmap, StoresOnlyBlocksThatTheSurfaceCrosses) {
    // A 100^3 grid with a ball of radius 40: 13^3 blocks, of which only those the one-voxel shell touches hold
    // values. The shell has area 4 pi 40^2 = 20100 voxels; a surface meets at most about three 8^3 blocks per
    // 64 voxels of its area.
    const Voxmap dense = ball({100, 100, 100}, 40.0);
    const SparseVoxmap sparse = to_sparse(dense);
    EXPECT_LE(sparse.stored_block_count(), 3 * 20100 / 64);
    EXPECT_GE(sparse.stored_block_count(), 20100 / 64);
    EXPECT_LT(sparse.bytes(), voxmap_bytes(dense.dims) / 4);
    // The uniform blocks read as their side.
    EXPECT_EQ(sparse.at(50, 50, 50), 1.0f);
    EXPECT_EQ(sparse.at(1, 1, 1), 0.0f);
}

TEST(SparseVoxmap, UniformBorderBlocksCoverOnlyTheirVoxelsInside) {
    // A solid 10^3 block of material: every block uniform (1 inside dims), nothing stored, and past dims 0.
    Voxmap dense({10, 10, 10}, Eigen::Vector3d::Zero(), 1.0);
    std::fill(dense.density.begin(), dense.density.end(), 1.0f);
    const SparseVoxmap sparse = to_sparse(dense);
    EXPECT_EQ(sparse.stored_block_count(), 0);
    EXPECT_EQ(sparse.at(9, 9, 9), 1.0f);
    EXPECT_EQ(sparse.at(10, 9, 9), 0.0f);
    EXPECT_DOUBLE_EQ(enclosed_volume(sparse), 1000.0);
    EXPECT_TRUE(bitwise_equal(to_dense(sparse), dense));
    // Extracted, it is the 10-voxel cube's surface (the density drops to 0 past the border), closed.
    const TriangleMesh mesh = extract(sparse);
    const MeshTopology t = topology(mesh);
    EXPECT_TRUE(t.watertight());
    EXPECT_EQ(t.euler, 2);
    EXPECT_EQ(t.components, 1);
}

TEST(SparseVoxmap, CopiesAreDeep) {
    SparseVoxmap a = to_sparse(ball({20, 20, 20}, 6.0));
    const SparseVoxmap b = a;
    std::int64_t stored = -1;
    for (std::int64_t q = 0; q < a.block_count() && stored < 0; ++q)
        if (a.block_values(q)) stored = q;
    ASSERT_GE(stored, 0);
    const std::vector<float> before(b.block_values(stored), b.block_values(stored) + SparseVoxmap::kBlockVoxels);
    a.set_uniform(stored, 0.5f);
    ASSERT_NE(b.block_values(stored), nullptr);
    EXPECT_TRUE(std::equal(before.begin(), before.end(), b.block_values(stored)));
}

TEST(SparseVoxmap, VoxelizeSparseEqualsTheDenseVoxelize) {
    const TriangleMesh torus = test::torus_mesh({0.1, 0, -0.2}, 1.0, 0.35, 96, 48);
    for (const SignMethod method : {SignMethod::flood_fill, SignMethod::winding_number}) {
        const VoxelizeOptions options{.resolution = 41, .sign = method};
        EXPECT_TRUE(bitwise_equal(to_dense(voxelize_sparse(torus, options)), voxelize(torus, options))) << int(method);
    }
}

TEST(SparseVoxmap, ConsumingWarpFreesItsDomain) {
    WarpDomain domain = make_domain(voxelize_sparse(test::sphere_mesh({0, 0, 0}, 1.0, 3), {.resolution = 24}), {});
    const Lattice identity = domain.lattice;
    const Voxmap borrowed = to_dense(warp(domain, identity));
    const SparseVoxmap consumed = warp(std::move(domain), identity);
    EXPECT_TRUE(domain.voxmap.empty()); // NOLINT(bugprone-use-after-move): emptying it is the documented effect
    EXPECT_TRUE(bitwise_equal(to_dense(consumed), borrowed));
}

} // namespace
} // namespace voxwarp
