#include <voxwarp/errors.h>
#include <voxwarp/extract.h>
#include <voxwarp_internal/vdb_convert.h>

#include "features.h"
#include "marching_cubes.h"

#include <openvdb/tools/VolumeToMesh.h>

#include <algorithm>
#include <cctype>
#include <string>

namespace voxwarp {

namespace {

void check(const ExtractOptions& options) {
    if (!(options.isovalue > 0 && options.isovalue < 1))
        throw InvalidInput("extract: isovalue " + std::to_string(options.isovalue) + " is outside (0, 1)");
    if (!(options.feature_angle > 0 && options.feature_angle < 180))
        throw InvalidInput("extract: feature angle " + std::to_string(options.feature_angle) + " is outside (0, 180) degrees");
    if (!(options.adaptivity >= 0 && options.adaptivity <= 1))
        throw InvalidInput("extract: adaptivity " + std::to_string(options.adaptivity) + " is outside [0, 1]");
}

TriangleMesh extract_grid(const openvdb::FloatGrid::Ptr& grid, const ExtractOptions& options, Progress& progress) {
    progress.report(0.3);

    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> triangles;
    std::vector<openvdb::Vec4I> quads;
    openvdb::tools::volumeToMesh(*grid, points, triangles, quads, options.isovalue, options.adaptivity);
    progress.report(0.9);

    // OpenVDB counts values below the isovalue as inside (level-set convention); for density, inside is
    // above it, so every face comes out wound inwards: reverse them.
    TriangleMesh mesh;
    mesh.vertices.resize(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) mesh.vertices[i] = Eigen::Vector3d(points[i][0], points[i][1], points[i][2]);
    mesh.triangles.reserve(triangles.size());
    for (const auto& t : triangles) mesh.triangles.push_back({std::int32_t(t[0]), std::int32_t(t[2]), std::int32_t(t[1])});
    mesh.quads.reserve(quads.size());
    for (const auto& q : quads) mesh.quads.push_back({std::int32_t(q[0]), std::int32_t(q[3]), std::int32_t(q[2]), std::int32_t(q[1])});
    if (!options.quads) mesh = mesh.triangulated();
    progress.report(1.0);
    return mesh;
}

} // namespace

Mesher parse_mesher(const std::string& name) {
    std::string lower = name;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (lower == "mc") return Mesher::marching_cubes;
    if (lower == "features") return Mesher::features;
    throw InvalidInput("mesher: expected \"mc\" or \"features\", got \"" + name + "\"");
}

TriangleMesh extract(const Voxmap& voxmap, const ExtractOptions& options) {
    check(options);
    return extract(to_sparse(voxmap), options);
}

TriangleMesh extract(const SparseVoxmap& voxmap, const ExtractOptions& options) {
    check(options);
    Progress progress(options.progress, "extract");
    progress.report(0.0);
    if (options.adaptivity == 0 && !options.quads) {
        std::vector<extract_internal::MarchingBlock> blocks;
        TriangleMesh mesh = extract_internal::marching_cubes(voxmap, float(options.isovalue), progress, options.mesher == Mesher::features ? &blocks : nullptr);
        if (options.mesher == Mesher::features) return extract_internal::restore_features(std::move(mesh), voxmap, options, blocks);
        return mesh; // moved, with its spare capacity (a conditional expression would copy it)
    }
    openvdb::initialize();
    // Meshed in index space, the points (32-bit floats) then put in the world as doubles: a world-space grid would
    // round the points of a voxmap far from the origin, and OpenVDB refuses a transform for a voxel under 1.45e-5.
    TriangleMesh mesh = extract_grid(vdb_internal::to_density_grid(voxmap, true), options, progress);
    for (auto& v : mesh.vertices) v = voxmap.world(v.x(), v.y(), v.z());
    return mesh;
}

std::vector<Eigen::Vector3d> off_grid_vertices(const TriangleMesh& mesh, const SparseVoxmap& voxmap) {
    const std::vector<std::uint32_t> off =
        extract_internal::select_in_parallel(mesh.vertices.size(), [&](std::size_t v) { return !extract_internal::on_grid_edge(voxmap, mesh.vertices[v]); });
    std::vector<Eigen::Vector3d> points(off.size());
    for (std::size_t i = 0; i < off.size(); ++i) points[i] = mesh.vertices[off[i]];
    return points;
}

} // namespace voxwarp
