#include "cli_common.h"

#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>
#include <voxwarp/vdb_io.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>

namespace voxwarp::cli {

namespace {

void print_mesh_info(const std::string& path) {
    const TriangleMesh mesh = read_mesh_warning(path);
    const MeshTopology t = topology(mesh);
    const Bounds b = bounds(mesh);
    std::printf("file: %s\nkind: mesh\nvertices: %zu (%lld referenced)\ntriangles: %zu\nedges: %lld\n", path.c_str(), mesh.vertices.size(),
                (long long)t.vertices, mesh.triangles.size(), (long long)t.edges);
    std::printf("bbox min: %.9g %.9g %.9g\nbbox max: %.9g %.9g %.9g\n", b.min.x(), b.min.y(), b.min.z(), b.max.x(), b.max.y(), b.max.z());
    std::printf("closed: %s (%lld boundary edges)\nmanifold: %s (%lld non-manifold edges, %lld non-manifold vertices)\n",
                t.closed() ? "yes" : "no", (long long)t.boundary_edges, t.manifold() ? "yes" : "no", (long long)t.nonmanifold_edges,
                (long long)t.nonmanifold_vertices);
    std::printf("oriented: %s (%lld misoriented edges)\ndegenerate faces: %lld\ncomponents: %lld\neuler characteristic: %lld\n",
                t.oriented() ? "yes" : "no", (long long)t.misoriented_edges, (long long)t.degenerate_faces, (long long)t.components,
                (long long)t.euler);
    if (t.watertight()) std::printf("enclosed volume: %.9g\n", enclosed_volume(mesh));
    // What a remesh or deform will carry: a file whose texture coordinates or normals were not recognised shows here.
    const std::string carried = attributes_of(mesh, true);
    std::printf("attributes: %s\n", carried.empty() ? "none" : carried.c_str());
}

void print_vdb_info(const std::string& path) {
    const Voxmap v = read_vdb(path);
    const auto [lo, hi] = std::minmax_element(v.density.begin(), v.density.end());
    std::printf("file: %s\nkind: voxmap\ndims: %lld %lld %lld\nvoxel size: %.9g\norigin: %.9g %.9g %.9g\n", path.c_str(), (long long)v.dims[0],
                (long long)v.dims[1], (long long)v.dims[2], v.voxel_size, v.origin.x(), v.origin.y(), v.origin.z());
    std::printf("density range: %.6g %.6g\nenclosed volume: %.9g\n", double(*lo), double(*hi), enclosed_volume(v));
}

} // namespace

void add_info(CLI::App& app, Global&, Action& action) {
    auto path = std::make_shared<std::string>();
    auto* cmd = app.add_subcommand("info", "Describe a mesh (counts, bounds, closed/manifold, Euler) or a .vdb voxmap (dims, voxel size, range)");
    cmd->add_option("file", *path, "Mesh or .vdb file")->required();
    cmd->callback([path, &action] {
        action = [path] {
            std::string ext = std::filesystem::path(*path).extension().string();
            std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
            if (ext == ".vdb")
                print_vdb_info(*path);
            else
                print_mesh_info(*path);
        };
    });
}

} // namespace voxwarp::cli
