/// @file mesh_io.h
/// @brief Mesh files in and out through OpenMesh's readers and writers (OBJ, OFF, PLY, STL, OM).
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <string>
#include <vector>

namespace voxwarp {

/// Read a mesh file as a plain polygon list (polygons fan-triangulated), keeping every face even at
/// non-manifold edges and vertices (OpenMesh's halfedge mesh would drop those).
/// Positions are world units as stored in the file.
/// @throw IOError when the file cannot be opened; InvalidInput when it is empty, unparsable, has
///        non-finite coordinates, or faces that index outside the vertex list.
TriangleMesh read_mesh(const std::string& path);

/// Write a mesh (format by extension: .obj .off .ply .stl .om). Written to a temporary file beside
/// `path` and renamed into place, so a failure never leaves a half-written or clobbered file.
/// .ply and .stl are binary (little-endian, float32 positions); .obj and .off are text with the shortest digits
/// that read back as the same double; .om goes through OpenMesh.
/// @throw InvalidInput for an unknown extension; IOError when writing fails.
void write_mesh(const TriangleMesh& mesh, const std::string& path);

/// The bytes write_mesh writes for a .ply file: binary little-endian PLY, float32 x y z per vertex, each face a
/// uchar corner count and int32 indices. What the editor's server answers with (Content-Type application/ply).
std::string encode_ply(const TriangleMesh& mesh);

/// The bytes of a .ply, .stl, .obj or .off file of the mesh. @throw InvalidInput for another extension.
std::string encode_mesh(const TriangleMesh& mesh, const std::string& extension);
/// The same bytes as consecutive pieces (encoded in parallel), for writing without joining them first.
std::vector<std::string> encode_mesh_chunks(const TriangleMesh& mesh, const std::string& extension);

/// True when the extension names a mesh format write_mesh/read_mesh understand.
bool is_mesh_path(const std::string& path);

} // namespace voxwarp
