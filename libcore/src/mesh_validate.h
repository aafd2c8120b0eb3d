// Checks run on a mesh file before OpenMesh reads it, because OpenMesh's readers crash, assert, hang or allocate
// without bound on malformed input (every case below was found by fuzzing; see tests/fuzz). Each throws
// InvalidInput naming the file and what is wrong.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <voxwarp/triangle_mesh.h>

namespace voxwarp::mesh_io_internal {

/// The first 64 KiB of a file: enough for any header.
std::string read_head(const std::string& path, std::uintmax_t file_size);

/// Read a .obj, binary .stl or plain ASCII OFF file in one validating pass of voxwarp's own (mesh_read.cpp);
/// false for the formats and variants left to OpenMesh. @throw InvalidInput naming the file and what is wrong.
/// Problems that do not stop the reading (a missing material library or texture) go to `warnings`.
bool read_mesh_directly(const std::string& path, const std::string& ext, std::uintmax_t file_size, TriangleMesh& mesh, std::vector<std::string>& warnings);

/// OpenMesh's binary .om (om_read.cpp): positions, faces (polygons fanned into triangles), vertex colours, vertex
/// normals, and texture coordinates per vertex or per face corner (halfedge). Other chunks are checked and skipped.
/// @throw InvalidInput naming the file, what is wrong and the byte where it was found.
TriangleMesh read_om(const std::string& path, std::string_view bytes);

/// Per-vertex texture coordinates and normals for formats that keep them per vertex (PLY, glTF): a vertex whose
/// corners name different ones (a seam, a hard edge) is written once per (texture coordinate, normal) pair.
/// `vertex_of[i]`: the mesh vertex that written vertex i copies; `uv_of[i]`, `normal_of[i]`: its texture
/// coordinate and normal (-1: none); `triangles` index written vertices. A mesh without either comes back as it is.
struct SeamSplit {
    std::vector<std::int32_t> vertex_of, uv_of, normal_of;
    std::vector<std::array<std::int32_t, 3>> triangles;
};
SeamSplit split_at_seams(const TriangleMesh& mesh);

/// `file` (a path usable from the current directory) as seen from `folder`: relative when it can be, else absolute.
/// How texture paths are written into a material library or a .gltf beside an output.
std::string path_from_folder(const std::string& file, const std::string& folder);

/// Fill `materials` (named by an OBJ's usemtl) from the OBJ's material libraries (mtllib names, relative to the OBJ's
/// folder). A library or texture that cannot be found, or a material no library defines, is a warning.
void fill_materials(const std::string& obj_path, const std::vector<std::string>& libraries, std::vector<Material>& materials, std::vector<std::string>& warnings);

/// Dispatch on the (lower-case) extension `ext`; formats without known reader problems pass through.
void validate_before_openmesh(const std::string& path, const std::string& ext, std::uintmax_t file_size);

void validate_obj(const std::string& path);
/// `body`: also check every vertex and face line (OpenMesh reads on regardless); false checks the header alone.
void validate_off(const std::string& path, const std::string& head, std::uintmax_t file_size, bool body = true);
void validate_ply(const std::string& path, std::uintmax_t file_size);
void validate_stl(const std::string& path, const std::string& head, std::uintmax_t file_size);

} // namespace voxwarp::mesh_io_internal
