// glTF 2.0 files (gltf_io.cpp, through tinygltf), behind read_mesh and write_mesh.
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <string>
#include <vector>

namespace voxwarp::mesh_io_internal {

/// A .gltf (binary = false) or .glb file's default scene as one mesh, vertices welded by position. @throw InvalidInput.
TriangleMesh read_gltf(const std::string& path, bool binary, std::vector<std::string>& warnings);

/// Write a .gltf (one file, its buffer a data URI, textures beside it) or a .glb (textures embedded), atomically.
/// @throw InvalidInput for quads; IOError when writing fails or a texture to embed cannot be read.
void write_gltf(const TriangleMesh& mesh, const std::string& path, bool binary);

} // namespace voxwarp::mesh_io_internal
