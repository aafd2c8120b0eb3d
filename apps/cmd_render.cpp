#include "cli_common.h"
#include "web.h"

#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include <filesystem>
#include <memory>

namespace voxwarp::cli {

namespace {

struct RenderArgs {
    std::vector<std::string> inputs, labels;
    std::string output, view = "30,20", size = "1200x600";
    int timeout = 90;
};

/// "AZ,EL" in degrees.
void parse_view(const std::string& text, RenderOptions& o) {
    double az = 0, el = 0;
    char comma = 0;
    std::istringstream in(text);
    if (!(in >> az >> comma >> el) || comma != ',' || !in.eof() || !std::isfinite(az) || !std::isfinite(el) || el < -90 || el > 90)
        throw InvalidInput("--view " + text + ": expected AZIMUTH,ELEVATION in degrees, elevation in [-90, 90]");
    o.azimuth = az, o.elevation = el;
}

/// "WxH" in pixels.
void parse_size(const std::string& text, RenderOptions& o) {
    int w = 0, h = 0;
    char x = 0;
    std::istringstream in(text);
    if (!(in >> w >> x >> h) || (x != 'x' && x != 'X') || !in.eof() || w < 16 || h < 16 || w > 8192 || h > 8192)
        throw InvalidInput("--size " + text + ": expected WIDTHxHEIGHT in pixels, 16..8192 each");
    o.width = w, o.height = h;
}

} // namespace

void add_render(CLI::App& app, Global& global, Action& action) {
    auto a = std::make_shared<RenderArgs>();
    auto* cmd = app.add_subcommand("render", "Shaded PNG of one or more meshes side by side under one camera (three.js in headless Chromium)");
    cmd->add_option("meshes", a->inputs, "Meshes to show, left to right (.obj .off .ply .stl .om .gltf .glb)")->required();
    cmd->add_option("-o,--output", a->output, "Output picture (.png)")->required();
    cmd->add_option("--view", a->view, "View direction AZIMUTH,ELEVATION in degrees (azimuth about +y from +z)")->capture_default_str();
    cmd->add_option("--size", a->size, "Picture size WIDTHxHEIGHT in pixels")->capture_default_str();
    cmd->add_option("--labels", a->labels, "One label per mesh (default: the file names)")->delimiter(',');
    cmd->add_option("--timeout", a->timeout, "Seconds to wait for Chromium")->check(CLI::Range(5, 3600))->capture_default_str();
    cmd->callback([a, &global, &action] {
        action = [a, &global] {
            if (std::filesystem::path(a->output).extension() != ".png") throw InvalidInput(a->output + ": expected a .png output");
            RenderOptions o;
            parse_view(a->view, o);
            parse_size(a->size, o);
            o.timeout = std::chrono::seconds(a->timeout);
            if (!a->labels.empty() && a->labels.size() != a->inputs.size())
                throw InvalidInput("--labels: " + std::to_string(a->labels.size()) + " labels for " + std::to_string(a->inputs.size()) + " meshes");
            std::vector<TriangleMesh> meshes;
            std::vector<std::string> labels = a->labels;
            for (const auto& path : a->inputs) {
                meshes.push_back(read_mesh(path));
                if (a->labels.empty()) labels.push_back(std::filesystem::path(path).filename().string());
            }
            render_png(meshes, labels, o, a->output);
            note(global, "wrote " + a->output);
        };
    });
}

} // namespace voxwarp::cli
