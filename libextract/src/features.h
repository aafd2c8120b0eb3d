/// @file features.h
/// @brief Internal: sharp edges and corners put back on marching cubes' output (features.cpp).
#pragma once

#include <voxwarp/extract.h>

namespace voxwarp::extract_internal {

/// `mesh`, marching cubes' output for `voxmap` (every vertex on a grid edge, every triangle in one cell), with
/// the cells that hold a sharp part re-meshed as fans around their feature points and those points joined.
TriangleMesh restore_features(TriangleMesh mesh, const SparseVoxmap& voxmap, const ExtractOptions& options);

} // namespace voxwarp::extract_internal
