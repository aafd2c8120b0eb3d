#include <voxwarp/errors.h>
#include <voxwarp/surface_distance.h>

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <limits>
#include <numeric>
#include <random>

namespace voxwarp {

namespace surface_distance_internal {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Triangle = Kernel::Triangle_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, Iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;

std::vector<Triangle> cgal_triangles(const TriangleMesh& mesh) {
    TriangleMesh storage;
    const auto& faces = all_triangles(mesh, storage);
    std::vector<Triangle> out;
    out.reserve(faces.size());
    auto p = [&](std::int32_t i) { return Point(mesh.vertices[i].x(), mesh.vertices[i].y(), mesh.vertices[i].z()); };
    for (const auto& f : faces) {
        Triangle t(p(f[0]), p(f[1]), p(f[2]));
        if (!t.is_degenerate()) out.push_back(t);
    }
    return out;
}

std::vector<Eigen::Vector3d> sample(const TriangleMesh& mesh, const SurfaceDistanceOptions& options) {
    TriangleMesh storage;
    const auto& faces = all_triangles(mesh, storage);
    std::vector<Eigen::Vector3d> points;
    std::vector<char> used(mesh.vertices.size(), 0);
    for (const auto& f : faces)
        for (auto i : f) used[std::size_t(i)] = 1;
    for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
        if (used[i]) points.push_back(mesh.vertices[i]);
    std::vector<double> cumulative(faces.size());
    double total = 0;
    for (std::size_t i = 0; i < faces.size(); ++i) {
        const auto& f = faces[i];
        total += 0.5 * (mesh.vertices[f[1]] - mesh.vertices[f[0]]).cross(mesh.vertices[f[2]] - mesh.vertices[f[0]]).norm();
        cumulative[i] = total;
    }
    if (total <= 0) return points;
    std::mt19937_64 rng(options.seed);
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    for (std::size_t s = 0; s < options.samples; ++s) {
        const auto it = std::lower_bound(cumulative.begin(), cumulative.end(), uniform(rng) * total);
        const auto& f = faces[std::size_t(std::min<std::ptrdiff_t>(it - cumulative.begin(), std::ptrdiff_t(faces.size()) - 1))];
        double u = uniform(rng), v = uniform(rng);
        if (u + v > 1) u = 1 - u, v = 1 - v;
        points.push_back(mesh.vertices[f[0]] + u * (mesh.vertices[f[1]] - mesh.vertices[f[0]]) + v * (mesh.vertices[f[2]] - mesh.vertices[f[0]]));
    }
    return points;
}

std::vector<double> distances(const std::vector<Eigen::Vector3d>& points, const TriangleMesh& to) {
    const auto triangles = cgal_triangles(to);
    if (triangles.empty()) throw InvalidInput("surface distance: the mesh measured against has no non-degenerate faces");
    Tree tree(triangles.begin(), triangles.end());
    tree.accelerate_distance_queries();
    std::vector<double> d(points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 1024), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i)
            d[i] = std::sqrt(tree.squared_distance(Point(points[i].x(), points[i].y(), points[i].z())));
    });
    return d;
}

DistanceStats summarise(std::vector<double> d) {
    DistanceStats s;
    s.samples = d.size();
    if (d.empty()) return s;
    s.mean = std::accumulate(d.begin(), d.end(), 0.0) / double(d.size());
    const std::size_t k = std::min(d.size() - 1, std::size_t(0.99 * double(d.size())));
    std::nth_element(d.begin(), d.begin() + std::ptrdiff_t(k), d.end());
    s.p99 = d[k];
    s.max = *std::max_element(d.begin(), d.end());
    return s;
}

} // namespace surface_distance_internal

using namespace surface_distance_internal;

DistanceStats one_sided_distance(const TriangleMesh& from, const TriangleMesh& to, const SurfaceDistanceOptions& options) {
    if (from.face_count() == 0 || to.face_count() == 0) throw InvalidInput("surface distance: a mesh has no faces");
    return summarise(distances(sample(from, options), to));
}

DistanceStats symmetric_distance(const TriangleMesh& a, const TriangleMesh& b, const SurfaceDistanceOptions& options) {
    if (a.face_count() == 0 || b.face_count() == 0) throw InvalidInput("surface distance: a mesh has no faces");
    auto d = distances(sample(a, options), b);
    auto e = distances(sample(b, options), a);
    d.insert(d.end(), e.begin(), e.end());
    return summarise(std::move(d));
}

} // namespace voxwarp

#include <numbers>
#include <unordered_map>

namespace voxwarp {

std::vector<double> distances_to_surface(const std::vector<Eigen::Vector3d>& points, const TriangleMesh& mesh) {
    return surface_distance_internal::distances(points, mesh);
}

std::vector<double> distances_to_surface_within(const std::vector<Eigen::Vector3d>& points, const TriangleMesh& mesh, double radius) {
    using namespace surface_distance_internal;
    TriangleMesh storage;
    const auto& faces = all_triangles(mesh, storage);
    std::vector<double> out;
    for (const auto& q : points) {
        const Eigen::Vector3d lo = q.array() - radius, hi = q.array() + radius;
        const double best = tbb::parallel_reduce(
            tbb::blocked_range<std::size_t>(0, faces.size(), 4096), std::numeric_limits<double>::infinity(),
            [&](const tbb::blocked_range<std::size_t>& r, double nearest) {
                const Point query(q.x(), q.y(), q.z());
                for (std::size_t f = r.begin(); f != r.end(); ++f) {
                    const Eigen::Vector3d &a = mesh.vertices[std::size_t(faces[f][0])], &b = mesh.vertices[std::size_t(faces[f][1])],
                                          &c = mesh.vertices[std::size_t(faces[f][2])];
                    if (((a.cwiseMin(b).cwiseMin(c)).array() > hi.array()).any() || ((a.cwiseMax(b).cwiseMax(c)).array() < lo.array()).any()) continue;
                    const Triangle t(Point(a.x(), a.y(), a.z()), Point(b.x(), b.y(), b.z()), Point(c.x(), c.y(), c.z()));
                    if (t.is_degenerate()) continue;
                    nearest = std::min(nearest, std::sqrt(CGAL::to_double(CGAL::squared_distance(query, t))));
                }
                return nearest;
            },
            [](double x, double y) { return std::min(x, y); });
        out.push_back(best <= radius ? best : std::numeric_limits<double>::infinity());
    }
    return out;
}

CreaseStats count_creases(const TriangleMesh& mesh, double threshold_degrees) {
    TriangleMesh storage;
    const auto& tris = all_triangles(mesh, storage);
    std::unordered_map<std::uint64_t, std::vector<std::size_t>> edge_faces;
    for (std::size_t f = 0; f < tris.size(); ++f)
        for (int c = 0; c < 3; ++c) {
            const auto a = std::uint32_t(tris[f][std::size_t(c)]), b = std::uint32_t(tris[f][std::size_t((c + 1) % 3)]);
            edge_faces[(std::uint64_t(std::min(a, b)) << 32) | std::max(a, b)].push_back(f);
        }
    auto normal = [&](std::size_t f) {
        const auto& t = tris[f];
        return Eigen::Vector3d((mesh.vertices[t[1]] - mesh.vertices[t[0]]).cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]).normalized());
    };
    const double cos_threshold = std::cos(threshold_degrees * std::numbers::pi / 180.0);
    CreaseStats stats;
    for (const auto& [key, faces] : edge_faces) {
        if (faces.size() != 2) continue;
        ++stats.edges;
        if (normal(faces[0]).dot(normal(faces[1])) < cos_threshold) ++stats.creased;
    }
    return stats;
}

} // namespace voxwarp
