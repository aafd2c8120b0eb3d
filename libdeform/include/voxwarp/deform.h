/// @file deform.h
/// @brief The end-to-end deform job: voxelize a mesh, apply an edit script (each edit's constraints solved on a
///        fresh lattice over the previous result, the volume warped through it), re-polygonize; with its report.
///
/// This is what `voxwarp deform` / `voxwarp warp`, the editor's server and the Python module all run. Frames:
/// world units throughout (the input mesh's own); residuals and misses are also given in voxels of the voxmap.
#pragma once

#include <voxwarp/edit_file.h>
#include <voxwarp/extract.h>
#include <voxwarp/voxelize.h>

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace voxwarp {

struct DeformOptions {
    VoxelizeOptions voxelize;      ///< resolution / voxel size of the volume
    ExtractOptions extract;
    bool preview = false;          ///< map-and-round warp (fast, aliased)
    std::size_t target_faces = 0;  ///< > 0: decimate the extracted mesh to about this many faces (CGAL edge collapse)
    /// Move each output vertex onto the exact image of its source point on the input (snap.h), where that moves it
    /// at most half a voxel and flips no face (half a voxel toward an image up to a voxel away). Mesh input, volume
    /// mode only.
    bool snap = true;
    /// Carry the input's texture coordinates, colours, materials and groups onto the output (transfer.h; mesh
    /// input, volume mode; --mode vertex keeps them as they are).
    bool attributes = true;
    int max_steps = 8;             ///< most steps a min-norm edit may be split into to avoid folding the lattice map
    double far_fraction = 0.25;    ///< constraint points farther than this fraction of the model's size from its box are refused
    ProgressCallback progress;     ///< optional progress / cancel (every stage)
};

struct ConstraintReport {
    std::string name;              ///< its JSON path, e.g. "edits[0].constraints[2]"
    std::string kind;              ///< "move", "pin", "control_point", "turn" (a frame's), "connect" or "region"
    std::string entry;             ///< the edit file's entry when it is one of several rows: "frame", "region", "connect"
    double residual = 0;           ///< how far the lattice map misses the constraint, world units (a region: its worst point)
    double residual_voxels = 0;
    double residual_degrees = -1;  ///< turn: the angle between the map's derivative and the one asked for (< 0: not a turn)
    /// move constraints: distance from the target to the surface the edit produced (the output mesh for the last
    /// edit, the 0.5 isosurface of the edit's voxmap for earlier ones), voxels; < 0 when not measured.
    double surface_miss_voxels = -1;
    /// move constraints: distance from the moved point to the surface the edit started from, voxels (< 0: not measured).
    double source_miss_voxels = -1;
    /// move constraints of a mesh's first edit: distance from the moved point to the input mesh, voxels (< 0: not measured).
    double model_miss_voxels = -1;
    /// move constraints: no voxel within a voxel of the moved point reaches 0.5 (the feature under it, if any, is
    /// thinner than a voxel and missing from the voxmap).
    bool source_thin = false;
    std::string miss_cause;        ///< why the surface misses by more than half a voxel, where known
};

struct EditReport {
    std::string solver = "min-norm"; ///< "min-norm" or "rigid" (the edit file's choice)
    bool preserve_volume = false;
    int steps = 1;                   ///< the edit was applied in this many injective steps
    bool folds_remain = false;       ///< the applied map folds somewhere (det J <= 0)
    int folded_regions = 0;          ///< regions where it does (find_folds on the final lattice)
    bool least_squares = false;
    int rank = 0, unknowns = 0;
    int iterations = 0;              ///< nonlinear solver iterations (rigid, preserve_volume)
    double seconds_solve = 0;
    double volume_before = 0, volume_after = 0; ///< voxmap mass before and after this edit, world units^3
    /// The largest control-point motion over the largest move's (per step); 0 without moves. Far above 1 (a warning
    /// past 10) where targets close together go different ways and the map stretches space steeply between them.
    double control_motion_ratio = 0;
    std::vector<ConstraintReport> constraints;
    /// The edit's lattice (its first step's, when it was split into steps): control points per axis, and their
    /// world positions at rest and as solved, index i + nx (j + ny k). For showing the lattice; not in the JSON report.
    std::array<int, 3> lattice_size{};
    std::vector<Eigen::Vector3d> lattice_rest, lattice_solved;
};

/// A part of the model the voxmap lost: thinner than a voxel when voxelized (a flood fill keeps a part only where
/// a voxel centre lies inside it; crumbs under three voxels are dropped), or squeezed below a voxel by an edit
/// (the warp's box filter averages it under density 0.5). Found as input surface with no material near where
/// the space took it; only parts thinner than 1.5 voxels where they were lost, with two voxels^2 of area or more.
struct ThinPart {
    std::string stage;                   ///< "voxelize", or the edit that lost it: "edits[0]", ...
    Eigen::Vector3d centre = Eigen::Vector3d::Zero(); ///< world: in the input's frame for "voxelize", the edit's result's otherwise
    Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero(); ///< its lost surface's bounds, same frame
    double area_voxels = 0;              ///< lost surface area, voxels^2
    double thickness_voxels = 0;         ///< how thick it was where it was lost (median over rays through it), voxels
    double thickness_before_voxels = 0;  ///< how thick it is on the input, voxels
    double voxel_size_to_keep = 0;       ///< world units: half its thickness (two voxels across keep it)
    std::int64_t resolution_to_keep = 0; ///< --resolution giving that voxel size; 0 when above 8192
};

struct DeformReport {
    std::string mode = "volume";     ///< "volume" (re-polygonized) or "vertex" (classic FFD of the input's vertices)
    std::string sign;                ///< mesh input, volume mode: the inside/outside test used ("flood-fill", "winding-number")
    std::string sign_note;           ///< why `--sign auto` gave up the flood fill, if it did
    double voxel_size = 0;
    std::array<std::int64_t, 3> dims{};
    double volume_before = 0, volume_after = 0; ///< world units^3: enclosed by the input and output meshes (voxmap mass for voxmaps)
    std::vector<EditReport> edits;
    double seconds_voxelize = 0, seconds_solve = 0, seconds_warp = 0, seconds_extract = 0;
    double seconds_read = 0, seconds_write = 0, seconds_total = 0; ///< filled by callers that read and write files
    std::size_t output_vertices = 0, output_faces = 0;
    bool snap = false;                ///< whether output vertices were snapped onto the exact warped input
    std::size_t snapped_vertices = 0, unsnapped_vertices = 0; ///< with snap: vertices moved, and left as extracted
    std::size_t partly_snapped_vertices = 0; ///< with snap: vertices moved half a voxel toward an image up to a voxel away
    std::size_t refined_vertices = 0; ///< with snap: vertices added on edges across the input's creases, at its corners and along its creases (refine_to_sources; among the snapped)
    std::size_t put_back_vertices = 0; ///< with snap and the feature mesher: vertices put back where extraction made them, their triangles having crossed another (among the unsnapped)
    double seconds_snap = 0;          ///< finding source points and snapping (part of seconds_extract)
    bool attributes = false;          ///< whether the input's texture coordinates, colours or materials were carried (transfer.h)
    std::size_t triangles_across_charts = 0; ///< with attributes: output triangles straddling a UV seam (each kept in one chart)
    double seconds_transfer = 0;      ///< carrying attributes, source points included when snapping did not find them (part of seconds_extract)
    std::uint64_t memory_estimate_bytes = 0;   ///< deform_mesh: what deform_memory_estimate asked for before it began
    std::uint64_t resident_bytes_at_start = 0; ///< deform_mesh: this process's resident memory when it began
    std::vector<ThinPart> thin_parts; ///< what the voxmap lost (mesh input, volume mode), largest first, at most 16
};

/// Apply every edit of `script` to a voxmap (each edit on a fresh lattice over the previous result).
/// @throw InvalidInput for constraints far outside the model; see solve_constraints, warp. Cancelled.
SparseVoxmap deform_voxmap(SparseVoxmap voxmap, const EditScript& script, const DeformOptions& options, DeformReport& report);

/// Bytes deform_mesh is expected to need beyond what the process holds when it begins (the input mesh is the
/// caller's): the largest of voxelizing (voxelize_memory_estimate), warping (the voxmap's blocks in and out and
/// the warp's sums) and extracting and snapping (the output mesh with its source points and index, about 950
/// bytes per voxel of the input's area), plus the input's snapping tree, which lives through all three. Measured
/// against the peaks of the bundled bunny and scan and a 600,000-face scan at 128 to 512, with and without
/// snapping, both meshers (docs/benchmarks.md, Memory): 1.09-1.84 x the peak. The feature mesher's share depends
/// on the input's sharp edges, and deform_mesh adds it (report.memory_estimate_bytes) once it has found them.
/// deform_mesh refuses a request above `options.voxelize.max_memory_bytes` (0: 90 % of available memory).
std::uint64_t deform_memory_estimate(const TriangleMesh& mesh, const DeformOptions& options);

/// Mesh in, re-polygonized deformed mesh out. report.volume_before / after are the input's and output's enclosed
/// volumes; per move constraint, how far the output surface misses its target.
/// @throw InvalidInput (bad mesh, bad constraints, nothing left to extract), ResourceLimit (memory estimate),
///        SolverFailure, Cancelled.
TriangleMesh deform_mesh(const TriangleMesh& mesh, const EditScript& script, const DeformOptions& options, DeformReport& report);

/// The classic free-form deformation of the same solved lattices applied to the mesh's vertices (the creased
/// baseline the papers argue against), for comparison.
TriangleMesh deform_vertices(const TriangleMesh& mesh, const EditScript& script, const DeformOptions& options, DeformReport& report);

/// Warnings a user should see about a finished run, one line each (no "warning:" prefix): a flood fill given up for
/// winding numbers, constraints that miss their targets by more than half a voxel (with the cause where known), maps
/// that still fold, thin parts lost.
std::vector<std::string> deform_warnings(const DeformReport& report);

/// Volume after against before, in percent; none where there is no volume before to compare with (an input whose
/// parts, wound inside out, cancel its own volume).
std::optional<double> volume_change_percent(double before, double after);

/// The report as the JSON text `voxwarp deform --report` writes (schema in README.md, "Reports"). `fields` are
/// added at the top level as strings (the CLI adds "input", "edits_file", "output").
std::string report_json(const DeformReport& report, const std::map<std::string, std::string>& fields = {});

} // namespace voxwarp
