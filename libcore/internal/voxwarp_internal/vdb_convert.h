/// @file vdb_convert.h
/// @brief Internal: voxmap <-> OpenVDB FloatGrid conversions shared by voxwarp's libraries.
/// Not installed, not public: it pulls in OpenVDB, which public headers keep out.
#pragma once

#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/voxmap.h>

#include <openvdb/openvdb.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <string>

namespace voxwarp::vdb_internal {

/// Transform taking grid index (i, j, k) to the world centre of voxmap voxel (i, j, k). @throw InvalidInput for a
/// voxel under kSmallestVdbVoxel, which OpenVDB's transforms refuse.
openvdb::math::Transform::Ptr voxmap_transform(const Eigen::Vector3d& origin, double voxel_size);
/// OpenVDB's linear transforms need a scale whose cube is at least 3e-15 (math::ScaleMap).
inline constexpr double kSmallestVdbVoxel = 1.45e-5;

/// Sparse copy of a voxmap's density (background 0; constant blocks become tiles). Parallel. With `index_space`,
/// the grid's transform is the identity (grid index = voxmap index), whatever the voxel size.
openvdb::FloatGrid::Ptr to_density_grid(const Voxmap& voxmap);
openvdb::FloatGrid::Ptr to_density_grid(const SparseVoxmap& voxmap, bool index_space = false);

/// Fill `out` block by block from `grid`: the grid's leaf at index lo + 8 (bx, by, bz) becomes block (bx, by, bz),
/// its values (OpenVDB's z fastest) transposed to x fastest, each through f; where there is no leaf, the tile
/// or background value there, through f, fills the block. Parallel over blocks: f must be thread-safe.
template <class F>
void grid_to_blocks(const openvdb::FloatGrid& grid, const openvdb::Coord& lo, SparseVoxmap& out, F&& f) {
    using LeafT = openvdb::FloatTree::LeafNodeType;
    constexpr int B = int(SparseVoxmap::kSide);
    static_assert(LeafT::DIM == B);
    const auto& bd = out.block_dims();
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, out.block_count()), [&](const auto& range) {
        auto accessor = grid.getConstAccessor();
        float block[SparseVoxmap::kBlockVoxels];
        for (std::int64_t b = range.begin(); b != range.end(); ++b) {
            const openvdb::Coord at = lo + openvdb::Coord(int(b % bd[0]) * B, int((b / bd[0]) % bd[1]) * B, int(b / (bd[0] * bd[1])) * B);
            if (const LeafT* leaf = accessor.probeConstLeaf(at)) {
                const float* values = leaf->buffer().data();
                for (int k = 0; k < B; ++k)
                    for (int j = 0; j < B; ++j)
                        for (int i = 0; i < B; ++i) block[i + B * (j + B * k)] = f(values[(i << 6) | (j << 3) | k]);
                out.set_block(b, block);
            } else {
                out.set_uniform(b, f(accessor.getValue(at)));
            }
        }
    });
}

/// Dense voxmap of a float grid's active bounding box. Level sets (GRID_LEVEL_SET) are converted to
/// density with a ramp one voxel wide on each side of the zero crossing; other grids are clamped to [0, 1].
/// `source` names the file in messages. @throw InvalidInput, ResourceLimit.
Voxmap from_float_grid(const openvdb::FloatGrid& grid, const std::string& source);
/// The same, block-sparse, its origin moved down to the nearest multiple of 8 voxels (so blocks are leaves).
SparseVoxmap sparse_from_float_grid(const openvdb::FloatGrid& grid, const std::string& source);

} // namespace voxwarp::vdb_internal

namespace voxwarp {
class Progress;
}

namespace voxwarp::vdb_internal {

/// OpenVDB interrupter (start/end/wasInterrupted) reporting through a voxwarp::Progress. It never throws
/// inside OpenVDB; the caller calls progress.check() once the OpenVDB operation has returned.
struct ProgressInterrupter {
    Progress* progress = nullptr;
    void start(const char* = nullptr) {}
    void end() {}
    bool wasInterrupted(int percent = -1);
};

} // namespace voxwarp::vdb_internal
