/// @file features.h
/// @brief Internal: sharp edges and corners put back on marching cubes' output (features.cpp).
#pragma once

#include <voxwarp/extract.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

namespace voxwarp::extract_internal {

using Index3 = std::array<std::int64_t, 3>;

/// A cell's key: 21 bits per axis, offset so that the border's cells (index -1) fit.
inline std::uint64_t cell_key(const Index3& c) {
    return std::uint64_t(c[0] + 2) | std::uint64_t(c[1] + 2) << 21 | std::uint64_t(c[2] + 2) << 42;
}

/// The cell a key names (cell_key's inverse).
inline Index3 key_cell(std::uint64_t key) {
    return {std::int64_t(key & 0x1fffff) - 2, std::int64_t(key >> 21 & 0x1fffff) - 2, std::int64_t(key >> 42) - 2};
}

/// The cell (voxel index of its low corner) holding a point given in index space.
inline Index3 cell_containing(const Eigen::Vector3d& q) {
    return {std::int64_t(std::floor(q.x())), std::int64_t(std::floor(q.y())), std::int64_t(std::floor(q.z()))};
}

/// Ids hashed by the cells a box (index space) covers: the feature surface's triangles, the sharp edges.
class CellBuckets {
public:
    void add(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, std::uint32_t id) {
        const Index3 a = cell_containing(lo), b = cell_containing(hi);
        for (std::int64_t z = a[2]; z <= b[2]; ++z)
            for (std::int64_t y = a[1]; y <= b[1]; ++y)
                for (std::int64_t x = a[0]; x <= b[0]; ++x) cells_[cell_key({x, y, z})].push_back(id);
    }
    /// The ids in the cell with this key, or none.
    const std::vector<std::uint32_t>& at(std::uint64_t key) const {
        static const std::vector<std::uint32_t> none;
        const auto it = cells_.find(key);
        return it == cells_.end() ? none : it->second;
    }

private:
    std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> cells_;
};

/// Which 8^3 blocks of cells hold a marked cell: a byte per block over the voxmap and 8 cells around it, so that a
/// cell or box with nothing marked in it is known without a hash lookup (the buckets above are hash maps, and a
/// pass over every vertex or triangle spent most of its time asking them about empty cells).
class CoarseMarks {
public:
    explicit CoarseMarks(const SparseVoxmap& v) {
        for (std::size_t a = 0; a < 3; ++a) dims_[a] = (v.dims()[a] + 2 * kMargin) / kSide + 1;
        marks_.assign(std::size_t(dims_[0] * dims_[1] * dims_[2]), 0);
    }
    /// Mark the cells in [lo, hi] (inclusive; those beyond the margin are never asked about).
    void mark(const Index3& lo, const Index3& hi) {
        Index3 a, b;
        if (!range(lo, hi, a, b)) return;
        for (std::int64_t z = a[2]; z <= b[2]; ++z)
            for (std::int64_t y = a[1]; y <= b[1]; ++y)
                for (std::int64_t x = a[0]; x <= b[0]; ++x) marks_[std::size_t(x + dims_[0] * (y + dims_[1] * z))] = 1;
    }
    /// False when no cell in [lo, hi] is marked (true may still mean none: blocks are coarse).
    bool any(const Index3& lo, const Index3& hi) const {
        Index3 a, b;
        if (!range(lo, hi, a, b)) return false;
        for (std::int64_t z = a[2]; z <= b[2]; ++z)
            for (std::int64_t y = a[1]; y <= b[1]; ++y)
                for (std::int64_t x = a[0]; x <= b[0]; ++x)
                    if (marks_[std::size_t(x + dims_[0] * (y + dims_[1] * z))]) return true;
        return false;
    }

private:
    static constexpr std::int64_t kSide = 8, kMargin = 8;
    /// The blocks holding cells [lo, hi], clipped to the grid; false when none is in it.
    bool range(const Index3& lo, const Index3& hi, Index3& a, Index3& b) const {
        for (std::size_t k = 0; k < 3; ++k) {
            a[k] = std::max<std::int64_t>(0, block(lo[k])), b[k] = std::min(dims_[k] - 1, block(hi[k]));
            if (a[k] > b[k]) return false;
        }
        return true;
    }
    static std::int64_t block(std::int64_t cell) { return cell + kMargin >= 0 ? (cell + kMargin) / kSide : -1; }
    Index3 dims_{};
    std::vector<std::uint8_t> marks_;
};

/// `mesh`, marching cubes' output for `voxmap` (every vertex on a grid edge, every triangle in one cell), with
/// the cells that hold a sharp part re-meshed as fans around their feature points and those points joined.
TriangleMesh restore_features(TriangleMesh mesh, const SparseVoxmap& voxmap, const ExtractOptions& options);

/// The feature mesher's last step (feature_edges.cpp): each mesh edge that passes under one of the input's sharp
/// `edges` (world units), its ends on either side, is split at the sharp edge's point nearest it; edges whose ends'
/// `normals` (one per vertex of marching cubes' output, zero where unknown) agree within `cos_feature` lie on one
/// face and are left. The mesh stays a closed 2-manifold.
void split_across_sharp_edges(std::vector<Eigen::Vector3d>& vertices, std::vector<std::array<std::int32_t, 3>>& triangles, const std::vector<Eigen::Vector3d>& normals,
                              double cos_feature, const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& edges, const SparseVoxmap& voxmap);

} // namespace voxwarp::extract_internal
