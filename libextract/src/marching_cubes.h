/// @file marching_cubes.h
/// @brief Internal: the primal mesher behind extract() (see marching_cubes.cpp for its rules).
#pragma once

#include <voxwarp/progress.h>
#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/triangle_mesh.h>

namespace voxwarp::extract_internal {

/// Triangles of the isosurface `isovalue` of the voxmap's trilinear field, one vertex on each grid edge
/// whose ends lie on opposite sides (inside = density >= isovalue; everything past dims is outside), faces
/// counter-clockwise seen from outside. Parallel over 8^3 blocks; the output does not depend on the thread
/// count.
TriangleMesh marching_cubes(const SparseVoxmap& voxmap, float isovalue, Progress& progress);

} // namespace voxwarp::extract_internal
