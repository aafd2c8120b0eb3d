#include <voxwarp/errors.h>
#include <voxwarp/transfer.h>
#include <voxwarp_internal/geometry.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <limits>
#include <type_traits>
#include <unordered_map>

namespace voxwarp {

namespace {

/// Normals on the two sides of an edge closer than this angle do not make it a hard edge: Blender's auto-smooth
/// default. A flat-shaded fine mesh (every face its own normal, a few degrees from its neighbours') is shaded smooth
/// rather than cut along every input edge; a box's edges, and a coarse model's creases, stay hard.
constexpr double kHardEdgeDegrees = 30;

/// Charts of the input: triangles joined across each edge whose two sides have the same material, the same group,
/// the same texture coordinates at both ends, and normals within kHardEdgeDegrees at both ends (or none on both
/// sides). A chart's boundary is a UV seam, a hard edge, or a material or group boundary.
std::vector<std::int32_t> charts_of(const TriangleMesh& input) {
    const auto& tris = input.triangles;
    auto corner = [](const std::vector<std::array<std::int32_t, 3>>& of_corner, std::size_t t, std::size_t c) { return of_corner.empty() ? -1 : of_corner[t][c]; };
    auto same_value = [](const auto& values, std::int32_t a, std::int32_t b) { return a == b || (a >= 0 && b >= 0 && values[std::size_t(a)] == values[std::size_t(b)]); };
    const double smooth = std::cos(kHardEdgeDegrees * M_PI / 180);
    auto smooth_normal = [&](std::int32_t a, std::int32_t b) {
        return a == b || (a >= 0 && b >= 0 && input.normals[std::size_t(a)].dot(input.normals[std::size_t(b)]) >= smooth);
    };
    auto same = [](const std::vector<std::int32_t>& of_triangle, std::size_t p, std::size_t q) { // a material or group
        return of_triangle.empty() || of_triangle[p] == of_triangle[q];
    };
    internal::DisjointSets sets(tris.size());
    struct Side { // the first triangle seen on an edge, and its texture coordinates and normals at the edge's lower and higher vertex
        std::size_t triangle;
        std::int32_t uv_low, uv_high, normal_low, normal_high;
    };
    std::unordered_map<std::uint64_t, Side> first;
    first.reserve(tris.size() * 2);
    for (std::size_t t = 0; t < tris.size(); ++t)
        for (std::size_t c = 0; c < 3; ++c) {
            const std::size_t d = (c + 1) % 3;
            std::int32_t a = tris[t][c], b = tris[t][d], ua = corner(input.triangle_uvs, t, c), ub = corner(input.triangle_uvs, t, d),
                         na = corner(input.triangle_normals, t, c), nb = corner(input.triangle_normals, t, d);
            if (a > b) std::swap(a, b), std::swap(ua, ub), std::swap(na, nb);
            const std::uint64_t key = (std::uint64_t(std::uint32_t(a)) << 32) | std::uint32_t(b);
            const auto [it, added] = first.try_emplace(key, Side{t, ua, ub, na, nb});
            const Side& s = it->second;
            if (!added && same(input.triangle_materials, s.triangle, t) && same(input.triangle_groups, s.triangle, t) && same_value(input.uvs, s.uv_low, ua) &&
                same_value(input.uvs, s.uv_high, ub) && smooth_normal(s.normal_low, na) && smooth_normal(s.normal_high, nb))
                sets.join(t, s.triangle);
        }
    std::vector<std::int32_t> chart(tris.size());
    std::unordered_map<std::size_t, std::int32_t> ids;
    for (std::size_t t = 0; t < tris.size(); ++t) chart[t] = ids.try_emplace(sets.find(t), std::int32_t(ids.size())).first->second;
    return chart;
}

/// Barycentric coordinates of `p` against triangle (a, b, c) in its plane (p projected onto it), unclamped: outside
/// the triangle they continue its affine map.
Eigen::Vector3d barycentric_in_plane(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const Eigen::Vector3d e1 = b - a, e2 = c - a, d = p - a;
    const double g11 = e1.dot(e1), g12 = e1.dot(e2), g22 = e2.dot(e2), det = g11 * g22 - g12 * g12;
    if (!(std::abs(det) > 1e-300)) return Eigen::Vector3d(1, 0, 0);
    const double r1 = e1.dot(d), r2 = e2.dot(d);
    const double v = (g22 * r1 - g12 * r2) / det, w = (g11 * r2 - g12 * r1) / det;
    return Eigen::Vector3d(1 - v - w, v, w);
}

} // namespace

TransferReport transfer_attributes(TriangleMesh& output, const SourceSurface& surface, const std::vector<SourcePoint>& sources,
                                   const std::vector<WarpStep>& steps) {
    const TriangleMesh& input = surface.mesh();
    if (!output.quads.empty()) throw InvalidInput("transfer_attributes: the output has quads; triangulate it first");
    if (!input.quads.empty()) throw InvalidInput("transfer_attributes: the input has quads");
    if (sources.size() != output.vertices.size())
        throw InvalidInput("transfer_attributes: " + std::to_string(sources.size()) + " sources for " + std::to_string(output.vertices.size()) + " vertices");
    TransferReport report;
    output.uvs.clear(), output.triangle_uvs.clear(), output.normals.clear(), output.triangle_normals.clear(), output.colours.clear(), output.triangle_materials.clear(), output.triangle_groups.clear();
    output.materials = input.materials;
    output.groups = input.groups;
    if (!input.has_attributes()) return report;
    const auto& in_tris = input.triangles;
    const auto& V = input.vertices;

    // A vertex without a source borrows its nearest neighbour's (breadth first over the output's edges).
    std::vector<SourcePoint> source = sources;
    std::deque<std::int32_t> queue;
    for (std::size_t v = 0; v < source.size(); ++v) {
        if (source[v].face >= std::int32_t(in_tris.size())) throw InvalidInput("transfer_attributes: vertex " + std::to_string(v) + "'s source face is not on the input");
        if (source[v].face >= 0) queue.push_back(std::int32_t(v));
        else ++report.vertices_without_source;
    }
    if (report.vertices_without_source > 0) {
        std::vector<std::vector<std::int32_t>> neighbours(output.vertices.size());
        for (const auto& t : output.triangles)
            for (std::size_t c = 0; c < 3; ++c) {
                const auto a = t[c], b = t[(c + 1) % 3];
                neighbours[std::size_t(a)].push_back(b), neighbours[std::size_t(b)].push_back(a);
            }
        while (!queue.empty()) {
            const auto v = queue.front();
            queue.pop_front();
            for (const auto n : neighbours[std::size_t(v)])
                if (source[std::size_t(n)].face < 0) source[std::size_t(n)] = source[std::size_t(v)], queue.push_back(n);
        }
    }
    auto point_of = [&](const SourcePoint& s) {
        const auto& t = in_tris[std::size_t(s.face)];
        return Eigen::Vector3d(s.barycentric[0] * V[std::size_t(t[0])] + s.barycentric[1] * V[std::size_t(t[1])] + s.barycentric[2] * V[std::size_t(t[2])]);
    };
    auto normal_of = [&](std::int32_t f) {
        const auto& t = in_tris[std::size_t(f)];
        const Eigen::Vector3d n = (V[std::size_t(t[1])] - V[std::size_t(t[0])]).cross(V[std::size_t(t[2])] - V[std::size_t(t[0])]);
        return n.norm() > 0 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d::Zero();
    };

    const std::vector<std::int32_t> chart = charts_of(input);

    // Each vertex's source point seen from every chart it touches: its own face's, and, where the point lies on an
    // edge or a corner of that face (on a seam, as snapping leaves vertices there), the faces across it.
    std::unordered_map<std::uint64_t, std::vector<std::int32_t>> edge_faces;
    std::vector<std::vector<std::int32_t>> vertex_faces(V.size());
    auto edge_key = [](std::int32_t a, std::int32_t b) { return (std::uint64_t(std::uint32_t(std::min(a, b))) << 32) | std::uint32_t(std::max(a, b)); };
    for (std::size_t f = 0; f < in_tris.size(); ++f)
        for (std::size_t c = 0; c < 3; ++c) {
            edge_faces[edge_key(in_tris[f][c], in_tris[f][(c + 1) % 3])].push_back(std::int32_t(f));
            vertex_faces[std::size_t(in_tris[f][c])].push_back(std::int32_t(f));
        }
    auto in_face = [&](const Eigen::Vector3d& p, std::int32_t g) {
        const auto& t = in_tris[std::size_t(g)];
        return SourcePoint{g, barycentric_in_plane(p, V[std::size_t(t[0])], V[std::size_t(t[1])], V[std::size_t(t[2])])};
    };
    std::vector<std::vector<SourcePoint>> sides(output.vertices.size());
    auto add_side = [&](std::vector<SourcePoint>& list, const SourcePoint& s) {
        for (const auto& e : list)
            if (chart[std::size_t(e.face)] == chart[std::size_t(s.face)]) return;
        list.push_back(s);
    };
    tbb::parallel_for(std::size_t(0), output.vertices.size(), [&](std::size_t v) {
        const SourcePoint& s = source[v];
        if (s.face < 0) return;
        sides[v].push_back(s);
        const auto& t = in_tris[std::size_t(s.face)];
        constexpr double on_edge = 1e-9;
        const int zeros = int(s.barycentric[0] <= on_edge) + int(s.barycentric[1] <= on_edge) + int(s.barycentric[2] <= on_edge);
        if (zeros == 0) return;
        const Eigen::Vector3d p = point_of(s);
        std::size_t i = 0; // zeros == 1: the corner opposite the edge; zeros == 2: the corner it sits on
        while (zeros == 1 ? s.barycentric[Eigen::Index(i)] > on_edge : s.barycentric[Eigen::Index(i)] <= on_edge) ++i;
        const auto& across = zeros == 1 ? edge_faces.at(edge_key(t[(i + 1) % 3], t[(i + 2) % 3])) : vertex_faces[std::size_t(t[i])];
        for (const auto g : across) add_side(sides[v], in_face(p, g));
    });
    auto side_in = [&](std::int32_t v, std::int32_t c) -> const SourcePoint* {
        for (const auto& e : sides[std::size_t(v)])
            if (chart[std::size_t(e.face)] == c) return &e;
        return nullptr;
    };
    // A chart both vertices touch (-1: none: the edge between them crosses a seam).
    auto common = [&](std::int32_t a, std::int32_t b) {
        for (const auto& e : sides[std::size_t(a)])
            if (side_in(b, chart[std::size_t(e.face)])) return chart[std::size_t(e.face)];
        return std::int32_t(-1);
    };

    // Per triangle, the chart each edge's two ends share (-1: the edge crosses a seam; all -2 for a triangle with a
    // corner without source, which keeps no attributes).
    const std::size_t nt = output.triangles.size();
    std::vector<std::array<std::int32_t, 3>> edge_chart(nt);
    tbb::parallel_for(std::size_t(0), nt, [&](std::size_t f) {
        const auto& t = output.triangles[f];
        const bool sourced = source[std::size_t(t[0])].face >= 0 && source[std::size_t(t[1])].face >= 0 && source[std::size_t(t[2])].face >= 0;
        edge_chart[f] = sourced ? std::array<std::int32_t, 3>{common(t[0], t[1]), common(t[1], t[2]), common(t[2], t[0])} : std::array<std::int32_t, 3>{-2, -2, -2};
    });
    std::vector<std::uint64_t> crossing_edges;
    for (std::size_t f = 0; f < nt; ++f)
        for (std::size_t c = 0; c < 3; ++c)
            if (edge_chart[f][c] == -1) crossing_edges.push_back(edge_key(output.triangles[f][c], output.triangles[f][(c + 1) % 3]));
    // The seam vertex of each output edge whose ends share no chart: bisection along the segment between their
    // source points, each midpoint taken to the input surface (nearest point facing the same way), until the two
    // sides' faces share an edge (the seam's): then where the segment passes closest to that edge. Placed at the
    // same fraction of the output edge. All crossing edges are bisected in parallel.
    std::sort(crossing_edges.begin(), crossing_edges.end());
    crossing_edges.erase(std::unique(crossing_edges.begin(), crossing_edges.end()), crossing_edges.end());
    struct Crossing {
        double t = 0.5;
        Eigen::Vector3d q = Eigen::Vector3d::Zero();
        std::int32_t low_face = -1, high_face = -1;
    };
    std::vector<Crossing> crossings(crossing_edges.size());
    auto shared_edge = [&](std::int32_t f, std::int32_t g, std::array<std::int32_t, 2>& edge) {
        int n = 0;
        for (const auto u : in_tris[std::size_t(f)])
            for (const auto w : in_tris[std::size_t(g)])
                if (u == w && n < 2) edge[std::size_t(n++)] = u;
        return n == 2;
    };
    tbb::parallel_for(std::size_t(0), crossing_edges.size(), [&](std::size_t i) {
        const auto a = std::int32_t(crossing_edges[i] >> 32), b = std::int32_t(crossing_edges[i] & 0xffffffffu);
        SourcePoint low = source[std::size_t(a)], high = source[std::size_t(b)];
        const Eigen::Vector3d pa = point_of(low), pb = point_of(high), d = pb - pa;
        const Eigen::Vector3d n = normal_of(low.face) + normal_of(high.face);
        const double reach = 2 * d.norm() + 1e-12;
        double t0 = 0, t1 = 1;
        std::array<std::int32_t, 2> edge{};
        bool exact = false;
        for (int k = 0; k < 30 && !(exact = shared_edge(low.face, high.face, edge)) && (t1 - t0) * d.norm() > 1e-9 * reach; ++k) {
            const double t = 0.5 * (t0 + t1);
            const SourcePoint s = surface.nearest(pa + t * d, n, reach);
            if (s.face < 0) break;
            if (side_in(a, chart[std::size_t(s.face)])) t0 = t, low = s;
            else t1 = t, high = s;
        }
        Crossing& x = crossings[i];
        x.low_face = low.face, x.high_face = high.face;
        x.t = 0.5 * (t0 + t1);
        x.q = 0.5 * (point_of(low) + point_of(high));
        if (exact) { // the closest points of the segment and the seam's edge
            const Eigen::Vector3d u = V[std::size_t(edge[0])], e = V[std::size_t(edge[1])] - u, r = pa - u;
            const double dd = d.dot(d), de = d.dot(e), ee = e.dot(e), denominator = dd * ee - de * de;
            if (denominator > 1e-12 * dd * ee) {
                const double t = std::clamp((de * e.dot(r) - ee * d.dot(r)) / denominator, t0, t1);
                const double along = std::clamp((e.dot(r) + t * de) / ee, 0.0, 1.0);
                x.t = t, x.q = u + along * e;
            }
        }
    });
    // A seam through an end of the edge (an output vertex on the input's seam: a fan's centre on a sharp edge the
    // seam follows) would put the new vertex on that end: kept eight 32-bit float steps away at the output's largest
    // coordinate, as marching cubes keeps its crossings off a grid edge's ends, so that the two stay apart in PLY,
    // STL and glTF (Spot's head turn at 128 with the feature mesher had 33 such edges).
    double largest = 0;
    if (!crossing_edges.empty())
        for (const auto& p : output.vertices) largest = std::max(largest, p.cwiseAbs().maxCoeff());
    const double apart = internal::float_gap(largest);
    const auto first_seam_vertex = std::int32_t(output.vertices.size());
    output.vertices.reserve(output.vertices.size() + crossing_edges.size());
    source.reserve(source.size() + crossing_edges.size());
    sides.reserve(sides.size() + crossing_edges.size());
    for (std::size_t i = 0; i < crossing_edges.size(); ++i) {
        const auto a = std::size_t(crossing_edges[i] >> 32), b = std::size_t(crossing_edges[i] & 0xffffffffu);
        const Crossing& x = crossings[i];
        const double keep = std::min(0.25, apart / ((output.vertices[b] - output.vertices[a]).norm() + 1e-300));
        const double t = std::clamp(x.t, keep, 1 - keep);
        output.vertices.push_back((1 - t) * output.vertices[a] + t * output.vertices[b]);
        source.push_back(in_face(x.q, x.low_face));
        sides.push_back({in_face(x.q, x.low_face)});
        add_side(sides.back(), in_face(x.q, x.high_face));
    }
    report.vertices_added = crossing_edges.size();
    auto seam_vertex = [&](std::int32_t a, std::int32_t b) {
        const auto it = std::lower_bound(crossing_edges.begin(), crossing_edges.end(), edge_key(a, b));
        return first_seam_vertex + std::int32_t(it - crossing_edges.begin());
    };
    auto primary = [&](std::int32_t v) { return source[std::size_t(v)].face >= 0 ? chart[std::size_t(source[std::size_t(v)].face)] : -1; };

    // Cut every triangle whose edges cross seams into pieces that each lie in one chart.
    struct Piece {
        std::array<std::int32_t, 3> corners;
        std::int32_t chart;
    };
    std::vector<Piece> pieces;
    pieces.reserve(output.triangles.size() + output.triangles.size() / 16);
    std::vector<std::size_t> cut; // the pieces of cut triangles
    for (std::size_t f = 0; f < nt; ++f) {
        const auto& t = output.triangles[f];
        const auto& shared = edge_chart[f];
        if (shared[0] == -2) { // nothing of the input within reach
            pieces.push_back({t, -1});
            continue;
        }
        const int crossings = int(shared[0] < 0) + int(shared[1] < 0) + int(shared[2] < 0);
        if (crossings == 0) {
            std::int32_t c = shared[0];
            for (const auto& e : sides[std::size_t(t[0])]) // a chart all three touch, if there is one
                if (side_in(t[1], chart[std::size_t(e.face)]) && side_in(t[2], chart[std::size_t(e.face)])) c = chart[std::size_t(e.face)];
            pieces.push_back({t, c});
            continue;
        }
        ++report.triangles_across_charts;
        const std::size_t first_piece = pieces.size();
        if (crossings == 1) { // a seam through one corner and across the opposite edge
            std::size_t e = 0;
            while (shared[e] >= 0) ++e;
            const std::int32_t a = t[e], b = t[(e + 1) % 3], c = t[(e + 2) % 3], m = seam_vertex(a, b);
            pieces.push_back({{a, m, c}, shared[(e + 2) % 3]});
            pieces.push_back({{m, b, c}, shared[(e + 1) % 3]});
        } else if (crossings == 2) { // a seam across two edges: the odd corner's piece, and the quad of the other two
            std::size_t e = 0;
            while (shared[e] < 0) ++e; // the edge that stays: corners a, b; the odd one o
            const std::int32_t a = t[e], b = t[(e + 1) % 3], o = t[(e + 2) % 3];
            const std::int32_t mbo = seam_vertex(b, o), moa = seam_vertex(o, a);
            pieces.push_back({{a, b, mbo}, shared[e]});
            pieces.push_back({{a, mbo, moa}, shared[e]});
            pieces.push_back({{mbo, o, moa}, primary(o)});
        } else { // three charts: a piece at each corner, and the middle
            const std::int32_t m01 = seam_vertex(t[0], t[1]), m12 = seam_vertex(t[1], t[2]), m20 = seam_vertex(t[2], t[0]);
            pieces.push_back({{t[0], m01, m20}, primary(t[0])});
            pieces.push_back({{t[1], m12, m01}, primary(t[1])});
            pieces.push_back({{t[2], m20, m12}, primary(t[2])});
            pieces.push_back({{m01, m12, m20}, primary(t[0])});
        }
        for (std::size_t i = first_piece; i < pieces.size(); ++i) cut.push_back(i);
    }
    // Where charts meet inside a triangle (a junction of seams), or an edge crosses a strip of a third chart, a piece
    // cut along the corners' seams can lie in a chart none of its corners names: each piece of a cut triangle takes
    // the chart of the input point nearest its middle.
    std::vector<std::int32_t> middle_face(pieces.size(), -1);
    tbb::parallel_for(std::size_t(0), cut.size(), [&](std::size_t i) {
        Piece& p = pieces[cut[i]];
        const SourcePoint a = source[std::size_t(p.corners[0])], b = source[std::size_t(p.corners[1])], c = source[std::size_t(p.corners[2])];
        const Eigen::Vector3d pa = point_of(a), pb = point_of(b), pc = point_of(c);
        const double reach = 2 * std::max({(pa - pb).norm(), (pb - pc).norm(), (pc - pa).norm()}) + 1e-12;
        const SourcePoint m = surface.nearest((pa + pb + pc) / 3, normal_of(a.face) + normal_of(b.face) + normal_of(c.face), reach);
        if (m.face >= 0) p.chart = chart[std::size_t(m.face)], middle_face[cut[i]] = m.face;
    });

    output.triangles.resize(pieces.size());
    for (std::size_t f = 0; f < pieces.size(); ++f) output.triangles[f] = pieces[f].corners;

    if (!input.colours.empty()) {
        output.colours.assign(output.vertices.size(), Eigen::Vector3f::Ones());
        tbb::parallel_for(std::size_t(0), output.vertices.size(), [&](std::size_t v) {
            const SourcePoint& s = source[v];
            if (s.face < 0) return;
            const auto& t = in_tris[std::size_t(s.face)];
            Eigen::Vector3f c = Eigen::Vector3f::Zero();
            for (int i = 0; i < 3; ++i) c += float(s.barycentric[i]) * input.colours[std::size_t(t[std::size_t(i)])];
            output.colours[v] = c.cwiseMax(0.0f).cwiseMin(1.0f);
        });
    }
    // A triangle's material and group, which no chart crosses: each output triangle takes its chart's.
    auto by_chart = [&](const std::vector<std::int32_t>& of_input, std::vector<std::int32_t>& of_output) {
        if (of_input.empty()) return;
        std::vector<std::int32_t> of_chart(in_tris.size(), -1);
        for (std::size_t t = 0; t < in_tris.size(); ++t) of_chart[std::size_t(chart[t])] = of_input[t];
        of_output.resize(pieces.size());
        for (std::size_t f = 0; f < pieces.size(); ++f) of_output[f] = pieces[f].chart >= 0 ? of_chart[std::size_t(pieces[f].chart)] : -1;
    };
    by_chart(input.triangle_materials, output.triangle_materials);
    by_chart(input.triangle_groups, output.triangle_groups);
    // Per-corner attributes (texture coordinates, normals): one value per (vertex, chart), read in that chart at the
    // vertex's source point, so that corners of one vertex in one chart share it and a seam's corners differ.
    auto per_corner = [&](const auto& in_values, const std::vector<std::array<std::int32_t, 3>>& in_index, auto& out_values,
                          std::vector<std::array<std::int32_t, 3>>& out_index, const auto& finish) {
        if (in_index.empty()) return;
        using Value = std::decay_t<decltype(in_values[0])>;
        out_index.assign(pieces.size(), {-1, -1, -1});
        std::vector<std::pair<std::int32_t, std::int32_t>> first(output.vertices.size(), {-1, -1}); // the first chart seen at a vertex, its value
        std::unordered_map<std::uint64_t, std::int32_t> more;                                      // (vertex, chart) beyond it: seams
        std::vector<SourcePoint> read_at;                                                          // where each value is read
        for (std::size_t f = 0; f < pieces.size(); ++f) {
            const Piece& p = pieces[f];
            if (p.chart < 0) continue;
            // A face of the piece's chart to continue the values from, for a corner that does not touch it.
            std::int32_t face = middle_face[f];
            for (const auto v : p.corners)
                if (const SourcePoint* s = side_in(v, p.chart); s && face < 0) face = s->face;
            if (face < 0 || in_index[std::size_t(face)][0] < 0) continue;
            for (std::size_t c = 0; c < 3; ++c) {
                const std::int32_t v = p.corners[c];
                auto& known = first[std::size_t(v)];
                const std::uint64_t key = (std::uint64_t(std::uint32_t(v)) << 32) | std::uint32_t(p.chart);
                if (known.first == p.chart) {
                    out_index[f][c] = known.second;
                    continue;
                }
                if (known.first >= 0)
                    if (const auto it = more.find(key); it != more.end()) {
                        out_index[f][c] = it->second;
                        continue;
                    }
                const SourcePoint* side = side_in(v, p.chart);
                out_index[f][c] = std::int32_t(read_at.size());
                if (known.first < 0) known = {p.chart, std::int32_t(read_at.size())};
                else more.emplace(key, std::int32_t(read_at.size()));
                read_at.push_back(side && in_index[std::size_t(side->face)][0] >= 0 ? *side : in_face(point_of(sides[std::size_t(v)][0]), face));
            }
        }
        out_values.resize(read_at.size());
        tbb::parallel_for(std::size_t(0), read_at.size(), [&](std::size_t i) { // a normal's push through the warps is the costly part
            const SourcePoint& s = read_at[i];
            Value value = Value::Zero();
            for (std::size_t k = 0; k < 3; ++k) value += s.barycentric[Eigen::Index(k)] * in_values[std::size_t(in_index[std::size_t(s.face)][k])];
            out_values[i] = finish(value, s);
        });
    };
    per_corner(input.uvs, input.triangle_uvs, output.uvs, output.triangle_uvs, [](const Eigen::Vector2d& uv, const SourcePoint&) { return uv; });
    // A normal is interpolated on the input, then carried through the warps as normals go.
    per_corner(input.normals, input.triangle_normals, output.normals, output.triangle_normals,
               [&](const Eigen::Vector3d& n, const SourcePoint& s) { return push_normal(steps, point_of(s), n); });
    return report;
}

} // namespace voxwarp
