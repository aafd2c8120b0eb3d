// Checks run on a mesh file before OpenMesh reads it, because OpenMesh's readers crash, assert, hang or allocate
// without bound on malformed input (every case below was found by fuzzing; see tests/fuzz). Each throws
// InvalidInput naming the file and what is wrong.
#pragma once

#include <cstdint>
#include <string>

namespace voxwarp::mesh_io_internal {

/// Dispatch on the (lower-case) extension `ext`; formats without known reader problems pass through.
void validate_before_openmesh(const std::string& path, const std::string& ext, std::uintmax_t file_size);

void validate_obj(const std::string& path);
void validate_off(const std::string& path, const std::string& head, std::uintmax_t file_size);
void validate_ply(const std::string& path, std::uintmax_t file_size);
void validate_stl(const std::string& path, const std::string& head, std::uintmax_t file_size);

} // namespace voxwarp::mesh_io_internal
