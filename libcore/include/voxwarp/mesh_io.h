/// @file mesh_io.h
/// @brief Mesh files in and out (OBJ, OFF, PLY, STL, OM), with their attributes where the format holds them:
///        OBJ texture coordinates (vt), materials (usemtl, mtllib and the .mtl's textures) and vertex colours
///        ("v x y z r g b"); PLY vertex colours and texture coordinates.
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <string>
#include <vector>

namespace voxwarp {

/// Read a mesh file as a plain polygon list (polygons fan-triangulated), keeping every face even at
/// non-manifold edges and vertices (OpenMesh's halfedge mesh would drop those), but once: a triangle with the
/// corners of an earlier one (in any order) is dropped, with a warning.
/// Positions are world units as stored in the file. glTF and PLY, which split a vertex wherever its texture
/// coordinates or normals differ, have such vertices (exactly one position) joined again, each face corner keeping
/// its own; a PLY without either is read as it is.
/// @throw IOError when the file cannot be opened; InvalidInput when it is empty, unparsable, has
///        non-finite coordinates, or faces that index outside the vertex list.
/// Problems that do not stop the reading (an OBJ's missing .mtl or texture, repeated faces) are appended to
/// `warnings` when given.
TriangleMesh read_mesh(const std::string& path, std::vector<std::string>* warnings = nullptr);

/// Write a mesh (format by extension: .obj .off .ply .stl .om). Written to a temporary file beside
/// `path` and renamed into place, so a failure never leaves a half-written or clobbered file.
/// .ply and .stl are binary (little-endian, float32 positions); .obj and .off are text with the shortest digits
/// that read back as the same double; .om goes through OpenMesh.
/// An OBJ with materials gets its material library beside it (same name, .mtl; written first, also atomically),
/// texture paths rewritten relative to the output's folder.
/// @throw InvalidInput for an unknown extension; IOError when writing fails.
void write_mesh(const TriangleMesh& mesh, const std::string& path);

/// An OBJ material library's materials (newmtl, Kd, map_Kd; the rest kept as text), texture paths made usable from
/// the current directory. Missing textures are appended to `warnings` when given.
/// @throw IOError when the file cannot be read; InvalidInput for a malformed statement.
std::vector<Material> read_material_library(const std::string& path, std::vector<std::string>* warnings = nullptr);
/// The text of a .mtl holding `materials`, to be written in `folder`: texture paths relative to it where they can be.
std::string encode_material_library(const std::vector<Material>& materials, const std::string& folder);

/// The bytes write_mesh writes for a .ply file of a mesh without attributes (attributes are left out): binary
/// little-endian PLY, float32 x y z per vertex, each face a uchar corner count and int32 indices. What the editor's server answers with (Content-Type application/ply).
std::string encode_ply(const TriangleMesh& mesh);

/// The bytes of a .ply, .stl, .obj or .off file of the mesh, attributes included where the format holds them; an
/// OBJ with materials names `material_library` in its mtllib line. @throw InvalidInput for another extension.
std::string encode_mesh(const TriangleMesh& mesh, const std::string& extension, const std::string& material_library = "");
/// The same bytes as consecutive pieces (encoded in parallel), for writing without joining them first.
std::vector<std::string> encode_mesh_chunks(const TriangleMesh& mesh, const std::string& extension, const std::string& material_library = "");

/// True when the extension names a mesh format write_mesh/read_mesh understand.
bool is_mesh_path(const std::string& path);

} // namespace voxwarp
