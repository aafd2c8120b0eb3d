/// @file features.h
/// @brief Internal: sharp edges and corners put back on marching cubes' output (features.cpp).
#pragma once

#include <voxwarp/extract.h>

#include <array>
#include <cstdint>
#include <utility>
#include <vector>

namespace voxwarp::extract_internal {

using Index3 = std::array<std::int64_t, 3>;

/// A cell's key: 21 bits per axis, offset so that the border's cells (index -1) fit.
inline std::uint64_t cell_key(const Index3& c) {
    return std::uint64_t(c[0] + 2) | std::uint64_t(c[1] + 2) << 21 | std::uint64_t(c[2] + 2) << 42;
}

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
