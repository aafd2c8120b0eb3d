/// @file marching_cubes.h
/// @brief Internal: the primal mesher behind extract() (see marching_cubes.cpp for its rules).
#pragma once

#include <voxwarp/progress.h>
#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/triangle_mesh.h>

#include <array>
#include <cstdint>
#include <vector>

namespace voxwarp::extract_internal {

/// Where one block of cells put its output, in the order of the blocks: its vertices and triangles are the runs
/// from here to the next block's; its cells are first_cell + [0, kCells) on each axis (every triangle lies in one
/// of them, every vertex on an edge of one).
struct MarchingBlock {
    static constexpr int kCells = 8; ///< cells per block side
    std::array<std::int64_t, 3> first_cell;
    std::uint32_t first_vertex, first_triangle;
};

/// Parameter units: how near a crossing may come to either end of its grid edge. A corner at the isovalue itself
/// (where a warp leaves a face on a plane of voxels) would put the crossings of all its edges on one point:
/// distinct vertices at one position, and triangles with none of their area. Kept apart by eight steps of a 32-bit
/// float at the domain's largest coordinate (2^-24 of it), so that they stay apart in the formats that store
/// positions as floats (PLY, STL, glTF): a millionth of a voxel, as before, merged 67 vertices of the bar bend at
/// 128 with others in its PLY. At least a millionth of a voxel, at most a hundredth (a model far from its origin
/// keeps less than that in floats anyway).
double edge_margin(const SparseVoxmap& voxmap);

/// Triangles of the isosurface `isovalue` of the voxmap's trilinear field, one vertex on each grid edge
/// whose ends lie on opposite sides (inside = density >= isovalue; everything past dims is outside), faces
/// counter-clockwise seen from outside. Parallel over 8^3 blocks; the output does not depend on the thread
/// count. Where `blocks` is given, each block it meshed is appended to it.
TriangleMesh marching_cubes(const SparseVoxmap& voxmap, float isovalue, Progress& progress, std::vector<MarchingBlock>* blocks = nullptr);

} // namespace voxwarp::extract_internal
