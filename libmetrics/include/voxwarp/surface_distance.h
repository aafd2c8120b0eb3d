/// @file surface_distance.h
/// @brief How far apart two surfaces are: distances from points sampled on one mesh to the other mesh's
///        surface (CGAL AABB tree), summarised as mean / p99 / max in world units.
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace voxwarp {

struct DistanceStats {
    double mean = 0, p99 = 0, max = 0; ///< world units
    std::size_t samples = 0;
};

struct SurfaceDistanceOptions {
    std::size_t samples = 200000; ///< area-uniform random samples per direction, added to the vertices
    std::uint64_t seed = 1;       ///< the sampling is deterministic for a given seed
};

/// Distances from `from` (its vertices plus area-uniform samples) to the surface of `to`.
/// @throw InvalidInput when either mesh has no faces.
DistanceStats one_sided_distance(const TriangleMesh& from, const TriangleMesh& to, const SurfaceDistanceOptions& options = {});

/// Both directions pooled: samples of a measured against b and samples of b measured against a.
DistanceStats symmetric_distance(const TriangleMesh& a, const TriangleMesh& b, const SurfaceDistanceOptions& options = {});

} // namespace voxwarp

namespace voxwarp {

/// Distance from each world point to the surface of `mesh` (CGAL AABB tree), world units. @throw InvalidInput
/// when the mesh has no non-degenerate faces.
std::vector<double> distances_to_surface(const std::vector<Eigen::Vector3d>& points, const TriangleMesh& mesh);

/// Distance from each world point to the faces of `mesh` that come within `radius` of it (no tree: one parallel
/// pass over the faces per point, so a few points against a large mesh cost less than building a tree), world
/// units; +infinity for a point no face comes that near.
std::vector<double> distances_to_surface_within(const std::vector<Eigen::Vector3d>& points, const TriangleMesh& mesh, double radius);

/// Edges whose dihedral angle (angle between the two faces' normals) exceeds a threshold: a mesh's creases.
struct CreaseStats {
    std::int64_t creased = 0; ///< interior edges above the threshold
    std::int64_t edges = 0;   ///< interior (two-face) edges considered
    double share() const { return edges > 0 ? double(creased) / double(edges) : 0.0; }
};
CreaseStats count_creases(const TriangleMesh& mesh, double threshold_degrees = 30.0);

} // namespace voxwarp
