#include <voxwarp/openvdb_baseline.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/VolumeToMesh.h>

namespace voxwarp {

TriangleMesh openvdb_round_trip(const TriangleMesh& mesh, int resolution) {
    openvdb::initialize();
    const double h = bounds(mesh).size().maxCoeff() / resolution;
    auto xform = openvdb::math::Transform::createLinearTransform(h);
    std::vector<openvdb::Vec3s> points;
    for (const auto& v : mesh.vertices) points.emplace_back(float(v.x()), float(v.y()), float(v.z()));
    std::vector<openvdb::Vec3I> tris;
    for (const auto& t : mesh.triangles) tris.emplace_back(openvdb::Index32(t[0]), openvdb::Index32(t[1]), openvdb::Index32(t[2]));
    auto grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xform, points, tris, 3.0f);
    std::vector<openvdb::Vec3s> out_points;
    std::vector<openvdb::Vec3I> out_tris;
    std::vector<openvdb::Vec4I> out_quads;
    openvdb::tools::volumeToMesh(*grid, out_points, out_tris, out_quads, 0.0, 0.0);
    TriangleMesh out;
    for (const auto& p : out_points) out.vertices.emplace_back(p[0], p[1], p[2]);
    for (const auto& t : out_tris) out.triangles.push_back({std::int32_t(t[0]), std::int32_t(t[1]), std::int32_t(t[2])});
    for (const auto& q : out_quads) out.quads.push_back({std::int32_t(q[0]), std::int32_t(q[1]), std::int32_t(q[2]), std::int32_t(q[3])});
    return out.triangulated();
}

} // namespace voxwarp
