/// @file extract.h
/// @brief Voxmap -> indexed, shared-vertex, watertight polygon mesh of its 0.5 isosurface.
///
/// Uses OpenVDB's VolumeToMesh (dual contouring of the sign changes, vertices placed from the linearly
/// interpolated edge crossings). Output positions are world units in the voxmap's frame; faces are
/// counter-clockwise seen from outside (outside = density below the isovalue). Where the density is zero on
/// the voxmap's border the result is a closed 2-manifold.
#pragma once

#include <voxwarp/progress.h>
#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/triangle_mesh.h>
#include <voxwarp/voxmap.h>

namespace voxwarp {

struct ExtractOptions {
    double isovalue = 0.5;   ///< density of the surface, (0, 1)
    double adaptivity = 0.0; ///< OpenVDB's adaptivity [0, 1]: 0 = uniform faces, higher merges flat areas
    bool quads = false;      ///< keep OpenVDB's quads instead of splitting each into two triangles
    ProgressCallback progress; ///< optional progress / cancel
};

/// Extract the isosurface. Parallel (oneTBB, inside OpenVDB).
/// @throw InvalidInput for an isovalue outside (0, 1) or adaptivity outside [0, 1]; Cancelled.
TriangleMesh extract(const Voxmap& voxmap, const ExtractOptions& options = {});
/// The same from a block-sparse voxmap: its blocks become the grid's leaves and tiles directly.
TriangleMesh extract(const SparseVoxmap& voxmap, const ExtractOptions& options = {});

} // namespace voxwarp
