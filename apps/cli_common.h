/// @file cli_common.h
/// @brief Shared pieces of the voxwarp command line: progress on stderr, exit codes, option helpers.
#pragma once

#include <voxwarp/errors.h>
#include <voxwarp/extract.h>
#include <voxwarp/progress.h>

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdint>
#include <exception>
#include <functional>
#include <string>

namespace voxwarp::cli {

/// Exit codes, documented in the README.
enum Exit : int { ok = 0, usage = 1, bad_input = 2, resource_limit = 3, solver_failure = 4, io_failure = 5, cancelled = 6, internal = 10 };

/// Options every subcommand shares.
struct Global {
    bool quiet = false;
    int threads = 0; ///< 0 = all cores
};

/// A progress callback printing "voxwarp: stage 40%" lines to stderr (throttled), or nothing when quiet.
ProgressCallback stderr_progress(const Global& global);

/// Print an informational line to stderr unless quiet.
void note(const Global& global, const std::string& line);

/// read_mesh, with the problems that do not stop the reading (a missing .mtl or texture, repeated faces) printed as
/// "voxwarp: warning: ..." lines on stderr.
TriangleMesh read_mesh_warning(const std::string& path);

/// The attributes a mesh carries, as a comma-separated list ("texture coordinates, normals, vertex colours,
/// materials, groups"; with `counts`, each with its number: "3225 texture coordinates, 1 material"); empty: none.
std::string attributes_of(const TriangleMesh& mesh, bool counts);

/// Run `f`; an InvalidInput it throws that does not already start with `source` is rethrown prefixed with it,
/// so every message about bad input names the file it came from.
template <class F>
auto naming_source(const std::string& source, F&& f) -> decltype(f()) {
    try {
        return f();
    } catch (const InvalidInput& e) {
        if (std::string(e.what()).rfind(source, 0) == 0) throw;
        throw InvalidInput(source + ": " + e.what());
    }
}

/// A check for an option that takes a finite number above 0 (a length, a memory limit): CLI::PositiveNumber's
/// message prints the largest double as its range.
inline CLI::Validator positive_number() {
    return CLI::Validator(
        [](const std::string& text) {
            try {
                std::size_t used = 0;
                const double x = std::stod(text, &used);
                if (used == text.size() && std::isfinite(x) && x > 0) return std::string();
            } catch (const std::exception&) {
            }
            return "expected a number above 0, got " + text;
        },
        "POSITIVE");
}

/// `--max-memory GIB` (a number above 0; unset: 0, the library's default of 90 % of free memory) on `cmd`.
inline CLI::Option* add_max_memory(CLI::App* cmd, double& gib) {
    return cmd->add_option("--max-memory", gib, "Refuse requests estimated above this many GiB (default: 90% of free memory)")->check(positive_number());
}

/// A GiB count as a byte count for VoxelizeOptions::max_memory_bytes: 0 stays 0 (the default), a count past what
/// 64 bits hold is the largest.
inline std::uint64_t gib_to_bytes(double gib) {
    const double bytes = gib * double(1ull << 30);
    return bytes >= 18446744073709551615.0 ? ~std::uint64_t(0) : std::uint64_t(bytes);
}

/// `--mesher mc|features`, read through parse_mesher so the command line, edit server and Python agree.
inline CLI::Option* add_mesher_option(CLI::App* cmd, Mesher& mesher) {
    return cmd
        ->add_option_function<std::string>(
            "--mesher", [&mesher](const std::string& name) { mesher = parse_mesher(name); },
            "mc: marching cubes (smooth, fast); features: sharp edges and corners put back (Extended Marching Cubes; "
            "the input's own sharp edges kept; a deformed mesh without any comes out as with mc; about 1.1-1.4x mc's time in a "
            "deform; vertices that would push a sheet through another go back, though faces can still touch, to "
            "round-off, where a model has sharp edges; mc's output never meets itself)")
        ->check([](const std::string& name) {
            try {
                parse_mesher(name);
                return std::string();
            } catch (const InvalidInput& e) {
                const std::string what = e.what(); // CLI11 names the option itself
                return what.substr(what.rfind("mesher: ", 0) == 0 ? 8 : 0);
            }
        })
        ->type_name("features|mc")
        ->default_str("mc");
}

/// Each subcommand registers itself and sets the action run after parsing.
using Action = std::function<void()>;
void add_voxelize(CLI::App& app, Global& global, Action& action);
void add_extract(CLI::App& app, Global& global, Action& action);
void add_info(CLI::App& app, Global& global, Action& action);
void add_deform(CLI::App& app, Global& global, Action& action);
void add_remesh(CLI::App& app, Global& global, Action& action);
void add_warp(CLI::App& app, Global& global, Action& action);
void add_compare(CLI::App& app, Global& global, Action& action);
void add_render(CLI::App& app, Global& global, Action& action);
void add_edit(CLI::App& app, Global& global, Action& action);

} // namespace voxwarp::cli
