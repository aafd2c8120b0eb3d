#include <voxwarp/decimate.h>
#include <voxwarp/errors.h>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>

#include <string>

namespace voxwarp {

TriangleMesh decimate(const TriangleMesh& input, std::size_t target_faces) {
    if (target_faces < 4) throw InvalidInput("decimate: target of " + std::to_string(target_faces) + " faces is below 4");
    TriangleMesh storage;
    const auto& triangles = all_triangles(input, storage);
    if (triangles.size() <= target_faces) return input.quads.empty() ? input : storage;

    using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
    using Mesh = CGAL::Surface_mesh<Kernel::Point_3>;
    Mesh mesh;
    std::vector<Mesh::Vertex_index> vertex;
    vertex.reserve(input.vertices.size());
    for (const auto& v : input.vertices) vertex.push_back(mesh.add_vertex(Kernel::Point_3(v.x(), v.y(), v.z())));
    for (const auto& t : triangles)
        if (mesh.add_face(vertex[std::size_t(t[0])], vertex[std::size_t(t[1])], vertex[std::size_t(t[2])]) == Mesh::null_face())
            throw InvalidInput("decimate: the mesh is not a 2-manifold (a face could not be added)");

    // A closed triangle mesh has 3F/2 edges: stopping at that many edges leaves about target_faces faces.
    CGAL::Surface_mesh_simplification::Count_stop_predicate<Mesh> stop(3 * target_faces / 2);
    CGAL::Surface_mesh_simplification::edge_collapse(mesh, stop);
    mesh.collect_garbage();

    TriangleMesh out;
    out.vertices.reserve(mesh.number_of_vertices());
    for (auto v : mesh.vertices()) {
        const auto& p = mesh.point(v);
        out.vertices.emplace_back(p.x(), p.y(), p.z());
    }
    for (auto f : mesh.faces()) {
        std::array<std::int32_t, 3> t{};
        int c = 0;
        for (auto v : CGAL::vertices_around_face(mesh.halfedge(f), mesh)) t[std::size_t(c++)] = std::int32_t(v.idx());
        out.triangles.push_back(t);
    }
    return out;
}

} // namespace voxwarp
