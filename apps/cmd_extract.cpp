#include "cli_common.h"

#include <voxwarp/errors.h>
#include <voxwarp/extract.h>
#include <voxwarp/mesh_io.h>
#include <voxwarp/vdb_io.h>

#include <memory>

namespace voxwarp::cli {

void add_extract(CLI::App& app, Global& global, Action& action) {
    struct Args {
        std::string input, output, grid;
        ExtractOptions options;
    };
    auto args = std::make_shared<Args>();
    auto* cmd = app.add_subcommand("extract", "Voxmap (.vdb) -> watertight mesh of its 0.5 isosurface");
    cmd->add_option("input", args->input, "Input .vdb (first float grid, or --grid)")->required();
    cmd->add_option("-o,--output", args->output, "Output mesh (.obj .off .ply .stl .om .gltf .glb)")->required();
    cmd->add_option("--grid", args->grid, "Name of the float grid to read");
    cmd->add_option("--isovalue", args->options.isovalue, "Density of the surface")->capture_default_str();
    add_mesher_option(cmd, args->options.mesher);
    cmd->add_option("--adaptivity", args->options.adaptivity, "OpenVDB adaptivity in [0, 1]: merge faces in flat areas (meshes with OpenVDB's VolumeToMesh instead of marching cubes)")->capture_default_str();
    cmd->add_flag("--quads", args->options.quads, "Quads instead of triangles (meshes with OpenVDB's VolumeToMesh instead of marching cubes)");
    cmd->callback([args, &global, &action] {
        action = [args, &global] {
            if (!is_mesh_path(args->output)) throw InvalidInput(args->output + ": unknown mesh format, expected .obj, .off, .ply, .stl, .om, .gltf or .glb");
            args->options.progress = stderr_progress(global);
            const SparseVoxmap voxmap = read_vdb_sparse(args->input, args->grid);
            const TriangleMesh mesh = extract(voxmap, args->options);
            if (mesh.face_count() == 0) throw InvalidInput(args->input + ": the volume has no surface at isovalue " + std::to_string(args->options.isovalue));
            write_mesh(mesh, args->output);
            note(global, "wrote " + args->output + ": " + std::to_string(mesh.vertices.size()) + " vertices, " +
                             std::to_string(mesh.face_count()) + " faces");
        };
    });
}

} // namespace voxwarp::cli
