/// @file web.h
/// @brief What `voxwarp edit` and `voxwarp render` share: the page's files (embedded at build time, three.js from
///        Debian's libjs-three), a local HTTP server (cpp-httplib, bound to 127.0.0.1), headless Chromium.
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <httplib.h>

#include <chrono>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace voxwarp::cli {

/// An embedded file of web/ (or three.js) by its URL path ("/" is /index.html); nullopt if there is none.
struct Asset {
    std::string_view data;
    const char* content_type;
};
std::optional<Asset> find_asset(const std::string& path);

/// Who a local server lets in. Every request must name the server by a loopback `Host` (127.0.0.1, localhost or
/// [::1], with `port`), so that a page of another site, resolved to 127.0.0.1 by DNS rebinding, is refused; a
/// request that carries an `Origin` must come from the server's own page (a cross-site form or fetch is refused);
/// and, when `token` is not empty, every /api/ request must carry it in the `X-Voxwarp-Token` header, which only
/// a page the server itself handed the token to (in its URL) can know. Refusals answer 403 before any work.
struct Gate {
    int port = 0;      ///< set once the server is bound
    std::string token; ///< empty: no token asked for
};

/// Install `gate` (which must outlive `server`) in front of every route: a pre-routing handler.
void guard(httplib::Server& server, const Gate& gate);

/// A fresh token: 128 random bits from the system's entropy source, as 32 hex digits. @throw IOError when there is none.
std::string random_token();

/// Serve every embedded file (GET) and answer other GETs with 404.
void serve_assets(httplib::Server& server);

/// Mesh as the body of a response: binary PLY, Content-Type application/ply; with its texture coordinates (s t, a
/// vertex on a seam once per side) and vertex colours (red green blue) when it has them.
void send_mesh(httplib::Response& response, const TriangleMesh& mesh);

/// The bytes of the first texture of a mesh with texture coordinates (its first material's that has one, read from
/// its file or carried embedded); empty when there is none or it cannot be read.
std::string first_texture(const TriangleMesh& mesh);

/// A texture's bytes as the body of a response: image/jpeg or image/png, by its first bytes.
void send_texture(httplib::Response& response, const std::string& bytes);

/// An error response: {"error": message} with `status`.
void send_error(httplib::Response& response, int status, const std::string& message);

/// Headless Chromium showing `url` in a window of width x height (Debian's chromium, or $VOXWARP_CHROMIUM), run
/// with SwiftShader's WebGL and a throw-away profile, in its own process group: the destructor kills it and
/// its helpers. @throw IOError when no Chromium is installed or it cannot start.
class Browser {
public:
    Browser(const std::string& url, int width, int height);
    ~Browser();
    Browser(const Browser&) = delete;
    Browser& operator=(const Browser&) = delete;
    /// The tail of what Chromium printed, for error messages.
    std::string log_tail() const;
    /// Whether the browser process is still running.
    bool running() const;

private:
    int pid_ = -1;
    std::string profile_, log_;
};

/// Path of the Chromium the command uses; empty when there is none.
std::string chromium_path();

/// Open `url` in the user's own browser (xdg-open), without waiting; false when there is none to open.
bool open_in_browser(const std::string& url);

/// Options for render_png.
struct RenderOptions {
    int width = 1200, height = 600;      ///< the whole picture, pixels; each mesh gets an equal share of the width
    double azimuth = 30, elevation = 20; ///< view direction, degrees: azimuth about +y from +z, elevation above
    std::chrono::seconds timeout{90};
};

/// Shaded picture of the meshes side by side under one camera (the union of their bounds framed), labelled, as
/// a PNG written atomically to `output`. Rendered by three.js in headless Chromium, served from this process.
/// @throw InvalidInput for no meshes or a bad size; IOError when Chromium is missing, fails or times out.
void render_png(const std::vector<TriangleMesh>& meshes, const std::vector<std::string>& labels, const RenderOptions& options, const std::string& output);

} // namespace voxwarp::cli
