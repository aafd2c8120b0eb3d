/// @file extract.h
/// @brief Voxmap -> indexed, shared-vertex, watertight polygon mesh of its 0.5 isosurface.
///
/// Mesher::features is marching cubes with sharp features put back (after Kobbelt et al.'s
/// Extended Marching Cubes, 2001): in a cell whose crossings' normals disagree by more than `feature_angle`, the
/// cell's polygon becomes a fan around the point its tangent planes meet at (an edge or a corner), and edges
/// between such points in neighbouring cells are flipped to join them, so edges and corners come out straight
/// and sharp; with `feature_surface`, mesh edges still cut across one of its sharp edges are split on it. Near
/// `feature_surface` (the input's surface around its sharp edges, e.g. sharp_feature_surface of the
/// mesh voxelized, carried through a warp) the crossings and their normals are where each grid edge meets it;
/// elsewhere the normals come from the density's gradient. Given `feature_surface`, sharp parts are looked for only
/// near it (a smooth warp makes none the input lacks; in a deform this costs about 1.0-1.4 x marching cubes at 256);
/// without it, everywhere. A last pass flips the edge of a triangle folded against its corners' normals where
/// that unfolds it (most, not all). Away from sharp parts the output is marching cubes'.
///
/// Triangles come from marching cubes: one vertex on each grid edge whose ends lie on opposite sides, at the
/// linear zero of the two densities, so the crossings voxelize fits are met exactly. An ambiguous grid face
/// (inside corners on one diagonal only) joins its outside corners; voxelize makes every such face with a wall
/// between its outside corners unambiguous, so walls thinner than a voxel hold. Everything past the voxmap's
/// border counts as outside, so the result is a closed 2-manifold. With `adaptivity` > 0 or `quads` the mesh
/// comes from OpenVDB's VolumeToMesh instead (dual contouring: one vertex per cell, the average of its edge
/// crossings), for its quads and merged flat areas. Output positions are world units in the voxmap's frame;
/// faces are counter-clockwise seen from outside (outside = density below the isovalue).
#pragma once

#include <voxwarp/progress.h>
#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/surface_samples.h>
#include <voxwarp/triangle_mesh.h>
#include <voxwarp/voxmap.h>

#include <string>
#include <vector>

namespace voxwarp {

enum class Mesher {
    marching_cubes, ///< vertices on grid edges at the linear zero of the densities: smooth shapes, chamfered edges; the default
    features,       ///< marching cubes with sharp edges and corners restored (see above)
};

/// The mesher named as the command line and the Python module name it: "mc" or "features" (any case).
/// @throw InvalidInput for any other name.
Mesher parse_mesher(const std::string& name);

struct ExtractOptions {
    Mesher mesher = Mesher::marching_cubes;
    double feature_angle = 35;           ///< degrees: crossings' normals further apart than this mark a sharp part
    const FeatureSurface* feature_surface = nullptr; ///< optional Hermite data for the feature mesher (world units)
    double isovalue = 0.5;   ///< density of the surface, (0, 1)
    double adaptivity = 0.0; ///< OpenVDB's adaptivity [0, 1]: 0 = uniform faces, higher merges flat areas (VolumeToMesh)
    bool quads = false;      ///< OpenVDB's quads instead of triangles (VolumeToMesh)
    ProgressCallback progress; ///< optional progress / cancel
};

/// Extract the isosurface. Parallel (oneTBB); the output does not depend on the thread count.
/// @throw InvalidInput for an isovalue outside (0, 1) or adaptivity outside [0, 1]; Cancelled.
TriangleMesh extract(const Voxmap& voxmap, const ExtractOptions& options = {});
/// The same from a block-sparse voxmap: its blocks become the grid's leaves and tiles directly.
TriangleMesh extract(const SparseVoxmap& voxmap, const ExtractOptions& options = {});

/// The vertices of `mesh`, extracted from `voxmap`, that lie off the voxmap's grid edges (world units, in vertex
/// order). Marching cubes puts every vertex on one: these are those the feature mesher made (fans' centres, splits)
/// or moved onto the input's surface, where its sharp parts are.
std::vector<Eigen::Vector3d> off_grid_vertices(const TriangleMesh& mesh, const SparseVoxmap& voxmap);

} // namespace voxwarp
