/// @file features.h
/// @brief Internal: sharp edges and corners put back on marching cubes' output (features.cpp).
#pragma once

#include <voxwarp/extract.h>

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
