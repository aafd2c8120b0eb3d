/// @file decimate.h
/// @brief Reduce a closed triangle mesh to about a target face count by edge collapse (CGAL's
///        Surface_mesh_simplification, Lindstrom-Turk cost and placement).
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <cstddef>

namespace voxwarp {

/// Collapse edges until the mesh has at most about `target_faces` faces (world units unchanged). Quads are
/// split into triangles first. A mesh already at or below the target is returned as it is. Collapses keep the
/// mesh's topology (CGAL refuses collapses that would make it non-manifold), so a closed 2-manifold stays one.
/// \pre the mesh is a 2-manifold (as extract() produces)
/// @throw InvalidInput for a target below 4 faces or a mesh CGAL cannot load as a 2-manifold.
TriangleMesh decimate(const TriangleMesh& mesh, std::size_t target_faces);

} // namespace voxwarp
