// Checks run on a mesh file before OpenMesh reads it, because OpenMesh's readers crash, assert, hang or allocate
// without bound on malformed input (every case below was found by fuzzing; see tests/fuzz). Each throws
// InvalidInput naming the file and what is wrong.
#pragma once

#include <cstdint>
#include <string>

#include <voxwarp/triangle_mesh.h>

namespace voxwarp::mesh_io_internal {

/// The first 64 KiB of a file: enough for any header.
std::string read_head(const std::string& path, std::uintmax_t file_size);

/// Read a .obj, binary .stl or plain ASCII OFF file in one validating pass of voxwarp's own (mesh_read.cpp);
/// false for the formats and variants left to OpenMesh. @throw InvalidInput naming the file and what is wrong.
bool read_mesh_directly(const std::string& path, const std::string& ext, std::uintmax_t file_size, TriangleMesh& mesh);

/// Dispatch on the (lower-case) extension `ext`; formats without known reader problems pass through.
void validate_before_openmesh(const std::string& path, const std::string& ext, std::uintmax_t file_size);

void validate_obj(const std::string& path);
/// `body`: also check every vertex and face line (OpenMesh reads on regardless); false checks the header alone.
void validate_off(const std::string& path, const std::string& head, std::uintmax_t file_size, bool body = true);
void validate_ply(const std::string& path, std::uintmax_t file_size);
void validate_stl(const std::string& path, const std::string& head, std::uintmax_t file_size);

} // namespace voxwarp::mesh_io_internal
