/// @file test_helpers.h
/// @brief Shared fixtures: analytic shapes as fine meshes with their exact distance functions, data paths.
#pragma once

#include <voxwarp/deform.h>
#include <voxwarp/edit_file.h>
#include <voxwarp/mesh_io.h>
#include <voxwarp/triangle_mesh.h>
#include <voxwarp_internal/geometry.h>

#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numbers>
#include <string>
#include <utility>

namespace voxwarp::test {

inline std::string data_path(const std::string& name) { return std::string(VOXWARP_DATA_DIR) + "/" + name; }

/// Icosphere: an icosahedron subdivided `levels` times and projected onto the sphere.
inline TriangleMesh sphere_mesh(const Eigen::Vector3d& centre, double radius, int levels) {
    const double t = (1.0 + std::sqrt(5.0)) / 2.0;
    TriangleMesh m;
    for (auto v : {Eigen::Vector3d(-1, t, 0), Eigen::Vector3d(1, t, 0), Eigen::Vector3d(-1, -t, 0), Eigen::Vector3d(1, -t, 0),
                   Eigen::Vector3d(0, -1, t), Eigen::Vector3d(0, 1, t), Eigen::Vector3d(0, -1, -t), Eigen::Vector3d(0, 1, -t),
                   Eigen::Vector3d(t, 0, -1), Eigen::Vector3d(t, 0, 1), Eigen::Vector3d(-t, 0, -1), Eigen::Vector3d(-t, 0, 1)})
        m.vertices.push_back(v.normalized());
    m.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                   {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},   {4, 9, 5}, {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
    for (int l = 0; l < levels; ++l) {
        std::map<std::pair<int, int>, int> mid;
        auto midpoint = [&](int a, int b) {
            auto key = std::minmax(a, b);
            auto it = mid.find(key);
            if (it != mid.end()) return it->second;
            m.vertices.push_back((m.vertices[a] + m.vertices[b]).normalized());
            return mid[key] = int(m.vertices.size() - 1);
        };
        std::vector<std::array<std::int32_t, 3>> next;
        for (const auto& f : m.triangles) {
            const int a = midpoint(f[0], f[1]), b = midpoint(f[1], f[2]), c = midpoint(f[2], f[0]);
            next.push_back({f[0], a, c});
            next.push_back({f[1], b, a});
            next.push_back({f[2], c, b});
            next.push_back({a, b, c});
        }
        m.triangles = std::move(next);
    }
    for (auto& v : m.vertices) v = centre + radius * v;
    return m;
}

/// Torus around the z axis: major radius R, minor radius r, nu x nv quads split into triangles.
inline TriangleMesh torus_mesh(const Eigen::Vector3d& centre, double R, double r, int nu, int nv) {
    TriangleMesh m;
    for (int i = 0; i < nu; ++i)
        for (int j = 0; j < nv; ++j) {
            const double u = 2 * std::numbers::pi * i / nu, v = 2 * std::numbers::pi * j / nv;
            m.vertices.push_back(centre + Eigen::Vector3d((R + r * std::cos(v)) * std::cos(u), (R + r * std::cos(v)) * std::sin(u), r * std::sin(v)));
        }
    auto id = [&](int i, int j) { return std::int32_t(((i + nu) % nu) * nv + (j + nv) % nv); };
    for (int i = 0; i < nu; ++i)
        for (int j = 0; j < nv; ++j) {
            m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
            m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
        }
    return m;
}

inline double torus_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& centre, double R, double r) {
    const Eigen::Vector3d q = p - centre;
    return std::hypot(std::hypot(q.x(), q.y()) - R, q.z()) - r;
}

/// A prism: the counter-clockwise polygon `outline` (in x, y; every vertex seen from its first, so a fan from it
/// covers it) extruded from z = 0 to `height`, faces wound outwards.
inline TriangleMesh prism_mesh(const std::vector<Eigen::Vector2d>& outline, double height) {
    TriangleMesh m;
    const int n = int(outline.size());
    for (double z : {0.0, height})
        for (const auto& p : outline) m.vertices.emplace_back(p.x(), p.y(), z);
    for (int i = 1; i + 1 < n; ++i) {
        m.triangles.push_back({0, i + 1, i});          // bottom, seen from below
        m.triangles.push_back({n, n + i, n + i + 1});  // top
    }
    for (int i = 0; i < n; ++i) {
        const int j = (i + 1) % n;
        m.triangles.push_back({i, j, n + j});
        m.triangles.push_back({i, n + j, n + i});
    }
    return m;
}

/// A regular polygon's outline (radius 1, `sides` corners), counter-clockwise.
inline std::vector<Eigen::Vector2d> regular_polygon(int sides) {
    std::vector<Eigen::Vector2d> out;
    for (int i = 0; i < sides; ++i) out.emplace_back(std::cos(2 * M_PI * i / sides), std::sin(2 * M_PI * i / sides));
    return out;
}

/// A regular tetrahedron (edge 2 sqrt 2) and a regular octahedron (corners at distance 1 on the axes), faces
/// wound outwards.
inline TriangleMesh tetrahedron_mesh() {
    TriangleMesh m;
    m.vertices = {{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}};
    m.triangles = {{0, 1, 2}, {0, 3, 1}, {0, 2, 3}, {1, 3, 2}};
    return m;
}
inline TriangleMesh octahedron_mesh() {
    TriangleMesh m;
    m.vertices = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    m.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
    return m;
}

/// Sharp shapes with their names, as the feature mesher's tests turn them off the grid: obtuse edges (a hexagonal
/// prism), a curved edge (a 24-gon prism's rims), corners where four faces meet (an octahedron), a concave edge (an
/// L-shaped block), and acute ones (a triangular prism, a tetrahedron).
inline std::vector<std::pair<std::string, TriangleMesh>> sharp_polyhedra() {
    return {
        {"hexagonal prism", prism_mesh(regular_polygon(6), 0.8)},
        {"24-gon prism", prism_mesh(regular_polygon(24), 1.0)},
        {"octahedron", octahedron_mesh()},
        {"L block", prism_mesh({{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}}, 0.7)},
        {"triangular prism", prism_mesh(regular_polygon(3), 1.2)},
        {"tetrahedron", tetrahedron_mesh()},
    };
}

/// A turn by a radians about z, then b about x, then c about y (applied to a point: y first).
inline Eigen::Matrix3d turn_zxy(double a, double b, double c) {
    return (Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(b, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(c, Eigen::Vector3d::UnitY()))
        .toRotationMatrix();
}

/// Axis-aligned box [lo, hi], each face an n x n grid of quads split into triangles, outward oriented.
inline TriangleMesh box_mesh(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, int n) {
    TriangleMesh m;
    std::map<std::array<int, 3>, int> ids;
    auto vertex = [&](std::array<int, 3> g) {
        auto it = ids.find(g);
        if (it != ids.end()) return it->second;
        Eigen::Vector3d p;
        for (int a = 0; a < 3; ++a) p[a] = lo[a] + (hi[a] - lo[a]) * g[std::size_t(a)] / n;
        m.vertices.push_back(p);
        return ids[g] = int(m.vertices.size() - 1);
    };
    for (int axis = 0; axis < 3; ++axis)
        for (int side = 0; side < 2; ++side) {
            const int u = (axis + 1) % 3, v = (axis + 2) % 3;
            for (int i = 0; i < n; ++i)
                for (int j = 0; j < n; ++j) {
                    auto g = [&](int di, int dj) {
                        std::array<int, 3> c{};
                        c[std::size_t(axis)] = side * n;
                        c[std::size_t(u)] = i + di;
                        c[std::size_t(v)] = j + dj;
                        return vertex(c);
                    };
                    const int a = g(0, 0), b = g(1, 0), c = g(1, 1), d = g(0, 1);
                    if (side == 1) {
                        m.triangles.push_back({a, b, c});
                        m.triangles.push_back({a, c, d});
                    } else {
                        m.triangles.push_back({a, c, b});
                        m.triangles.push_back({a, d, c});
                    }
                }
        }
    return m;
}

/// Two meshes in one (b's vertices renumbered after a's).
inline TriangleMesh joined(TriangleMesh a, const TriangleMesh& b) {
    const auto offset = std::int32_t(a.vertices.size());
    a.vertices.insert(a.vertices.end(), b.vertices.begin(), b.vertices.end());
    for (auto t : b.triangles) a.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
    return a;
}

/// The mesh facing the other way (each triangle's winding reversed): a cavity's walls, from a closed mesh.
inline TriangleMesh inverted(TriangleMesh m) {
    for (auto& t : m.triangles) std::swap(t[1], t[2]);
    return m;
}

/// Split every triangle into four until no edge is longer than `longest`: the vertex FFD of the result follows
/// the map between the input's vertices.
inline TriangleMesh subdivided(TriangleMesh m, double longest) {
    for (;;) {
        double worst = 0;
        for (const auto& t : m.triangles)
            for (int e = 0; e < 3; ++e) worst = std::max(worst, (m.vertices[std::size_t(t[std::size_t(e)])] - m.vertices[std::size_t(t[std::size_t((e + 1) % 3)])]).norm());
        if (worst <= longest) return m;
        std::map<std::pair<std::int32_t, std::int32_t>, std::int32_t> middle;
        auto midpoint = [&](std::int32_t a, std::int32_t b) {
            const auto key = std::minmax(a, b);
            if (const auto it = middle.find(key); it != middle.end()) return it->second;
            m.vertices.push_back(0.5 * (m.vertices[std::size_t(a)] + m.vertices[std::size_t(b)]));
            return middle[key] = std::int32_t(m.vertices.size() - 1);
        };
        std::vector<std::array<std::int32_t, 3>> finer;
        for (const auto t : m.triangles) {
            const std::int32_t a = midpoint(t[0], t[1]), b = midpoint(t[1], t[2]), c = midpoint(t[2], t[0]);
            finer.insert(finer.end(), {{t[0], a, c}, {a, t[1], b}, {c, b, t[2]}, {a, b, c}});
        }
        m.triangles = std::move(finer);
    }
}

/// A bundled mesh deformed by a bundled edit file at `resolution` (snapped, the CLI's defaults), and the exact warp
/// the geometry tests measure it against: the same lattice map on the mesh's vertices after its edges were split
/// under `edge_voxels` voxels, so that the vertex FFD follows the map between them.
struct DeformedAndExact {
    TriangleMesh out, exact;
    DeformReport report;
    double h = 0; ///< the voxmap's voxel size
};
inline DeformedAndExact deform_with_exact_warp(const std::string& mesh, const std::string& edit, int resolution, double edge_voxels = 1.0) {
    const TriangleMesh input = read_mesh(data_path(mesh));
    const EditScript script = read_edit_file(data_path(edit));
    DeformOptions options;
    options.voxelize.resolution = resolution;
    DeformedAndExact r;
    r.out = deform_mesh(input, script, options, r.report);
    r.h = r.report.voxel_size;
    DeformReport exact_report;
    r.exact = deform_vertices(subdivided(input, edge_voxels * r.h), script, options, exact_report);
    return r;
}

/// Output triangles that face against the input's surface: against the normal of every input face within half a
/// voxel of their centre (of the nearest face where none is that near), so that a triangle on a sharp edge may
/// face along either side. An in-plane fold faces straight against its face. Triangles under a millionth of a
/// square voxel (two marching-cubes crossings a millionth of a voxel apart) have no direction a renderer shows, and
/// are not counted. Brute force over the input's faces: for the polyhedra of these tests.
inline std::size_t facing_against(const TriangleMesh& out, const TriangleMesh& input, double h) {
    std::size_t count = 0;
    for (const auto& t : out.triangles) {
        const Eigen::Vector3d &a = out.vertices[std::size_t(t[0])], &b = out.vertices[std::size_t(t[1])], &c = out.vertices[std::size_t(t[2])];
        const Eigen::Vector3d n = (b - a).cross(c - a);
        if (0.5 * n.norm() < 1e-6 * h * h) continue;
        const Eigen::Vector3d centre = (a + b + c) / 3;
        bool along_any = false, near_any = false;
        double nearest = std::numeric_limits<double>::infinity();
        bool along_nearest = false;
        for (const auto& f : input.triangles) {
            const Eigen::Vector3d &p = input.vertices[std::size_t(f[0])], &q = input.vertices[std::size_t(f[1])], &r = input.vertices[std::size_t(f[2])];
            const double d = (internal::closest_on_triangle(centre, p, q, r) - centre).norm();
            const bool along = n.dot((q - p).cross(r - p)) > 0;
            if (d <= 0.5 * h) near_any = true, along_any |= along;
            if (d < nearest) nearest = d, along_nearest = along;
        }
        if (near_any ? !along_any : !along_nearest) ++count;
    }
    return count;
}

using Map = std::function<Eigen::Vector3d(const Eigen::Vector3d&)>;

/// A box of length `length` along x (centred on the origin) and cross-section `width` x `width`.
struct Bar {
    double length, width;
    Eigen::Vector3d lo() const { return {-length / 2, -width / 2, -width / 2}; }
    Eigen::Vector3d hi() const { return {length / 2, width / 2, width / 2}; }
    /// The bar bent by `angle` into a circular arc in the x-y plane, towards +y, its centre line keeping its
    /// length, cross-sections staying planar and square to it; the end x = -length/2 stays put.
    Map bend(double angle) const {
        const double R = length / angle, L = length;
        return [=](const Eigen::Vector3d& p) {
            const double theta = (p.x() + L / 2) / R;
            return Eigen::Vector3d(-L / 2 + (R - p.y()) * std::sin(theta), R - (R - p.y()) * std::cos(theta), p.z());
        };
    }
    /// The bar twisted about its axis: cross-section x turned by angle * (x + length/2) / length.
    Map twist(double angle) const {
        const double L = length;
        return [=](const Eigen::Vector3d& p) {
            const double theta = angle * (p.x() + L / 2) / L;
            return Eigen::Vector3d(p.x(), p.y() * std::cos(theta) - p.z() * std::sin(theta), p.y() * std::sin(theta) + p.z() * std::cos(theta));
        };
    }
    /// Pins at the corners and centre of the end x = -length/2, moves of the other end's corners and centre to
    /// where `map` takes them.
    /// (Constraints named as an edit file would name them.)
    Edit end_constraints(const Map& map, Solver solver) const {
        Edit edit;
        edit.solver = solver;
        int id = 0;
        for (double x : {-length / 2, length / 2})
            for (const Eigen::Vector3d& yz : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, -1, -1), Eigen::Vector3d(0, 1, -1), Eigen::Vector3d(0, 1, 1),
                                             Eigen::Vector3d(0, -1, 1)}) {
                Constraint c;
                c.point = Eigen::Vector3d(x, 0, 0) + yz * (width / 2);
                c.name = "edits[0].constraints[" + std::to_string(id++) + "]";
                if (x < 0) {
                    c.kind = ConstraintKind::pin, c.to = c.point;
                } else {
                    c.kind = ConstraintKind::move, c.to = map(c.point);
                }
                edit.constraints.push_back(c);
            }
        return edit;
    }
    /// The exact answer: a finely tessellated box mapped through `map`.
    TriangleMesh exact(const Map& map, int n) const {
        TriangleMesh m = box_mesh(lo(), hi(), n);
        for (auto& v : m.vertices) v = map(v);
        return m;
    }
};

} // namespace voxwarp::test
