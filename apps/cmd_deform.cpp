#include "cli_common.h"
#include "web.h"
#include <voxwarp/deform.h>

#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>
#include <voxwarp/resources.h>
#include <voxwarp/vdb_io.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

namespace voxwarp::cli {

namespace {

struct DeformArgs {
    std::string input, edits, output, report, png, mode = "volume", sign = "auto";
    DeformOptions options;
    double max_memory_gib = 0;
};

void add_common_options(CLI::App* cmd, DeformArgs& a, bool mesh_input) {
    cmd->add_option("input", a.input, mesh_input ? "Input mesh (.obj .off .ply .stl .om .gltf .glb)" : "Input voxmap (.vdb)")->required();
    cmd->add_option("edits", a.edits, "Edit file (JSON; schema in README.md)")->required();
    cmd->add_option("-o,--output", a.output, mesh_input ? "Output mesh (.obj .off .ply .stl .om .gltf .glb)" : "Output .vdb")->required();
    cmd->add_flag("--preview", a.options.preview, "Map-and-round warp (the paper's preview: no box filter; with tents to fill stretched gaps it now costs about what the full warp does)");
    cmd->add_option("--max-steps", a.options.max_steps, "Most steps an edit is split into so the lattice map stays injective")
        ->check(CLI::Range(1, 64))
        ->capture_default_str();
    cmd->add_option("--report", a.report, "Write a JSON report: residuals, steps, volumes, timings, peak memory");
    add_max_memory(cmd, a.max_memory_gib);
}

/// Run a deform job: messages about a constraint (they start with its JSON path, "edits[...") name the edit
/// file, any other bad-input message names the input file.
template <class F>
auto attributing_errors(const DeformArgs& a, F&& f) -> decltype(f()) {
    return naming_source(a.input, [&] {
        try {
            return f();
        } catch (const InvalidInput& e) {
            if (std::string(e.what()).rfind("edits[", 0) == 0) throw InvalidInput(a.edits + ": " + e.what());
            throw;
        }
    });
}

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

void finish(const Global& global, const DeformArgs& a, DeformReport& r, Clock::time_point start) {
    for (const auto& w : deform_warnings(r)) std::fprintf(stderr, "voxwarp: warning: %s\n", w.c_str());
    r.seconds_total = seconds_since(start);
    char line[256];
    char change[48] = "no input volume to compare";
    if (const auto percent = volume_change_percent(r.volume_before, r.volume_after)) std::snprintf(change, sizeof change, "%+.2f%%", *percent);
    std::snprintf(line, sizeof line, "volume %.6g -> %.6g (%s), %zu edit(s), %.2f s", r.volume_before, r.volume_after, change, r.edits.size(), r.seconds_total);
    note(global, line);
    if (!a.report.empty()) {
        const auto text = report_json(r, {{"input", a.input}, {"edits_file", a.edits}, {"output", a.output}});
        write_file_atomically(a.report, text, "the report");
    }
}

} // namespace

namespace {

/// The options deform and remesh share: how the mesh becomes a voxmap and the voxmap a mesh again.
void add_mesh_options(CLI::App* cmd, DeformArgs& a) {
    auto* res = cmd->add_option("-r,--resolution", a.options.voxelize.resolution, "Voxels along the mesh's longest side")->capture_default_str();
    cmd->add_option("--voxel-size", a.options.voxelize.voxel_size, "Voxel size in world units (instead of --resolution)")->excludes(res)->check(positive_number());
    cmd->add_option("--sign", a.sign, "Inside/outside test: auto (flood fill for watertight meshes, unless it loses the surface or walls are thinner than a voxel), flood-fill or winding-number")
        ->check(CLI::IsMember({"auto", "flood-fill", "winding-number"}))
        ->capture_default_str();
    add_mesher_option(cmd, a.options.extract.mesher);
    cmd->add_flag("--no-snap", [&a](std::int64_t) { a.options.snap = false; },
                  "Leave output vertices where extraction puts them (by default each moves onto the exact image of its source point on the input, when that moves it at most half a voxel (an image up to a voxel away: half a voxel toward it) and flips no face; the vertex nearest each move's target, within 1.5 voxels, onto the target; and edges that cut under a crease of the input split on it)");
    cmd->add_option("--adaptivity", a.options.extract.adaptivity, "OpenVDB adaptivity in [0, 1]: fewer faces in flat areas (meshes with OpenVDB's VolumeToMesh instead of marching cubes)")->capture_default_str();
    auto* quads = cmd->add_flag("--quads", a.options.extract.quads, "Quads instead of triangles (meshes with OpenVDB's VolumeToMesh instead of marching cubes)");
    cmd->add_option("--png", a.png, "Also write a before / after picture (voxwarp render's, headless Chromium)");
    cmd->add_option("--faces", a.options.target_faces, "Decimate the output to about this many triangles (CGAL edge collapse)")
        ->check(CLI::Range(std::size_t(4), std::size_t(1) << 40))
        ->excludes(quads);
}

/// Read the mesh (its warnings on stderr), deform it by `script` (none: the round trip), write the output and the report.
void run_mesh_job(const Global& global, DeformArgs& a, const EditScript& script, Clock::time_point start) {
    DeformReport report;
    auto t = Clock::now();
    const TriangleMesh mesh = read_mesh_warning(a.input);
    report.seconds_read = seconds_since(t);
    TriangleMesh out = attributing_errors(a, [&] {
        return a.mode == "vertex" ? deform_vertices(mesh, script, a.options, report) : deform_mesh(mesh, script, a.options, report);
    });
    t = Clock::now();
    write_mesh(out, a.output);
    report.seconds_write = seconds_since(t);
    finish(global, a, report, start);
    const std::string carried = attributes_of(out, false);
    note(global, "wrote " + a.output + ": " + std::to_string(out.vertices.size()) + " vertices, " + std::to_string(out.face_count()) + " faces" +
                     (carried.empty() ? "" : " (with its " + carried + ")"));
    if (!a.png.empty()) {
        render_png({mesh, out}, {"before", "after"}, {}, a.png);
        note(global, "wrote " + a.png);
    }
}

void check_paths(DeformArgs& a, const Global& global) {
    if (!is_mesh_path(a.output)) throw InvalidInput(a.output + ": unknown mesh format, expected .obj, .off, .ply, .stl, .om, .gltf or .glb");
    if (!a.png.empty() && std::filesystem::path(a.png).extension() != ".png") throw InvalidInput(a.png + ": expected a .png picture");
    a.options.voxelize.max_memory_bytes = gib_to_bytes(a.max_memory_gib);
    a.options.voxelize.sign = parse_sign(a.sign);
    a.options.progress = stderr_progress(global);
}

} // namespace

void add_deform(CLI::App& app, Global& global, Action& action) {
    auto a = std::make_shared<DeformArgs>();
    auto* cmd = app.add_subcommand("deform", "Mesh in, deformed re-polygonized mesh out: voxelize, warp by the edit file's constraints, extract");
    add_common_options(cmd, *a, true);
    add_mesh_options(cmd, *a);
    cmd->add_option("--mode", a->mode, "volume (re-polygonized, crease-free) or vertex (classic FFD of the input's vertices, for comparison)")
        ->check(CLI::IsMember({"volume", "vertex"}))
        ->capture_default_str();
    cmd->callback([a, &global, &action] {
        action = [a, &global] {
            const auto start = Clock::now();
            check_paths(*a, global);
            run_mesh_job(global, *a, read_edit_file(a->edits), start);
        };
    });
}

void add_remesh(CLI::App& app, Global& global, Action& action) {
    auto a = std::make_shared<DeformArgs>();
    auto* cmd = app.add_subcommand("remesh", "Mesh in, re-polygonized mesh out (the round trip, no edit): voxelize, extract, snap onto the input; texture coordinates, normals, colours, materials and groups carried");
    cmd->add_option("input", a->input, "Input mesh (.obj .off .ply .stl .om .gltf .glb)")->required();
    cmd->add_option("-o,--output", a->output, "Output mesh (.obj .off .ply .stl .om .gltf .glb)")->required();
    cmd->add_option("--report", a->report, "Write a JSON report: volumes, timings, peak memory, snapped vertices");
    add_max_memory(cmd, a->max_memory_gib);
    add_mesh_options(cmd, *a);
    cmd->callback([a, &global, &action] {
        action = [a, &global] {
            const auto start = Clock::now();
            check_paths(*a, global);
            run_mesh_job(global, *a, EditScript{}, start);
        };
    });
}

void add_warp(CLI::App& app, Global& global, Action& action) {
    auto a = std::make_shared<DeformArgs>();
    auto* cmd = app.add_subcommand("warp", "Voxmap (.vdb) in, warped voxmap out, by the edit file's constraints");
    add_common_options(cmd, *a, false);
    cmd->callback([a, &global, &action] {
        action = [a, &global] {
            const auto start = Clock::now();
            a->options.voxelize.max_memory_bytes = gib_to_bytes(a->max_memory_gib);
            a->options.progress = stderr_progress(global);
            const EditScript script = read_edit_file(a->edits);
            DeformReport report;
            auto t = Clock::now();
            SparseVoxmap voxmap = read_vdb_sparse(a->input);
            report.seconds_read = seconds_since(t);
            voxmap = attributing_errors(*a, [&] { return deform_voxmap(std::move(voxmap), script, a->options, report); });
            t = Clock::now();
            write_vdb(voxmap, a->output);
            report.seconds_write = seconds_since(t);
            finish(global, *a, report, start);
        };
    });
}

} // namespace voxwarp::cli
