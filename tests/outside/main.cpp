// Deform a sphere made here through an installed voxwarp: the move lands, the output is closed.
#include <voxwarp/deform.h>
#include <voxwarp/errors.h>

#include <cmath>
#include <cstdio>

int main() {
    voxwarp::TriangleMesh sphere;
    const int n = 24;
    for (int i = 0; i <= n; ++i)
        for (int j = 0; j < 2 * n; ++j) {
            const double t = M_PI * i / n, p = M_PI * j / n;
            sphere.vertices.emplace_back(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t));
        }
    auto id = [&](int i, int j) { return std::int32_t(i * 2 * n + (j % (2 * n))); };
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < 2 * n; ++j) {
            if (i > 0) sphere.triangles.push_back({id(i, j), id(i + 1, j), id(i, j + 1)});
            if (i + 1 < n) sphere.triangles.push_back({id(i, j + 1), id(i + 1, j), id(i + 1, j + 1)});
        }
    const voxwarp::EditScript script = voxwarp::parse_edit_script(
        R"({"edits": [{"solver": "rigid", "constraints": [{"move": [0, 0, 1], "to": [0, 0.3, 1.2]}, {"pin": [0, 0, -1]}]}]})", "outside");
    voxwarp::DeformOptions options;
    options.voxelize.resolution = 48;
    voxwarp::DeformReport report;
    try {
        const voxwarp::TriangleMesh out = voxwarp::deform_mesh(sphere, script, options, report);
        const voxwarp::MeshTopology t = voxwarp::topology(out);
        std::printf("outside: %zu faces, closed %d, volume %.4f -> %.4f\n", out.face_count(), int(t.watertight()), report.volume_before, report.volume_after);
        return t.watertight() && out.face_count() > 1000 ? 0 : 1;
    } catch (const voxwarp::Error& e) {
        std::fprintf(stderr, "outside: %s\n", e.what());
        return 1;
    }
}
