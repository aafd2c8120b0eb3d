/// @file pipeline.h
/// @brief The end-to-end jobs behind `voxwarp deform` and `voxwarp warp`: voxelize, solve each edit's
///        constraints on a fresh lattice, warp (split into steps while the map would fold), extract.
#pragma once

#include <voxwarp/edit_file.h>
#include <voxwarp/extract.h>
#include <voxwarp/voxelize.h>

#include <string>
#include <vector>

namespace voxwarp {

struct DeformOptions {
    VoxelizeOptions voxelize;      ///< resolution / voxel size of the volume
    ExtractOptions extract;
    bool preview = false;          ///< map-and-round warp (fast, aliased)
    std::size_t target_faces = 0;  ///< > 0: decimate the extracted mesh to about this many faces (CGAL edge collapse)
    int max_steps = 8;             ///< most steps one edit may be split into to avoid folding the lattice map
    double far_fraction = 0.25;    ///< constraint points farther than this fraction of the model's size from its box are refused
    ProgressCallback progress;
};

struct ConstraintReport {
    std::string name;
    std::string kind;
    double residual = 0;         ///< world units
    double residual_voxels = 0;
};

struct EditReport {
    int steps = 1;               ///< the edit was applied in this many injective steps
    bool folds_remain = false;   ///< even max_steps steps fold the map somewhere
    bool least_squares = false;
    int rank = 0, unknowns = 0;
    std::vector<ConstraintReport> constraints;
};

struct DeformReport {
    double voxel_size = 0;
    std::array<std::int64_t, 3> dims{};
    double volume_before = 0, volume_after = 0; ///< world units^3 (voxmap mass; for meshes the output mesh's)
    std::vector<EditReport> edits;
    double seconds_voxelize = 0, seconds_solve = 0, seconds_warp = 0, seconds_extract = 0;
};

/// Apply every edit of `script` to a voxmap (each edit on a fresh lattice over the previous result).
/// @throw InvalidInput for constraints far outside the model; see solve_constraints, warp.
SparseVoxmap deform_voxmap(SparseVoxmap voxmap, const EditScript& script, const DeformOptions& options, DeformReport& report);

/// Mesh in, re-polygonized deformed mesh out.
TriangleMesh deform_mesh(const TriangleMesh& mesh, const EditScript& script, const DeformOptions& options, DeformReport& report);

/// The classic free-form deformation of the same solved lattices applied to the mesh's vertices (the creased
/// baseline the papers argue against), for comparison.
TriangleMesh deform_vertices(const TriangleMesh& mesh, const EditScript& script, const DeformOptions& options, DeformReport& report);

} // namespace voxwarp
