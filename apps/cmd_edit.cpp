// voxwarp edit: the direct-manipulation editor's local server (cpp-httplib, 127.0.0.1 only). The page (web/) and
// scripts use the same HTTP API (README.md, "The editor"):
//   GET  /                      the editor page (and its scripts, three.js from Debian's libjs-three)
//   GET  /api/model             the input mesh, binary PLY (with texture coordinates and colours when it has them);
//                               X-Voxwarp-Model: JSON facts (name, bounds, voxel size, whether it has a texture)
//   GET  /api/texture           the input's (first) texture, PNG or JPEG (404 when none)
//   GET  /api/edit              the edit file given on the command line (204 when none)
//   POST /api/deform[?resolution=N]   body: an edit file's JSON; 200: the deformed mesh (binary PLY,
//                               Content-Type application/ply; at full resolution with the input's texture
//                               coordinates and colours carried), the report as JSON in the X-Voxwarp-Report header
//   GET  /api/lattice           the last deform's last edit's lattice: {"size": [nx, ny, nz], "rest": [[x, y, z], ...],
//                               "solved": [...]}, control point i + nx (j + ny k) (204 before the first deform)
// Errors answer {"error": message}: 400 malformed edits (the CLI's message, the file named "request") or a
// resolution over --max-resolution, 403 a foreign Host or Origin or a missing token (web.h, Gate), 404 unknown
// paths, 409 a request superseded by a newer one (which runs instead), 413 bodies over 16 MiB, 503 memory or
// time limits, 500 anything else. One deform runs at a time; the server keeps serving whatever a request does.
#include "cli_common.h"
#include "web.h"

#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>
#include <voxwarp/resources.h>
#include <voxwarp/session.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <sstream>

namespace voxwarp::cli {

namespace {

struct EditArgs {
    std::string mesh, edits, token;
    int port = 8765, resolution = 128, max_seconds = 120, max_resolution = 0;
    double max_memory_gib = 0;
    bool no_browser = false, no_token = false;
};

std::atomic<httplib::Server*> g_server{nullptr};
extern "C" void stop_server(int) {
    if (auto* s = g_server.load()) s->stop();
}

/// The deform requests: one at a time on the session; a newer request cancels the one running.
class Editor {
public:
    Editor(const EditArgs& args, TriangleMesh mesh) : args_(args), session_(std::move(mesh), options(args)) {}

    static DeformOptions options(const EditArgs& args) {
        DeformOptions o;
        o.voxelize.resolution = args.resolution;
        o.voxelize.max_memory_bytes = gib_to_bytes(args.max_memory_gib);
        return o;
    }

    void deform(const httplib::Request& request, httplib::Response& response) {
        int resolution = args_.resolution;
        if (request.has_param("resolution")) {
            const std::string text = request.get_param_value("resolution");
            std::size_t used = 0;
            try {
                resolution = std::stoi(text, &used);
            } catch (const std::exception&) {
                used = 0;
            }
            if (used != text.size() || resolution < 8 || resolution > args_.max_resolution)
                return send_error(response, 400, "request: resolution '" + text.substr(0, 20) + "': expected an integer in [8, " +
                                                     std::to_string(args_.max_resolution) + "] (--max-resolution)");
        }
        EditScript script;
        try {
            script = parse_edit_script(request.body, "request");
        } catch (const InvalidInput& e) {
            return send_error(response, 400, e.what());
        }
        const std::uint64_t ticket = ++latest_;
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(args_.max_seconds);
        bool late = false;
        auto progress = [&](std::string_view, double) {
            if (std::chrono::steady_clock::now() > deadline) late = true;
            return latest_ == ticket && !late;
        };
        std::lock_guard lock(mutex_);
        if (latest_ != ticket) return send_error(response, 409, "request: superseded by a newer request");
        try {
            DeformReport report;
            const auto start = std::chrono::steady_clock::now();
            // Drag previews (below the full resolution) are shown for a moment: they skip snapping and the attributes
            // (texture coordinates, colours), the result does not.
            const TriangleMesh out = session_.deform(script, resolution, report, progress, resolution >= args_.resolution);
            report.seconds_total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
            send_mesh(response, out);
            if (!report.edits.empty()) lattice_ = lattice_json(report.edits.back());
            // One line of JSON: a header holds it.
            response.set_header("X-Voxwarp-Report", nlohmann::json::parse(report_json(report)).dump());
        } catch (const Cancelled&) {
            if (late) return send_error(response, 503, "request: took longer than " + std::to_string(args_.max_seconds) + " s (--max-seconds)");
            send_error(response, 409, "request: superseded by a newer request");
        } catch (const InvalidInput& e) {
            const std::string m = e.what();
            send_error(response, 400, m.rfind("edits[", 0) == 0 ? "request: " + m : m);
        } catch (const ResourceLimit& e) {
            send_error(response, 503, e.what());
        } catch (const SolverFailure& e) {
            send_error(response, 422, e.what());
        } catch (const std::bad_alloc&) {
            send_error(response, 503, "out of memory; lower the resolution");
        }
    }

    void texture(httplib::Response& response) const {
        if (texture_.empty()) return send_error(response, 404, "the model has no texture");
        send_texture(response, texture_);
    }

    void lattice(httplib::Response& response) {
        std::lock_guard lock(mutex_);
        if (lattice_.empty()) {
            response.status = 204;
            return;
        }
        response.set_content(lattice_, "application/json");
    }

    static std::string lattice_json(const EditReport& edit) {
        auto points = [](const std::vector<Eigen::Vector3d>& ps) {
            nlohmann::json out = nlohmann::json::array();
            for (const auto& p : ps) out.push_back({p.x(), p.y(), p.z()});
            return out;
        };
        return nlohmann::json{{"size", edit.lattice_size}, {"rest", points(edit.lattice_rest)}, {"solved", points(edit.lattice_solved)}}.dump();
    }

    void model(httplib::Response& response) const {
        const Bounds b = bounds(session_.mesh());
        const nlohmann::json facts{{"name", std::filesystem::path(args_.mesh).filename().string()},
                                   {"bounds", {{b.min.x(), b.min.y(), b.min.z()}, {b.max.x(), b.max.y(), b.max.z()}}},
                                   {"resolution", args_.resolution},
                                   {"voxel_size", session_.voxel_size()},
                                   {"vertices", session_.mesh().vertices.size()},
                                   {"faces", session_.mesh().face_count()},
                                   {"texture", !texture_.empty()}};
        send_mesh(response, session_.mesh());
        response.set_header("X-Voxwarp-Model", facts.dump());
    }

private:
    const EditArgs& args_;
    DeformSession session_;
    std::mutex mutex_;
    std::atomic<std::uint64_t> latest_{0};
    std::string lattice_; // lattice_json of the last deform, under mutex_
    std::string texture_ = first_texture(session_.mesh());
};

} // namespace

void add_edit(CLI::App& app, Global& global, Action& action) {
    auto a = std::make_shared<EditArgs>();
    auto* cmd = app.add_subcommand("edit", "Edit in the browser: click the model to add handles and pins, drag them, see the result live; serves 127.0.0.1 only");
    cmd->add_option("mesh", a->mesh, "Mesh to edit (.obj .off .ply .stl .om .gltf .glb)")->required();
    cmd->add_option("edits", a->edits, "Edit file to start from (JSON)");
    cmd->add_option("--port", a->port, "Port on 127.0.0.1 (0: any free one)")->check(CLI::Range(0, 65535))->capture_default_str();
    cmd->add_option("-r,--resolution", a->resolution, "Voxels along the mesh's longest side for the full result (drags preview at half)")
        ->check(CLI::Range(8, 1024))
        ->capture_default_str();
    cmd->add_option("--max-seconds", a->max_seconds, "Longest a deform request may take")->check(CLI::Range(1, 3600))->capture_default_str();
    cmd->add_option("--max-resolution", a->max_resolution, "Highest resolution a request may ask for (default: twice --resolution, at most 1024)")
        ->check(CLI::Range(8, 1024));
    add_max_memory(cmd, a->max_memory_gib);
    auto* token = cmd->add_option("--token", a->token, "The session's token (letters, digits, - _ . ~; at least 16), for scripts; default: 128 random bits");
    cmd->add_flag("--no-token", a->no_token, "Let /api/ requests in without the token (any local program, and any page you visit, can then use the server)")
        ->excludes(token);
    cmd->add_flag("--no-browser", a->no_browser, "Do not open a browser; print the address only");
    cmd->callback([a, &global, &action] {
        if (a->max_resolution == 0) a->max_resolution = std::min(1024, 2 * a->resolution);
        if (a->max_resolution < a->resolution)
            throw CLI::ValidationError("--max-resolution", std::to_string(a->max_resolution) + " is below --resolution " + std::to_string(a->resolution));
        if (!a->token.empty()) {
            const bool url_safe = std::all_of(a->token.begin(), a->token.end(), [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || std::strchr("-_.~", c); });
            if (!url_safe || a->token.size() < 16 || a->token.size() > 256)
                throw CLI::ValidationError("--token", "expected 16 to 256 letters, digits, '-', '_', '.' or '~'");
        }
        action = [a, &global] {
            TriangleMesh mesh = read_mesh_warning(a->mesh); // drag previews carry no attributes (DeformSession)
            std::string initial_edit;
            if (!a->edits.empty()) {
                read_edit_file(a->edits); // refused here, with the file's name, rather than in the page
                std::ifstream in(a->edits);
                std::stringstream text;
                text << in.rdbuf();
                initial_edit = text.str();
            }
            Editor editor(*a, std::move(mesh));
            Gate gate{0, a->no_token ? std::string() : a->token.empty() ? random_token() : a->token};
            if (a->no_token) // a warning even with -q: it says who else can use the server
                std::fprintf(stderr, "voxwarp: warning: edit --no-token: any program on this machine, and any web page open in its browsers, can use the server\n");
            httplib::Server server;
            guard(server, gate);
            server.set_payload_max_length(16u << 20);
            server.set_read_timeout(30, 0);
            server.set_write_timeout(30, 0);
            server.Get("/api/model", [&](const httplib::Request&, httplib::Response& r) { editor.model(r); });
            server.Get("/api/edit", [&](const httplib::Request&, httplib::Response& r) {
                if (initial_edit.empty()) r.status = 204;
                else r.set_content(initial_edit, "application/json");
            });
            server.Get("/api/lattice", [&](const httplib::Request&, httplib::Response& r) { editor.lattice(r); });
            server.Get("/api/texture", [&](const httplib::Request&, httplib::Response& r) { editor.texture(r); });
            server.Post("/api/deform", [&](const httplib::Request& q, httplib::Response& r) { editor.deform(q, r); });
            server.Get("/favicon.ico", [](const httplib::Request&, httplib::Response& r) { r.status = 204; });
            server.Post(R"(/.*)", [](const httplib::Request& q, httplib::Response& r) { send_error(r, 404, "no such path: " + q.path); });
            serve_assets(server);
            server.set_exception_handler([](const httplib::Request&, httplib::Response& r, std::exception_ptr e) {
                try {
                    std::rethrow_exception(e);
                } catch (const std::exception& x) {
                    send_error(r, 500, std::string("internal error: ") + x.what());
                } catch (...) {
                    send_error(r, 500, "internal error");
                }
            });
            server.set_error_handler([](const httplib::Request&, httplib::Response& r) {
                if (r.body.empty()) send_error(r, r.status, r.status == 413 ? "request: body larger than 16 MiB" : "request refused (HTTP " + std::to_string(r.status) + ")");
            });
            const int port = a->port == 0 ? server.bind_to_any_port("127.0.0.1") : (server.bind_to_port("127.0.0.1", a->port) ? a->port : -1);
            if (port <= 0) throw IOError("edit: cannot listen on 127.0.0.1:" + std::to_string(a->port) + " (in use? try --port 0)");
            gate.port = port;
            const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/" + (gate.token.empty() ? "" : "?token=" + gate.token);
            // The address goes to stdout (scripts read it), the rest of the chatter to stderr.
            std::printf("voxwarp edit: serving %s at %s\n", a->mesh.c_str(), url.c_str());
            std::fflush(stdout);
            if (!a->no_browser && !open_in_browser(url)) note(global, "open " + url + " in a browser");
            g_server = &server;
            std::signal(SIGINT, stop_server);
            std::signal(SIGTERM, stop_server);
            server.listen_after_bind();
            g_server = nullptr;
            note(global, "edit: stopped");
        };
    });
}

} // namespace voxwarp::cli
