/// @file snap.h
/// @brief Where each vertex of a re-polygonized mesh came from: its source point on the input surface, found by
///        carrying the vertex back through the warps (pullback) and taking the nearest input point whose normal
///        agrees; snapping the vertex onto the exact image of that point (pushforward); and refining, splitting
///        edges that cut under a crease of the input on it.
///
/// Frames: world units throughout. The input lives in the frame before the first warp, the output in the frame after
/// the last; a WarpStep is one warp's map, from its rest lattice's world to its moved lattice's world.
#pragma once

#include <voxwarp/lattice.h>
#include <voxwarp/triangle_mesh.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

namespace voxwarp {

/// One warp: a point p of the rest frame goes to moved.evaluate(rest.parameter_of(p)).
struct WarpStep {
    Lattice rest, moved;
};

/// The exact image of an input-frame point through every step, in order.
Eigen::Vector3d push_forward(const std::vector<WarpStep>& steps, Eigen::Vector3d point);

/// A surface normal at an input-frame point, carried through every step as a normal goes (the inverse transpose of
/// the map's Jacobian there), unit length; a zero normal stays zero.
Eigen::Vector3d push_normal(const std::vector<WarpStep>& steps, Eigen::Vector3d point, Eigen::Vector3d normal);

/// The input-frame point whose image is `point` (Newton's method per step, last step first), and the Jacobian of
/// the whole map there (d output / d input). Empty where Newton does not converge (the map folds or the point lies
/// beyond the lattice's reach).
std::optional<Eigen::Vector3d> pull_back(const std::vector<WarpStep>& steps, Eigen::Vector3d point, Eigen::Matrix3d* jacobian = nullptr);

/// A point on the input surface: a triangle of all_triangles(input) and barycentric weights of its corners.
struct SourcePoint {
    std::int32_t face = -1; ///< -1: no source found
    Eigen::Vector3d barycentric = Eigen::Vector3d::Zero();
};

struct SnapOptions {
    double voxel_size = 0;       ///< the voxmap's h, world units (> 0)
    double max_move_voxels = 0.5; ///< a vertex whose exact image lies farther than this stays where it is
    double reach_voxels = 2;     ///< sources are looked for this far (input frame) from the pulled-back vertex
    /// Points of the input surface (input frame) the output must pass through: snap_to_sources puts the output
    /// vertex nearest each one's image (within anchor_reach_voxels) on it, the vertices of its sheet around it
    /// following part of the way, unless a face would flip. A move's point, whose target the user asked for, on a
    /// tip or thin edge the voxmap rounds off.
    std::vector<Eigen::Vector3d> anchors;
    double anchor_reach_voxels = 1.5;
};

/// The input surface indexed for nearest-point queries (a CGAL AABB tree over its triangles): build it once and
/// query it for every output of the same input (the editor's session does). `input` must outlive it.
class SourceSurface {
public:
    /// @throw InvalidInput when the mesh has no face with area.
    explicit SourceSurface(const TriangleMesh& input);
    ~SourceSurface();
    SourceSurface(const SourceSurface&) = delete;
    SourceSurface& operator=(const SourceSurface&) = delete;
    const TriangleMesh& mesh() const;
    /// The point of the input surface nearest to `point` (input frame) within `reach`, on a face whose normal has a
    /// positive dot product with `normal` (any face when `normal` is zero); face -1 when there is none.
    SourcePoint nearest(const Eigen::Vector3d& point, const Eigen::Vector3d& normal, double reach) const;
    struct Impl;
    const Impl& impl() const { return *impl_; }

private:
    std::unique_ptr<Impl> impl_;
};

/// For each vertex of `output` (the surface after `steps`), its source point on `input`: the nearest point of the
/// input surface to the pulled-back vertex among faces whose normal, pushed forward, agrees with the vertex's
/// normal on the output (so that a sheet across a gap thinner than the reach is not chosen), within reach.
/// Parallel (oneTBB); the answer does not depend on the thread count. @throw InvalidInput when voxel_size is not
/// positive.
std::vector<SourcePoint> find_sources(const TriangleMesh& output, const SourceSurface& input, const std::vector<WarpStep>& steps,
                                      const SnapOptions& options);
/// The same, indexing `input` for this one call.
std::vector<SourcePoint> find_sources(const TriangleMesh& output, const TriangleMesh& input, const std::vector<WarpStep>& steps,
                                      const SnapOptions& options);

struct SnapReport {
    std::size_t snapped = 0;   ///< vertices moved onto the exact image of their source point (or of an anchor; with snap_and_refine, the refined too)
    std::size_t partly_snapped = 0; ///< vertices moved max_move_voxels toward an exact image up to twice that far
    std::size_t unsnapped = 0; ///< vertices left where extraction put them (no source, too far, or a face would flip)
    std::size_t refined = 0;   ///< snap_and_refine: vertices added on edges across the input's creases, and at its corners and along its creases (among the snapped)
    std::size_t put_back = 0;  ///< snap_and_refine with RefineOptions::put_back_crossings: vertices put back where extraction made them (among the unsnapped)
};

/// Move each output vertex to the exact image of its source point, unless it has none, that moves it more than
/// max_move_voxels (up to twice that: max_move_voxels toward it, partly_snapped), or a face around it would flip
/// (turn by more than 90 degrees or collapse), or a face it turns more than 45 degrees from a corner's normal would
/// cross one within two rings of it; and the vertex
/// nearest each anchor's image onto it (SnapOptions::anchors). The mesh's connectivity is kept. Parallel (oneTBB).
SnapReport snap_to_sources(TriangleMesh& output, const TriangleMesh& input, const std::vector<WarpStep>& steps, const std::vector<SourcePoint>& sources,
                           const SnapOptions& options);

struct RefineOptions {
    double chord_voxels = 0.05; ///< an edge whose middle lies farther than this from the exact surface is split
    int rounds = 1;             ///< passes, each splitting the edges the last one made or left (0: none, and no corners or crease points put in)
    /// Also test each split triangle whose pieces turn more than 45 degrees from a corner's extracted normal for
    /// crossings, as a rim's: the feature mesher's sharp edges and slivers need it (its bunny ear edit at 128: 10
    /// pairs crossing -> 5, its bar bend 6 -> 0); marching cubes' output showed none, and at 256 it costs ~30 ms.
    bool steep_crossings = false;
    /// snap_and_refine: then look for triangles crossing another over the whole output, and put the corner that moved
    /// farthest of each crossing pair back where extraction made it (a refined vertex on the triangle it split),
    /// until none crosses. The feature mesher's output needs it (bunny ear edit at 128: 5 pairs crossing -> 0, 12
    /// vertices put back; the snowden scan 69 -> 0, 199); at 256 the search costs about 120 ms.
    bool put_back_crossings = false;
    /// Where crossings may start (world units), for put_back_crossings: given any, only the triangles with a corner
    /// within 3 voxels of one (where extraction made it) are searched. The feature mesher's pairs all lay within
    /// 0.8 voxel of a vertex it made off the grid's edges (a fan's centre, a split, a crossing moved onto the input's
    /// surface): 7 bundled edits at 64, 128 and 256, 1,600 pairs. The bunny ear's search then takes 35-42 ms at
    /// 256 against 126-128 over the whole output, and 74-86 ms at 512 against 487-506. Empty: the whole output.
    std::vector<Eigen::Vector3d> crossings_near;
};

/// Where an output edge runs across a crease or bump of the input (its two ends' sources on faces that meet at an
/// angle), its straight middle misses the exact warped surface: split it, the new vertex on the exact image of a
/// source point (where the two faces share an edge, the point of that edge nearest the output edge, so the pieces
/// lie on the faces; otherwise the source of the ends' sources' middle) when the middle misses that by more than
/// chord_voxels, unless that is more than max_move_voxels or a piece would fold. Triangles split 1 to 2, 3 or 4 by
/// their split edges, so the mesh stays closed and its topology is kept. In thin parts (another sheet within 1.5
/// voxels), and where an edge misses its crease point by more than max_move_voxels (a sharp ridge the voxmap rounds
/// off; that point then goes in up to 1.5 voxels away), the pieces are judged by the exact normals (turning up to
/// 120 degrees from the triangle they replace) and given up where they would cross the output.
/// Then where the input's corners and creases lie (vertices whose faces' normals spread by over 10 degrees, and
/// points half a voxel apart along edges whose faces meet at over 10 degrees, on faces at least half a voxel
/// long), the output's triangles still cut under them: each such point whose exact image lies more than
/// chord_voxels and at most 1.5 voxels from the output goes in, splitting the nearest triangle into three (or its
/// nearest side, both triangles into two), unless a piece would turn over, fold back onto a neighbour, or cross
/// the output (thin parts included: a rim's tip may go in). Last, two vertices on the exact surface that follow
/// each other along a crease (their sources on it) but are not joined, where the middle between them lies more
/// than chord_voxels off the triangles around them, are joined by flipping the edges between them, unless a
/// triangle would turn over, fold or cross the output: the output's edges then run along the creases (the bent
/// and twisted box's edges: p99 0.041-0.059 voxel off the exact warp, 0.067-0.168 before). Then two triangles whose
/// normals turn from the exact normals at their corners (the normals of the faces at each corner's source, as the
/// maps carry them) trade their shared side for the other diagonal where that turns them less, both face along the
/// exact normals and neither crosses the output: a triangle from one face of a sharp crease to the other stops
/// cutting under it, and a triangle folded flat onto its neighbours unfolds (the box's edges: p99 0.004-0.027).
/// `sources` grows with the vertices. A mesh with quads is left as it is. Parallel (oneTBB); the answer does not depend on the thread
/// count. Returns the number of vertices added.
std::size_t refine_to_sources(TriangleMesh& output, std::vector<SourcePoint>& sources, const SourceSurface& input, const std::vector<WarpStep>& steps,
                              const SnapOptions& options, const RefineOptions& refine = {});

/// snap_to_sources, then refine_to_sources with what snapping found out about the output's sheets (the deform's
/// path: refinement then costs its splits alone). Empty `sources` are found first (find_sources), the output's
/// vertex normals worked out once for both. Before the last flips, the vertices snapping left where they were try
/// again, one at a time, against the refined output (where a face's corners all had their sources on one crease,
/// moving them together collapsed it); with a flip around one, up to three times. The report counts those moved
/// among the snapped.
SnapReport snap_and_refine(TriangleMesh& output, const SourceSurface& input, const std::vector<WarpStep>& steps, std::vector<SourcePoint>& sources,
                           const SnapOptions& options, const RefineOptions& refine = {});

} // namespace voxwarp
