#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp_internal/vdb_convert.h>

#include <openvdb/tools/Dense.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <bit>
#include <cmath>
#include <cstdio>
#include <limits>

namespace voxwarp::vdb_internal {

openvdb::math::Transform::Ptr voxmap_transform(const Eigen::Vector3d& origin, double voxel_size) {
    if (!(voxel_size >= kSmallestVdbVoxel)) {
        char text[160];
        std::snprintf(text, sizeof text, "voxel size %g is below %g, the smallest an OpenVDB grid's transform takes; scale the model up", voxel_size,
                      kSmallestVdbVoxel);
        throw InvalidInput(text);
    }
    auto xform = openvdb::math::Transform::createLinearTransform(voxel_size);
    xform->postTranslate(openvdb::Vec3d(origin.x(), origin.y(), origin.z()));
    return xform;
}

openvdb::FloatGrid::Ptr to_density_grid(const SparseVoxmap& voxmap, bool index_space) {
    // First, so that a voxel OpenVDB cannot hold is refused before the work.
    const auto xform = index_space ? openvdb::math::Transform::createLinearTransform(1.0) : voxmap_transform(voxmap.origin(), voxmap.voxel_size());
    // The voxmap's blocks are OpenVDB's leaves: a stored block becomes a leaf (built in parallel, transposed
    // from x fastest to OpenVDB's z fastest), a uniform nonzero block a tile. Only the tree insertions are serial.
    using LeafT = openvdb::FloatTree::LeafNodeType;
    static_assert(LeafT::DIM == SparseVoxmap::kSide);
    constexpr std::int64_t B = SparseVoxmap::kSide;
    const auto& bd = voxmap.block_dims();
    const std::size_t blocks = std::size_t(voxmap.block_count());
    auto block_origin = [&](std::size_t b) {
        return openvdb::Coord(int(std::int64_t(b % std::size_t(bd[0])) * B), int(std::int64_t((b / std::size_t(bd[0])) % std::size_t(bd[1])) * B),
                              int(std::int64_t(b / std::size_t(bd[0] * bd[1])) * B));
    };
    std::vector<LeafT*> leaves(blocks, nullptr);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks), [&](const auto& range) {
        for (std::size_t b = range.begin(); b != range.end(); ++b) {
            const float* values = voxmap.block_values(std::int64_t(b));
            if (!values) continue;
            auto* leaf = new LeafT(block_origin(b), 0.0f, false);
            for (int k = 0; k < B; ++k)
                for (int j = 0; j < B; ++j)
                    for (int i = 0; i < B; ++i)
                        if (const float v = values[i + B * (j + B * k)]; v != 0.0f) leaf->setValueOn(LeafT::coordToOffset(openvdb::Coord(i, j, k)), v);
            leaves[b] = leaf;
        }
    });
    auto grid = openvdb::FloatGrid::create(0.0f);
    auto& tree = grid->tree();
    const auto& dims = voxmap.dims();
    for (std::size_t b = 0; b < blocks; ++b) {
        if (leaves[b]) {
            tree.addLeaf(leaves[b]);
            continue;
        }
        const float u = voxmap.block_uniform(std::int64_t(b));
        if (u == 0.0f) continue;
        const openvdb::Coord origin = block_origin(b);
        if (origin.x() + B <= dims[0] && origin.y() + B <= dims[1] && origin.z() + B <= dims[2]) {
            tree.addTile(1, origin, u, true); // level 1: a tile the size of one leaf
            continue;
        }
        // A border block: past dims the voxmap reads 0, so only the voxels inside take the value.
        auto* leaf = new LeafT(origin, 0.0f, false);
        for (int k = 0; k < B && origin.z() + k < dims[2]; ++k)
            for (int j = 0; j < B && origin.y() + j < dims[1]; ++j)
                for (int i = 0; i < B && origin.x() + i < dims[0]; ++i) leaf->setValueOn(LeafT::coordToOffset(openvdb::Coord(i, j, k)), u);
        tree.addLeaf(leaf);
    }
    grid->setTransform(xform);
    return grid;
}

openvdb::FloatGrid::Ptr to_density_grid(const Voxmap& voxmap) { return to_density_grid(to_sparse(voxmap)); }

namespace {

/// What a float grid becomes as a voxmap: its voxel size and the index box the voxmap covers (the active
/// bounding box, a level set's one more voxel each side, and the stored dims of a file voxwarp wrote).
struct GridFrame {
    double h = 0;
    openvdb::CoordBBox box;
    bool level_set = false;
};

/// Whether every value the grid holds (leaf voxels, tiles, background) is finite.
bool finite_values(const openvdb::FloatGrid& grid) {
    const auto& tree = grid.tree();
    if (!std::isfinite(tree.background())) return false;
    std::vector<const openvdb::FloatTree::LeafNodeType*> leaves;
    leaves.reserve(tree.leafCount());
    tree.getNodes(leaves);
    const bool leaves_finite = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, leaves.size(), 256), true,
        [&](const auto& r, bool ok) {
            for (std::size_t i = r.begin(); ok && i != r.end(); ++i) {
                const float* v = leaves[i]->buffer().data();
                bool all = true;
                for (int k = 0; k < 512; ++k) all &= std::isfinite(v[k]);
                ok = all;
            }
            return ok;
        },
        [](bool a, bool b) { return a && b; });
    if (!leaves_finite) return false;
    auto tiles = tree.cbeginValueAll();
    tiles.setMaxDepth(openvdb::FloatTree::ValueAllCIter::LEAF_DEPTH - 1);
    for (; tiles; ++tiles)
        if (!std::isfinite(*tiles)) return false;
    return true;
}

GridFrame grid_frame(const openvdb::FloatGrid& grid, const std::string& source) {
    const auto& xform = grid.transform();
    if (!xform.isLinear() || !xform.hasUniformScale())
        throw InvalidInput(source + ": grid '" + grid.getName() + "' has a non-uniform or non-linear transform; voxmaps need cubic voxels");
    // Rotation would leave index axes off the world axes: compare the mapped unit axes with a pure scale.
    const double h = xform.voxelSize()[0];
    const auto o = xform.indexToWorld(openvdb::Vec3d(0, 0, 0));
    for (int a = 0; a < 3; ++a) {
        openvdb::Vec3d e(0, 0, 0);
        e[a] = 1;
        const auto d = xform.indexToWorld(e) - o;
        for (int b = 0; b < 3; ++b)
            if (std::abs(d[b] - (a == b ? h : 0.0)) > 1e-9 * h)
                throw InvalidInput(source + ": grid '" + grid.getName() + "' is rotated or sheared; voxmaps need axis-aligned voxels");
    }
    if (!(h > 0) || !std::isfinite(h)) throw InvalidInput(source + ": grid '" + grid.getName() + "' has voxel size " + std::to_string(h));
    // Before the bounding box: a damaged file's NaN tile can lie far off, and the voxmap would cover the way there.
    if (!finite_values(grid)) throw InvalidInput(source + ": grid '" + grid.getName() + "' holds non-finite values (NaN or infinity)");

    GridFrame frame{h, grid.evalActiveVoxelBoundingBox(), grid.getGridClass() == openvdb::GRID_LEVEL_SET};
    if (frame.box.empty()) throw InvalidInput(source + ": grid '" + grid.getName() + "' has no active voxels");
    if (frame.level_set) frame.box.expand(1); // the ramp can reach one voxel past the band's last active voxel
    if (auto meta = grid.getMetadata<openvdb::Vec3IMetadata>("voxwarp_dims")) {
        const auto d = meta->value();
        if (d[0] > 0 && d[1] > 0 && d[2] > 0) frame.box.expand(openvdb::CoordBBox(openvdb::Coord(0, 0, 0), openvdb::Coord(d[0] - 1, d[1] - 1, d[2] - 1)));
    }
    return frame;
}

/// Grid value -> density: a level set's signed distance through a one-voxel ramp, anything else clamped to [0, 1].
/// (grid_frame has refused grids holding NaN or infinity.)
inline float to_density(float v, const GridFrame& frame) {
    if (frame.level_set) v = 0.5f - 0.5f * v / float(frame.h);
    return v < 0 ? 0.0f : (v > 1 ? 1.0f : v);
}

} // namespace

Voxmap from_float_grid(const openvdb::FloatGrid& grid, const std::string& source) {
    const GridFrame frame = grid_frame(grid, source);
    const openvdb::CoordBBox& box = frame.box;
    const std::array<std::int64_t, 3> dims{box.dim()[0], box.dim()[1], box.dim()[2]};
    require_memory(voxmap_bytes(dims), 0, source + ": a dense voxmap of " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]));

    const auto origin = grid.transform().indexToWorld(box.min());
    Voxmap voxmap(dims, Eigen::Vector3d(origin[0], origin[1], origin[2]), frame.h);
    using DenseT = openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ>;
    DenseT dense(box, voxmap.density.data());
    openvdb::tools::copyToDense(grid, dense);

    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, voxmap.density.size(), 1 << 16), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) voxmap.density[i] = to_density(voxmap.density[i], frame);
    });
    return voxmap;
}

SparseVoxmap sparse_from_float_grid(const openvdb::FloatGrid& grid, const std::string& source) {
    GridFrame frame = grid_frame(grid, source);
    // Start the voxmap on a multiple of 8 so that each of its blocks is one of the grid's leaf positions: a leaf
    // becomes a block, a tile (or background) one value. The few extra voxels are the grid's own values.
    constexpr int B = int(SparseVoxmap::kSide);
    openvdb::Coord lo = frame.box.min();
    for (int a = 0; a < 3; ++a) lo[a] &= ~(B - 1);
    frame.box = openvdb::CoordBBox(lo, frame.box.max());
    const std::array<std::int64_t, 3> dims{frame.box.dim()[0], frame.box.dim()[1], frame.box.dim()[2]};
    // A value and a pointer for every block of the box, 2 KiB for each leaf: voxels far apart (a grid of two voxels
    // 5000 apart took 3.9 GB) are refused with the estimate.
    long double bytes = (long double)grid.tree().leafCount() * SparseVoxmap::kBlockVoxels * sizeof(float);
    bytes += (long double)((dims[0] + B - 1) / B) * (long double)((dims[1] + B - 1) / B) * (long double)((dims[2] + B - 1) / B) * (sizeof(float) + sizeof(void*));
    require_memory(bytes >= 1.8e19L ? std::numeric_limits<std::uint64_t>::max() : std::uint64_t(bytes), 0,
                   source + ": a voxmap of " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]));
    const auto origin = grid.transform().indexToWorld(lo);
    SparseVoxmap voxmap(dims, Eigen::Vector3d(origin[0], origin[1], origin[2]), frame.h);
    grid_to_blocks(grid, lo, voxmap, [&](float v) { return to_density(v, frame); });
    return voxmap;
}

} // namespace voxwarp::vdb_internal

#include <voxwarp/progress.h>

namespace voxwarp::vdb_internal {

bool ProgressInterrupter::wasInterrupted(int percent) {
    if (!progress) return false;
    return percent >= 0 ? !progress->poll(percent / 100.0) : progress->cancelled();
}

} // namespace voxwarp::vdb_internal
