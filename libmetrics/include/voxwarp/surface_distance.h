/// @file surface_distance.h
/// @brief How far apart two surfaces are: distances from points sampled on one mesh to the other mesh's
///        surface (CGAL AABB tree), summarised as mean / p99 / max in world units.
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <cstddef>
#include <cstdint>

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
