#include "cli_common.h"

#include <cstdio>

#include <voxwarp/mesh_io.h>
#include <voxwarp/vdb_io.h>
#include <voxwarp/voxelize.h>

#include <memory>

namespace voxwarp::cli {

void add_voxelize(CLI::App& app, Global& global, Action& action) {
    struct Args {
        std::string input, output, sign = "auto";
        VoxelizeOptions options;
        double max_memory_gib = 0;
    };
    auto args = std::make_shared<Args>();
    auto* cmd = app.add_subcommand("voxelize", "Mesh -> antialiased density voxmap (.vdb, FloatGrid 'density', surface at 0.5)");
    cmd->add_option("input", args->input, "Input mesh (.obj .off .ply .stl .om .gltf .glb)")->required();
    cmd->add_option("-o,--output", args->output, "Output .vdb file")->required();
    auto* res = cmd->add_option("-r,--resolution", args->options.resolution, "Voxels along the mesh's longest side")
                    ->capture_default_str();
    cmd->add_option("--voxel-size", args->options.voxel_size, "Voxel size in world units (instead of --resolution)")->excludes(res)->check(positive_number());
    cmd->add_option("--padding", args->options.padding_voxels, "Empty voxels around the mesh")->capture_default_str();
    cmd->add_option("--sign", args->sign, "Inside/outside test: auto (flood fill for watertight meshes, unless it loses the surface or walls are thinner than a voxel), flood-fill or winding-number")
        ->check(CLI::IsMember({"auto", "flood-fill", "winding-number"}))
        ->capture_default_str();
    add_max_memory(cmd, args->max_memory_gib);
    cmd->callback([args, &global, &action] {
        action = [args, &global] {
            auto& o = args->options;
            o.sign = parse_sign(args->sign);
            VoxelizeReport done;
            o.report = &done;
            o.max_memory_bytes = gib_to_bytes(args->max_memory_gib);
            o.progress = stderr_progress(global);
            const TriangleMesh mesh = read_mesh_warning(args->input);
            const SparseVoxmap voxmap = naming_source(args->input, [&] { return voxelize_sparse(mesh, o); });
            write_vdb(voxmap, args->output);
            const auto& n = voxmap.dims();
            if (!done.note.empty()) note(global, "voxelize: " + done.note);
            char size[32];
            std::snprintf(size, sizeof size, "%.6g", voxmap.voxel_size());
            note(global, "wrote " + args->output + ": " + std::to_string(n[0]) + "x" + std::to_string(n[1]) + "x" + std::to_string(n[2]) +
                             " voxels of size " + size);
        };
    });
}

} // namespace voxwarp::cli
