/// @file bench_common.h
/// @brief Shared inputs for voxwarp-bench: the bundled meshes, loaded once.
#pragma once

#include <voxwarp/mesh_io.h>

#include <string>

namespace voxwarp::bench {

inline const TriangleMesh& bunny_mesh() {
    static const TriangleMesh mesh = read_mesh(std::string(VOXWARP_DATA_DIR) + "/bunny.obj");
    return mesh;
}

/// The snowden bust, an open scan (holes, overlapping layers): the winding-number path.
inline const TriangleMesh& scan_mesh() {
    static const TriangleMesh mesh = read_mesh(std::string(VOXWARP_DATA_DIR) + "/snowden_lo.obj");
    return mesh;
}

} // namespace voxwarp::bench
