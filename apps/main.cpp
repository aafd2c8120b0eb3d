// voxwarp: mesh in, warped volume, mesh out. See README.md for the commands, formats and exit codes.
#include "cli_common.h"

#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include <tbb/global_control.h>

#include <chrono>
#include <memory>
#include <cstdio>
#include <iostream>
#include <mutex>

namespace voxwarp::cli {

ProgressCallback stderr_progress(const Global& global) {
    if (global.quiet) return {};
    struct State {
        std::string stage;
        int last_percent = -100;
        std::chrono::steady_clock::time_point last = std::chrono::steady_clock::now();
    };
    auto state = std::make_shared<State>();
    return [state](std::string_view stage, double fraction) {
        const int percent = int(fraction * 100);
        const auto now = std::chrono::steady_clock::now();
        const bool new_stage = stage != state->stage;
        if (new_stage || (percent >= state->last_percent + 10 && now - state->last > std::chrono::milliseconds(500)) ||
            (percent == 100 && state->last_percent != 100)) {
            std::fprintf(stderr, "voxwarp: %.*s %d%%\n", int(stage.size()), stage.data(), percent);
            state->stage = std::string(stage);
            state->last_percent = percent;
            state->last = now;
        }
        return true;
    };
}

void note(const Global& global, const std::string& line) {
    if (!global.quiet) std::fprintf(stderr, "voxwarp: %s\n", line.c_str());
}

TriangleMesh read_mesh_warning(const std::string& path) {
    std::vector<std::string> warnings;
    TriangleMesh mesh = read_mesh(path, &warnings);
    for (const auto& w : warnings) std::fprintf(stderr, "voxwarp: warning: %s\n", w.c_str());
    return mesh;
}

std::string attributes_of(const TriangleMesh& mesh, bool counts) {
    std::string list;
    auto add = [&](bool has, std::size_t count, const char* one, const char* many) {
        if (has) list += (list.empty() ? "" : ", ") + (counts ? std::to_string(count) + " " + (count == 1 ? one : many) : std::string(many));
    };
    add(!mesh.triangle_uvs.empty(), mesh.uvs.size(), "texture coordinate", "texture coordinates");
    add(!mesh.triangle_normals.empty(), mesh.normals.size(), "normal", "normals");
    if (!mesh.colours.empty()) list += (list.empty() ? "" : ", ") + std::string("vertex colours");
    add(!mesh.materials.empty(), mesh.materials.size(), "material", "materials");
    add(!mesh.triangle_groups.empty(), mesh.groups.size(), "group", "groups");
    return list;
}

} // namespace voxwarp::cli

int main(int argc, char** argv) {
    using namespace voxwarp;
    using namespace voxwarp::cli;
    CLI::App app{"voxwarp: deform polygon models by warping the space they live in (True & Hughes volume warping).\n"
                 "A mesh is voxelized into a density volume (a voxmap), warped by a cubic B-spline lattice, and\n"
                 "re-polygonized, so large deformations of coarse models come out smooth and crease-free."};
    app.require_subcommand(1);
    app.fallthrough(); // global flags such as --quiet work after the subcommand too
    app.set_version_flag("--version", "voxwarp 0.1.0");
    Global global;
    app.add_flag("-q,--quiet", global.quiet, "No progress or notes on stderr");
    app.add_option("-j,--threads", global.threads, "Worker threads (default: all cores); results are byte-identical for any count")
        ->check(CLI::Range(1, 1024));
    Action action;
    add_voxelize(app, global, action);
    add_extract(app, global, action);
    add_info(app, global, action);
    add_deform(app, global, action);
    add_remesh(app, global, action);
    add_warp(app, global, action);
    add_compare(app, global, action);
    add_render(app, global, action);
    add_edit(app, global, action);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        const int code = app.exit(e);
        return code == 0 ? Exit::ok : Exit::usage;
    }
    try {
        std::unique_ptr<tbb::global_control> limit;
        if (global.threads > 0) limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, std::size_t(global.threads));
        action();
        return Exit::ok;
    } catch (const InvalidInput& e) {
        std::cerr << "voxwarp: error: " << e.what() << "\n";
        return Exit::bad_input;
    } catch (const ResourceLimit& e) {
        std::cerr << "voxwarp: error: " << e.what() << "\n";
        return Exit::resource_limit;
    } catch (const SolverFailure& e) {
        std::cerr << "voxwarp: error: " << e.what() << "\n";
        return Exit::solver_failure;
    } catch (const IOError& e) {
        std::cerr << "voxwarp: error: " << e.what() << "\n";
        return Exit::io_failure;
    } catch (const Cancelled& e) {
        std::cerr << "voxwarp: error: " << e.what() << "\n";
        return Exit::cancelled;
    } catch (const std::bad_alloc&) {
        std::cerr << "voxwarp: error: out of memory; lower the resolution\n";
        return Exit::resource_limit;
    } catch (const std::exception& e) {
        std::cerr << "voxwarp: internal error: " << e.what() << "\n";
        return Exit::internal;
    }
}
