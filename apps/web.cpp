#include "web.h"

#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include <nlohmann/json.hpp>

#include <cctype>
#include <cerrno>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>

#include <fcntl.h>
#include <signal.h>
#include <sys/random.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

// The page's files, linked into the program so that it serves them wherever it is installed.
#define VOXWARP_EMBED(name, path)                                                                                                                      \
    asm(".section .rodata\n.balign 16\n.global " #name "_begin\n" #name "_begin:\n.incbin \"" path "\"\n.global " #name "_end\n" #name "_end:\n" \
        ".byte 0\n.previous\n");                                                                                                                       \
    extern "C" const char name##_begin[];                                                                                                              \
    extern "C" const char name##_end[];
VOXWARP_EMBED(voxwarp_web_index, VOXWARP_WEB_DIR "/index.html")
VOXWARP_EMBED(voxwarp_web_editor, VOXWARP_WEB_DIR "/editor.js")
VOXWARP_EMBED(voxwarp_web_viewer, VOXWARP_WEB_DIR "/viewer.js")
VOXWARP_EMBED(voxwarp_web_render, VOXWARP_WEB_DIR "/render.html")
VOXWARP_EMBED(voxwarp_web_style, VOXWARP_WEB_DIR "/style.css")
VOXWARP_EMBED(voxwarp_three, VOXWARP_THREE_JS)
VOXWARP_EMBED(voxwarp_orbit, VOXWARP_ORBIT_CONTROLS_JS)
VOXWARP_EMBED(voxwarp_transform, VOXWARP_TRANSFORM_CONTROLS_JS)

namespace voxwarp::cli {

std::optional<Asset> find_asset(const std::string& path) {
    struct Entry {
        const char* path;
        const char *begin, *end;
        const char* type;
    };
    static const Entry entries[] = {
        {"/", voxwarp_web_index_begin, voxwarp_web_index_end, "text/html; charset=utf-8"},
        {"/index.html", voxwarp_web_index_begin, voxwarp_web_index_end, "text/html; charset=utf-8"},
        {"/editor.js", voxwarp_web_editor_begin, voxwarp_web_editor_end, "text/javascript; charset=utf-8"},
        {"/viewer.js", voxwarp_web_viewer_begin, voxwarp_web_viewer_end, "text/javascript; charset=utf-8"},
        {"/render.html", voxwarp_web_render_begin, voxwarp_web_render_end, "text/html; charset=utf-8"},
        {"/style.css", voxwarp_web_style_begin, voxwarp_web_style_end, "text/css; charset=utf-8"},
        {"/three.min.js", voxwarp_three_begin, voxwarp_three_end, "text/javascript; charset=utf-8"},
        {"/OrbitControls.js", voxwarp_orbit_begin, voxwarp_orbit_end, "text/javascript; charset=utf-8"},
        {"/TransformControls.js", voxwarp_transform_begin, voxwarp_transform_end, "text/javascript; charset=utf-8"},
    };
    for (const auto& e : entries)
        if (path == e.path) return Asset{std::string_view(e.begin, std::size_t(e.end - e.begin)), e.type};
    return std::nullopt;
}

void send_error(httplib::Response& response, int status, const std::string& message) {
    response.status = status;
    response.set_content(nlohmann::json{{"error", message}}.dump() + "\n", "application/json");
}

namespace {

std::string lower(std::string text) {
    for (char& c : text) c = char(std::tolower(static_cast<unsigned char>(c)));
    return text;
}

// The names this server answers to: loopback, on its own port.
bool loopback_host(const std::string& host, int port) {
    const std::string h = lower(host), p = ":" + std::to_string(port);
    return h == "127.0.0.1" + p || h == "localhost" + p || h == "[::1]" + p;
}

// Compares every byte whatever the first difference, so that the time taken does not tell how much of a guess was right.
bool same_secret(const std::string& a, const std::string& b) {
    if (a.size() != b.size()) return false;
    unsigned char differ = 0;
    for (std::size_t i = 0; i < a.size(); ++i) differ |= static_cast<unsigned char>(a[i] ^ b[i]);
    return differ == 0;
}

} // namespace

void guard(httplib::Server& server, const Gate& gate) {
    server.set_pre_routing_handler([&gate](const httplib::Request& request, httplib::Response& response) {
        using Answer = httplib::Server::HandlerResponse;
        if (!loopback_host(request.get_header_value("Host"), gate.port)) {
            send_error(response, 403, "request: Host must be 127.0.0.1:" + std::to_string(gate.port) + ", localhost:" + std::to_string(gate.port) +
                                          " or [::1]:" + std::to_string(gate.port));
            return Answer::Handled;
        }
        if (request.has_header("Origin")) {
            const std::string origin = lower(request.get_header_value("Origin"));
            if (origin.rfind("http://", 0) != 0 || !loopback_host(origin.substr(7), gate.port)) {
                send_error(response, 403, "request: cross-origin requests are refused");
                return Answer::Handled;
            }
        }
        if (!gate.token.empty() && request.path.rfind("/api/", 0) == 0 && !same_secret(request.get_header_value("X-Voxwarp-Token"), gate.token)) {
            send_error(response, 403, "request: missing or wrong X-Voxwarp-Token (the token is in the URL voxwarp printed)");
            return Answer::Handled;
        }
        return Answer::Unhandled;
    });
}

std::string random_token() {
    unsigned char bytes[16];
    std::size_t got = 0;
    while (got < sizeof bytes) {
        const ssize_t n = ::getrandom(bytes + got, sizeof bytes - got, 0);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) throw IOError(std::string("no random bytes for the session token: ") + std::strerror(errno));
        got += std::size_t(n);
    }
    static const char digits[] = "0123456789abcdef";
    std::string token;
    for (const unsigned char b : bytes) {
        token += digits[b >> 4];
        token += digits[b & 15];
    }
    return token;
}

void serve_assets(httplib::Server& server) {
    server.Get(R"(/.*)", [](const httplib::Request& request, httplib::Response& response) {
        if (const auto asset = find_asset(request.path)) {
            response.set_content(std::string(asset->data), asset->content_type);
            response.set_header("Cache-Control", "no-cache");
            return;
        }
        send_error(response, 404, "no such path: " + request.path);
    });
}

namespace {
/// A mesh as binary PLY for a page: with texture coordinates and colours when it has them (encode_mesh, which splits
/// a vertex on a seam), the plain geometry otherwise.
std::string page_ply(const TriangleMesh& mesh) {
    return mesh.triangle_uvs.empty() && mesh.colours.empty() ? encode_ply(mesh) : encode_mesh(mesh, ".ply");
}
} // namespace

void send_mesh(httplib::Response& response, const TriangleMesh& mesh) { response.set_content(page_ply(mesh), "application/ply"); }

void send_texture(httplib::Response& response, const std::string& bytes) {
    const bool jpeg = bytes.size() > 2 && static_cast<unsigned char>(bytes[0]) == 0xff && static_cast<unsigned char>(bytes[1]) == 0xd8;
    response.set_content(bytes, jpeg ? "image/jpeg" : "image/png");
}

std::string first_texture(const TriangleMesh& mesh) {
    if (mesh.triangle_uvs.empty()) return {};
    for (const auto& material : mesh.materials) {
        if (material.texture.empty()) continue;
        if (!material.texture_bytes.empty()) return material.texture_bytes;
        std::ifstream in(material.texture, std::ios::binary);
        std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        if (!bytes.empty()) return bytes;
    }
    return {};
}

std::string chromium_path() {
    if (const char* env = std::getenv("VOXWARP_CHROMIUM"); env && *env) return ::access(env, X_OK) == 0 ? env : "";
    for (const char* candidate : {"/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome"})
        if (::access(candidate, X_OK) == 0) return candidate;
    return {};
}

bool open_in_browser(const std::string& url) {
    if (::access("/usr/bin/xdg-open", X_OK) != 0 || !std::getenv("DISPLAY")) return false;
    const char* argv[] = {"xdg-open", url.c_str(), nullptr};
    pid_t pid = -1;
    return posix_spawn(&pid, "/usr/bin/xdg-open", nullptr, nullptr, const_cast<char* const*>(argv), environ) == 0;
}

Browser::Browser(const std::string& url, int width, int height) {
    const std::string chromium = chromium_path();
    if (chromium.empty())
        throw IOError(std::getenv("VOXWARP_CHROMIUM") ? std::string("VOXWARP_CHROMIUM=") + std::getenv("VOXWARP_CHROMIUM") + ": not an executable Chromium"
                                                     : "no Chromium to render with: install Debian's chromium (apt-get install chromium) or set VOXWARP_CHROMIUM");
    char profile_template[] = "/tmp/voxwarp-chromium-XXXXXX";
    if (!::mkdtemp(profile_template)) throw IOError("cannot make a temporary Chromium profile folder");
    profile_ = profile_template;
    log_ = profile_ + "/chromium.log";
    const std::vector<std::string> args{chromium,
                                        "--headless=new",
                                        "--no-sandbox",
                                        "--use-angle=swiftshader",
                                        "--enable-unsafe-swiftshader",
                                        "--ignore-gpu-blocklist",
                                        "--disable-background-networking",
                                        "--disable-component-update",
                                        "--disable-sync",
                                        "--disable-quic",
                                        "--no-first-run",
                                        "--no-default-browser-check",
                                        "--hide-scrollbars",
                                        "--user-data-dir=" + profile_,
                                        "--window-size=" + std::to_string(width) + "," + std::to_string(height),
                                        url};
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, 1, 2);
    posix_spawnattr_t attributes;
    posix_spawnattr_init(&attributes);
    posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETPGROUP);
    posix_spawnattr_setpgroup(&attributes, 0); // its own group: killed with its helpers
    const int status = posix_spawn(&pid_, chromium.c_str(), &actions, &attributes, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    posix_spawnattr_destroy(&attributes);
    if (status != 0) {
        pid_ = -1;
        throw IOError(chromium + ": cannot start: " + std::strerror(status));
    }
}

Browser::~Browser() {
    if (pid_ > 0) {
        ::kill(-pid_, SIGKILL);
        int status = 0;
        ::waitpid(pid_, &status, 0);
    }
    std::error_code ec;
    if (profile_.empty()) return;
    // Chromium keeps its singleton socket in a folder of its own under /tmp, linked from the profile; killed,
    // it cannot remove that folder itself.
    const auto socket = std::filesystem::read_symlink(std::filesystem::path(profile_) / "SingletonSocket", ec);
    if (!ec && socket.parent_path().filename().string().rfind("org.chromium.Chromium.", 0) == 0) std::filesystem::remove_all(socket.parent_path(), ec);
    std::filesystem::remove_all(profile_, ec);
}

bool Browser::running() const {
    if (pid_ <= 0) return false;
    int status = 0;
    return ::waitpid(pid_, &status, WNOHANG) == 0;
}

std::string Browser::log_tail() const {
    std::ifstream in(log_);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (text.size() > 600) text = text.substr(text.size() - 600);
    return text;
}

void render_png(const std::vector<TriangleMesh>& meshes, const std::vector<std::string>& labels, const RenderOptions& options, const std::string& output) {
    if (meshes.empty()) throw InvalidInput("render: no meshes");
    if (options.width < 16 || options.height < 16 || options.width > 8192 || options.height > 8192)
        throw InvalidInput("render: size " + std::to_string(options.width) + "x" + std::to_string(options.height) + " is outside 16..8192 per side");
    for (std::size_t i = 0; i < meshes.size(); ++i)
        if (meshes[i].face_count() == 0) throw InvalidInput("render: mesh " + std::to_string(i + 1) + " has no faces");
    // A mesh with texture coordinates and a textured material is shown with its (first) texture; vertex colours are
    // shown too. Both travel in the PLY (s t, red green blue), the texture's file beside it.
    std::vector<std::string> plys, textures;
    nlohmann::json config{{"width", options.width}, {"height", options.height}, {"azimuth", options.azimuth}, {"elevation", options.elevation}};
    config["meshes"] = nlohmann::json::array();
    for (std::size_t i = 0; i < meshes.size(); ++i) {
        const TriangleMesh& m = meshes[i];
        const std::string texture = first_texture(m);
        plys.push_back(page_ply(m));
        textures.push_back(texture);
        config["meshes"].push_back({{"label", i < labels.size() ? labels[i] : ""}, {"texture", !texture.empty()}, {"colours", !m.colours.empty()}});
    }

    std::mutex mutex;
    std::condition_variable done;
    std::string png, page_error;
    Gate gate{0, random_token()}; // the server is up for a moment, but any page the user has open could reach it
    httplib::Server server;
    guard(server, gate);
    server.Get("/api/render/config", [&](const httplib::Request&, httplib::Response& r) { r.set_content(config.dump(), "application/json"); });
    server.Get(R"(/api/render/mesh/(\d+))", [&](const httplib::Request& q, httplib::Response& r) {
        const std::size_t i = std::stoul(q.matches[1]);
        if (i >= plys.size()) return send_error(r, 404, "no mesh " + std::to_string(i));
        r.set_content(plys[i], "application/ply");
    });
    server.Get(R"(/api/render/texture/(\d+))", [&](const httplib::Request& q, httplib::Response& r) {
        const std::size_t i = std::stoul(q.matches[1]);
        if (i >= textures.size() || textures[i].empty()) return send_error(r, 404, "no texture " + std::to_string(i));
        send_texture(r, textures[i]);
    });
    server.Post("/api/render/png", [&](const httplib::Request& q, httplib::Response& r) {
        std::lock_guard lock(mutex);
        png = q.body;
        done.notify_all();
        r.set_content("{}", "application/json");
    });
    server.Post("/api/render/error", [&](const httplib::Request& q, httplib::Response& r) {
        std::lock_guard lock(mutex);
        page_error = q.body.empty() ? "unknown error" : q.body.substr(0, 400);
        done.notify_all();
        r.set_content("{}", "application/json");
    });
    serve_assets(server);
    const int port = server.bind_to_any_port("127.0.0.1");
    if (port <= 0) throw IOError("render: cannot listen on 127.0.0.1");
    gate.port = port;
    std::thread listener([&] { server.listen_after_bind(); });
    // stop() only stops a server that has started listening: wait for that first.
    for (int i = 0; i < 500 && !server.is_running(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    struct Stop { // whatever happens below, the server stops and its thread is joined
        httplib::Server& server;
        std::thread& thread;
        ~Stop() {
            server.stop();
            if (thread.joinable()) thread.join();
        }
    } stop{server, listener};
    std::string failure;
    {
        Browser browser("http://127.0.0.1:" + std::to_string(port) + "/render.html?token=" + gate.token, options.width, options.height);
        std::unique_lock lock(mutex);
        const auto deadline = std::chrono::steady_clock::now() + options.timeout;
        while (png.empty() && page_error.empty() && std::chrono::steady_clock::now() < deadline) {
            done.wait_for(lock, std::chrono::milliseconds(200));
            if (!browser.running()) break;
        }
        if (png.empty())
            failure = !page_error.empty() ? "render: the page failed: " + page_error
                                          : "render: no picture from Chromium within " + std::to_string(options.timeout.count()) + " s; it said: " + browser.log_tail();
    }
    if (!failure.empty()) throw IOError(failure);
    if (png.size() < 8 || png.compare(1, 3, "PNG") != 0) throw IOError("render: the page sent something that is not a PNG");
    write_file_atomically(output, png, "the picture");
}

} // namespace voxwarp::cli
