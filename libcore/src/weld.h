// Vertices at one position, joined: for the readers of formats that split a vertex wherever its attributes
// differ (glTF, PLY).
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <Eigen/Core>

#include <cstdint>
#include <cstring>

namespace voxwarp::mesh_io_internal {

/// Hashes a position by its exact bits (FNV-1a): equal coordinates, equal keys.
struct PositionHash {
    std::size_t operator()(const Eigen::Vector3d& p) const {
        std::uint64_t h = 1469598103934665603ull, u;
        for (int a = 0; a < 3; ++a) std::memcpy(&u, &p[a], 8), h = (h ^ u) * 1099511628211ull;
        return std::size_t(h);
    }
};

/// Joins vertices at exactly one position into the first of them (its colour kept); the faces' corners keep their
/// own texture coordinates and normals.
void weld_by_position(TriangleMesh& mesh);

} // namespace voxwarp::mesh_io_internal
