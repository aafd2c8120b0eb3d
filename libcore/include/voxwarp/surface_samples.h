/// @file surface_samples.h
/// @brief The input's surface where it is sharp: the Hermite data (exact crossings with their normals, and the
///        sharp edges themselves) that lets the feature mesher (extract.h) put sharp edges and corners back. Made
///        by sharp_feature_surface (voxelize.h), carried through a warp by push_feature_surface (warp.h).
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <utility>
#include <vector>

namespace voxwarp {

/// World units. `faces`: the surface near its sharp edges as triangles at most about a voxel across (a warp that
/// carries their vertices bends them with the space), counter-clockwise seen from outside. `edges`: the sharp
/// edges as segments at most half a voxel long.
struct FeatureSurface {
    TriangleMesh faces;
    std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> edges;
    bool empty() const { return faces.triangles.empty() && edges.empty(); }
};

} // namespace voxwarp
