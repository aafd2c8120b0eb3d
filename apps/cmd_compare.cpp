#include "cli_common.h"

#include <voxwarp/mesh_io.h>
#include <voxwarp/surface_distance.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <memory>

namespace voxwarp::cli {

namespace {

nlohmann::json mesh_facts(const std::string& path, const TriangleMesh& mesh, double crease_degrees) {
    const MeshTopology t = topology(mesh);
    const CreaseStats c = count_creases(mesh, crease_degrees);
    nlohmann::json j{{"file", path},
                     {"vertices", mesh.vertices.size()},
                     {"faces", mesh.face_count()},
                     {"closed", t.closed()},
                     {"manifold", t.manifold()},
                     {"oriented", t.oriented()},
                     {"components", t.components},
                     {"euler", t.euler},
                     {"creased_edges", c.creased},
                     {"interior_edges", c.edges},
                     {"creased_share", c.share()}};
    j["enclosed_volume"] = t.watertight() ? nlohmann::json(enclosed_volume(mesh)) : nlohmann::json(nullptr);
    return j;
}

} // namespace

void add_compare(CLI::App& app, Global&, Action& action) {
    struct Args {
        std::string a, b;
        double voxel = 0, crease = 30;
        std::size_t samples = 200000;
        bool json = false;
    };
    auto args = std::make_shared<Args>();
    auto* cmd = app.add_subcommand("compare", "Compare two meshes: symmetric surface distance (mean, p99, max), topology, volume, creases");
    cmd->add_option("a", args->a, "First mesh")->required();
    cmd->add_option("b", args->b, "Second mesh")->required();
    cmd->add_option("--voxel", args->voxel, "Voxel size: also report distances in voxels")->check(positive_number());
    cmd->add_option("--crease", args->crease, "Dihedral angle (degrees) above which an edge counts as a crease")->capture_default_str()->check(CLI::Range(0.0, 180.0));
    cmd->add_option("--samples", args->samples, "Area samples per mesh for the distance, besides the vertices")->capture_default_str();
    cmd->add_flag("--json", args->json, "Print JSON instead of text");
    cmd->callback([args, &action] {
        action = [args] {
            const TriangleMesh a = read_mesh(args->a), b = read_mesh(args->b);
            const SurfaceDistanceOptions options{.samples = args->samples};
            const DistanceStats ab = one_sided_distance(a, b, options), ba = one_sided_distance(b, a, options);
            const DistanceStats both = symmetric_distance(a, b, options);
            nlohmann::json j;
            j["a"] = mesh_facts(args->a, a, args->crease);
            j["b"] = mesh_facts(args->b, b, args->crease);
            j["crease_degrees"] = args->crease;
            auto dist = [&](const DistanceStats& d) {
                nlohmann::json r{{"mean", d.mean}, {"p99", d.p99}, {"max", d.max}, {"samples", d.samples}};
                if (args->voxel > 0) r["voxels"] = {{"mean", d.mean / args->voxel}, {"p99", d.p99 / args->voxel}, {"max", d.max / args->voxel}};
                return r;
            };
            j["distance"] = {{"symmetric", dist(both)}, {"a_to_b", dist(ab)}, {"b_to_a", dist(ba)}};
            if (args->json) {
                std::printf("%s\n", j.dump(2).c_str());
                return;
            }
            auto print_mesh = [](const char* label, const nlohmann::json& m) {
                std::printf("%s: %s\n  %zu vertices, %zu faces, closed %s, manifold %s, %lld component(s), euler %lld\n", label,
                            m["file"].get<std::string>().c_str(), m["vertices"].get<std::size_t>(), m["faces"].get<std::size_t>(),
                            m["closed"].get<bool>() ? "yes" : "no", m["manifold"].get<bool>() ? "yes" : "no", m["components"].get<long long>(),
                            m["euler"].get<long long>());
                if (!m["enclosed_volume"].is_null()) std::printf("  enclosed volume %.9g\n", m["enclosed_volume"].get<double>());
                std::printf("  creased edges %lld of %lld (%.2f%%)\n", m["creased_edges"].get<long long>(), m["interior_edges"].get<long long>(),
                            100 * m["creased_share"].get<double>());
            };
            print_mesh("a", j["a"]);
            print_mesh("b", j["b"]);
            for (const char* which : {"symmetric", "a_to_b", "b_to_a"}) {
                const auto& d = j["distance"][which];
                std::printf("distance %-9s mean %.6g  p99 %.6g  max %.6g", which, d["mean"].get<double>(), d["p99"].get<double>(), d["max"].get<double>());
                if (d.contains("voxels"))
                    std::printf("  (voxels: mean %.4f p99 %.4f max %.4f)", d["voxels"]["mean"].get<double>(), d["voxels"]["p99"].get<double>(),
                                d["voxels"]["max"].get<double>());
                std::printf("\n");
            }
        };
    });
}

} // namespace voxwarp::cli
