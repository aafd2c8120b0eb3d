#include "cli_common.h"
#include "pipeline.h"

#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>
#include <voxwarp/resources.h>
#include <voxwarp/vdb_io.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>

namespace voxwarp::cli {

namespace {

struct DeformArgs {
    std::string input, edits, output, report, mode = "volume";
    DeformOptions options;
    double max_memory_gib = 0;
};

void add_common_options(CLI::App* cmd, DeformArgs& a, bool mesh_input) {
    cmd->add_option("input", a.input, mesh_input ? "Input mesh (.obj .off .ply .stl .om)" : "Input voxmap (.vdb)")->required();
    cmd->add_option("edits", a.edits, "Edit file (JSON; schema in README.md)")->required();
    cmd->add_option("-o,--output", a.output, mesh_input ? "Output mesh (.obj .off .ply .stl .om)" : "Output .vdb")->required();
    cmd->add_flag("--preview", a.options.preview, "Map-and-round warp (the paper's fast, aliased preview)");
    cmd->add_option("--max-steps", a.options.max_steps, "Most steps an edit is split into so the lattice map stays injective")
        ->check(CLI::Range(1, 64))
        ->capture_default_str();
    cmd->add_option("--report", a.report, "Write a JSON report: residuals, steps, volumes, timings, peak memory");
    cmd->add_option("--max-memory", a.max_memory_gib, "Refuse requests estimated above this many GiB (default: 90% of free memory)");
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

nlohmann::json report_json(const DeformArgs& a, const DeformReport& r, double seconds) {
    nlohmann::json j;
    j["input"] = a.input;
    j["edits_file"] = a.edits;
    j["output"] = a.output;
    j["mode"] = a.mode;
    j["voxel_size"] = r.voxel_size;
    j["dims"] = {r.dims[0], r.dims[1], r.dims[2]};
    j["volume_before"] = r.volume_before;
    j["volume_after"] = r.volume_after;
    j["volume_change_percent"] = r.volume_before != 0 ? 100.0 * (r.volume_after / r.volume_before - 1.0) : 0.0;
    j["seconds"] = {{"total", seconds}, {"voxelize", r.seconds_voxelize}, {"solve", r.seconds_solve}, {"warp", r.seconds_warp}, {"extract", r.seconds_extract}};
    j["peak_resident_bytes"] = peak_resident_bytes();
    for (const auto& e : r.edits) {
        nlohmann::json je;
        je["steps"] = e.steps;
        je["folds_remain"] = e.folds_remain;
        je["solver"] = e.least_squares ? "weighted least squares (Ceres)" : "minimum-norm pseudoinverse";
        je["rank"] = e.rank;
        je["unknowns"] = e.unknowns;
        for (const auto& c : e.constraints)
            je["constraints"].push_back({{"name", c.name}, {"kind", c.kind}, {"residual", c.residual}, {"residual_voxels", c.residual_voxels}});
        j["edits"].push_back(je);
    }
    return j;
}

void finish(const Global& global, const DeformArgs& a, const DeformReport& r, double seconds) {
    for (const auto& e : r.edits) {
        for (const auto& c : e.constraints)
            if (c.residual_voxels > 0.5)
                std::fprintf(stderr, "voxwarp: warning: %s misses its target by %.3g (%.2f voxels)\n", c.name.c_str(), c.residual, c.residual_voxels);
        if (e.folds_remain && a.mode == "vertex")
            std::fprintf(stderr, "voxwarp: warning: an edit folds the lattice map; vertex mode applies it as it is (surfaces may cross)\n");
        else if (e.folds_remain)
            std::fprintf(stderr, "voxwarp: warning: an edit still folds the lattice map after %d steps; raise --max-steps\n", e.steps);
    }
    char line[256];
    std::snprintf(line, sizeof line, "volume %.6g -> %.6g (%+.2f%%), %zu edit(s), %.2f s", r.volume_before, r.volume_after,
                  r.volume_before != 0 ? 100.0 * (r.volume_after / r.volume_before - 1.0) : 0.0, r.edits.size(), seconds);
    note(global, line);
    if (!a.report.empty()) {
        const auto text = report_json(a, r, seconds).dump(2) + "\n";
        write_atomically(a.report, [&](const std::string& tmp) {
            std::ofstream out(tmp);
            out << text;
            if (!out) throw IOError(a.report + ": writing the report failed");
        });
    }
}

} // namespace

void add_deform(CLI::App& app, Global& global, Action& action) {
    auto a = std::make_shared<DeformArgs>();
    auto* cmd = app.add_subcommand("deform", "Mesh in, deformed re-polygonized mesh out: voxelize, warp by the edit file's constraints, extract");
    add_common_options(cmd, *a, true);
    auto* res = cmd->add_option("-r,--resolution", a->options.voxelize.resolution, "Voxels along the mesh's longest side")->capture_default_str();
    cmd->add_option("--voxel-size", a->options.voxelize.voxel_size, "Voxel size in world units (instead of --resolution)")->excludes(res);
    cmd->add_option("--mode", a->mode, "volume (re-polygonized, crease-free) or vertex (classic FFD of the input's vertices, for comparison)")
        ->check(CLI::IsMember({"volume", "vertex"}))
        ->capture_default_str();
    cmd->add_option("--adaptivity", a->options.extract.adaptivity, "OpenVDB adaptivity in [0, 1]: fewer faces in flat areas (meshes with OpenVDB's VolumeToMesh instead of marching cubes)")->capture_default_str();
    auto* quads = cmd->add_flag("--quads", a->options.extract.quads, "Quads instead of triangles (meshes with OpenVDB's VolumeToMesh instead of marching cubes)");
    cmd->add_option("--faces", a->options.target_faces, "Decimate the output to about this many triangles (CGAL edge collapse)")
        ->check(CLI::Range(std::size_t(4), std::size_t(1) << 40))
        ->excludes(quads);
    cmd->callback([a, &global, &action] {
        action = [a, &global] {
            const auto start = std::chrono::steady_clock::now();
            if (!is_mesh_path(a->output)) throw InvalidInput(a->output + ": unknown mesh format, expected .obj, .off, .ply, .stl or .om");
            a->options.voxelize.max_memory_bytes = std::uint64_t(a->max_memory_gib * double(1ull << 30));
            a->options.progress = stderr_progress(global);
            const EditScript script = read_edit_file(a->edits);
            const TriangleMesh mesh = read_mesh(a->input);
            DeformReport report;
            TriangleMesh out = attributing_errors(*a, [&] {
                return a->mode == "vertex" ? deform_vertices(mesh, script, a->options, report) : deform_mesh(mesh, script, a->options, report);
            });
            if (a->mode == "volume") report.volume_before = enclosed_volume(mesh.quads.empty() ? mesh : mesh.triangulated()), report.volume_after = enclosed_volume(out);
            write_mesh(out, a->output);
            finish(global, *a, report, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
            note(global, "wrote " + a->output + ": " + std::to_string(out.vertices.size()) + " vertices, " + std::to_string(out.face_count()) + " faces");
        };
    });
}

void add_warp(CLI::App& app, Global& global, Action& action) {
    auto a = std::make_shared<DeformArgs>();
    auto* cmd = app.add_subcommand("warp", "Voxmap (.vdb) in, warped voxmap out, by the edit file's constraints");
    add_common_options(cmd, *a, false);
    cmd->callback([a, &global, &action] {
        action = [a, &global] {
            const auto start = std::chrono::steady_clock::now();
            a->options.voxelize.max_memory_bytes = std::uint64_t(a->max_memory_gib * double(1ull << 30));
            a->options.progress = stderr_progress(global);
            const EditScript script = read_edit_file(a->edits);
            SparseVoxmap voxmap = read_vdb_sparse(a->input);
            DeformReport report;
            voxmap = attributing_errors(*a, [&] { return deform_voxmap(std::move(voxmap), script, a->options, report); });
            write_vdb(voxmap, a->output);
            finish(global, *a, report, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        };
    });
}

} // namespace voxwarp::cli
