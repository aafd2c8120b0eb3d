/// @file openvdb_baseline.h
/// @brief OpenVDB's own mesh -> level set -> mesh round trip, the baseline voxwarp's figures are compared with.
#pragma once

#include <voxwarp/triangle_mesh.h>

namespace voxwarp {

/// meshToLevelSet (half width 3 voxels) then volumeToMesh at 0, voxel size = longest bounding-box side /
/// resolution, quads split into triangles. World units in and out.
TriangleMesh openvdb_round_trip(const TriangleMesh& mesh, int resolution);

} // namespace voxwarp
