// libFuzzer target: every mesh reader (OBJ, OFF, PLY, STL, .om) on arbitrary bytes must either return a mesh or
// throw voxwarp::Error; never crash, hang or exhaust memory. The first byte picks the format (mesh_fuzz_extension).
#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include "mesh_fuzz_extension.h"

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size < 1) return 0;
    const std::string path = "/tmp/voxwarp_fuzz_" + std::to_string(::getpid()) + mesh_fuzz_extension(data[0]);
    if (std::FILE* f = std::fopen(path.c_str(), "wb")) {
        std::fwrite(data + 1, 1, size - 1, f);
        std::fclose(f);
    }
    try {
        const voxwarp::TriangleMesh mesh = voxwarp::read_mesh(path);
        for (const auto& t : mesh.triangles)
            for (auto i : t)
                if (i < 0 || std::size_t(i) >= mesh.vertices.size()) __builtin_trap(); // a reader let a bad index through
    } catch (const voxwarp::Error&) {
    }
    std::remove(path.c_str());
    return 0;
}
