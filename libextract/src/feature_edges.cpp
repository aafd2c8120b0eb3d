// The feature mesher's last step (features.cpp): mesh edges that still cut across one of the input's sharp edges
// are split where the sharp edge passes over them.
//
// Why: fans put a vertex on the edge in each cell whose loop sees both faces, and flips join neighbouring fans.
// Where an edge only clips a cell, two fans along it can be a triangle apart, and marching cubes' triangle between
// them joins a crossing on one face straight to a crossing on the other: a chamfer under the edge. A warp that
// bends the edge a little leaves more of them (a cube turned 30 degrees by the warp lost up to 0.30 voxel of edge
// there, 0.10 with this step).
//
// How: a mesh edge whose ends lie on either side of a sharp edge (seen from outside, along its two triangles' mean
// normal), and that passes under the sharp edge between its ends, is split at the sharp edge's point nearest it:
// its two triangles become four around the new vertex. Where a triangle had two such edges, the two new vertices
// share an edge, so the split points chain along the sharp edge. A split keeps the mesh a closed 2-manifold; one
// that would turn a triangle over is not made.
#include "features.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <unordered_map>

namespace voxwarp::extract_internal {

namespace {

using Triangle = std::array<std::int32_t, 3>;

/// Closest points of segments p0 p1 and q0 q1 (Ericson, Real-Time Collision Detection 5.1.9): parameters s, t.
void closest_between_segments(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& q0, const Eigen::Vector3d& q1, double& s, double& t) {
    const Eigen::Vector3d d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
    const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r), c = d1.dot(r);
    if (a <= 0 || e <= 0) { // a point: its nearest on the other
        s = a > 0 ? std::clamp(-c / a, 0.0, 1.0) : 0.0, t = a > 0 || e <= 0 ? 0.0 : std::clamp(f / e, 0.0, 1.0);
        return;
    }
    const double b = d1.dot(d2), denom = a * e - b * b;
    s = denom > 0 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
    t = (b * s + f) / e;
    if (t < 0) t = 0, s = std::clamp(-c / a, 0.0, 1.0);
    else if (t > 1) t = 1, s = std::clamp((b - c) / a, 0.0, 1.0);
}

/// The input's sharp edges filed by cell (CellBuckets).
class EdgeGrid {
public:
    /// Each edge filed in the cells within `reach` (world units) of its bounding box, so that a query reads only
    /// the cells its own segment passes through.
    EdgeGrid(const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& edges, const SparseVoxmap& v, double reach)
        : edges_(edges), voxmap_(v), reach_(reach), cells_(v) {
        const Eigen::Vector3d grow = Eigen::Vector3d::Constant(reach / v.voxel_size());
        for (std::size_t i = 0; i < edges.size(); ++i) {
            const Eigen::Vector3d qa = v.index_of(edges[i].first), qb = v.index_of(edges[i].second);
            const Index3 lo = cell_containing(qa.cwiseMin(qb)), hi = cell_containing(qa.cwiseMax(qb));
            if (hi[0] - lo[0] > 8 || hi[1] - lo[1] > 8 || hi[2] - lo[2] > 8) continue; // not cut for this voxmap
            cells_.add(qa.cwiseMin(qb) - grow, qa.cwiseMax(qb) + grow, std::uint32_t(i));
        }
        cells_.build();
    }
    /// The sharp edges' point nearest the segment a b, where that is within the reach of it, nearest it between its
    /// ends and at least `margin` from either (a sharp edge through an end, a feature vertex on another sharp
    /// edge, is no reason to split); with the edge's direction there. False when there is none.
    bool nearest(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double margin, Eigen::Vector3d& point, Eigen::Vector3d& direction) const {
        const Eigen::Vector3d qa = voxmap_.index_of(a), qb = voxmap_.index_of(b);
        // A mesh edge spans a voxel or two. One with an end that is not a number, or gone far off, would have this
        // walk cells without end (a fan's centre slid by an infinite amount once hung the snowden edit here).
        if (!(qa.allFinite() && qb.allFinite()) || ((qa - qb).cwiseAbs().array() > 64).any()) return false;
        const Index3 lo = cell_containing(qa.cwiseMin(qb)), hi = cell_containing(qa.cwiseMax(qb));
        if (!cells_.any(lo, hi)) return false;
        double best = reach_;
        std::uint32_t chosen = 0;
        bool found = false;
        for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
            for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
                for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
                    for (std::uint32_t i : cells_.at({x, y, z})) {
                        const auto& [q0, q1] = edges_[i];
                        double s = 0, t = 0;
                        closest_between_segments(a, b, q0, q1, s, t);
                        const Eigen::Vector3d on_edge = q0 + t * (q1 - q0);
                        const double d = (a + s * (b - a) - on_edge).norm();
                        if (s < 0.02 || s > 0.98 || (on_edge - a).norm() < margin || (on_edge - b).norm() < margin) continue;
                        if (d < best || (d == best && found && i < chosen)) best = d, chosen = i, point = on_edge, direction = q1 - q0, found = true;
                    }
        return found;
    }

private:
    const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& edges_;
    const SparseVoxmap& voxmap_;
    double reach_;
    CellBuckets cells_;
};

std::uint64_t directed(std::int32_t a, std::int32_t b) { return std::uint64_t(std::uint32_t(a)) << 32 | std::uint32_t(b); }

Eigen::Vector3d area_normal(const std::vector<Eigen::Vector3d>& v, const Triangle& t) {
    return (v[std::size_t(t[1])] - v[std::size_t(t[0])]).cross(v[std::size_t(t[2])] - v[std::size_t(t[0])]);
}

/// Whether vertex `v` has a normal: `normals` holds one per vertex of marching cubes' output, zero where unknown.
bool known(const std::vector<Eigen::Vector3d>& normals, std::int32_t v) { return std::size_t(v) < normals.size() && !normals[std::size_t(v)].isZero(); }

/// The corner of `t` that is neither `a` nor `b`.
std::int32_t third(const Triangle& t, std::int32_t a, std::int32_t b) {
    for (auto v : t)
        if (v != a && v != b) return v;
    return -1;
}

/// Which triangle holds each directed edge, among the triangles with a corner marked in `near` (by vertex; those
/// past its end unmarked), and with `both_ends` only the edges whose two ends are marked. A triangle changed is
/// entered again. The edges at the start are a sorted list, and those entered since a small map; an answer is
/// checked against the triangle's corners, so what a changed triangle held before needs no erasing (a hash map of
/// every edge, a node each, cost the bunny ear edit at 256 5-14 ms a build).
class EdgeHolders {
public:
    EdgeHolders(const std::vector<Triangle>& triangles, const std::vector<std::uint8_t>& near, bool both_ends)
        : triangles_(triangles), near_(near), both_ends_(both_ends) {
        const std::vector<std::uint32_t> around = select_in_parallel(triangles.size(), [&](std::size_t i) {
            const Triangle& t = triangles[i];
            return (near[std::size_t(t[0])] | near[std::size_t(t[1])] | near[std::size_t(t[2])]) != 0;
        });
        start_.reserve(3 * around.size());
        for (const std::uint32_t i : around) each_edge(i, [&](std::uint64_t e) { start_.push_back({e, i}); });
        tbb::parallel_sort(start_.begin(), start_.end());
    }
    void enter(std::uint32_t i) {
        each_edge(i, [&](std::uint64_t e) { entered_[e] = i; });
    }
    /// The triangle holding a -> b, or -1 when none is known.
    std::int64_t of(std::int32_t a, std::int32_t b) const {
        const std::uint64_t e = directed(a, b);
        if (const auto it = entered_.find(e); it != entered_.end()) return holds(it->second, a, b) ? std::int64_t(it->second) : -1;
        // The last entered, as the map's was (a closed mesh holds each directed edge once).
        auto it = std::upper_bound(start_.begin(), start_.end(), std::pair(e, std::numeric_limits<std::uint32_t>::max()));
        if (it == start_.begin() || (--it)->first != e) return -1;
        return holds(it->second, a, b) ? std::int64_t(it->second) : -1;
    }

private:
    bool marked(std::int32_t v) const { return std::size_t(v) < near_.size() && near_[std::size_t(v)]; }
    template <class F>
    void each_edge(std::uint32_t i, const F& f) const {
        const Triangle& t = triangles_[i];
        for (int c = 0; c < 3; ++c) {
            const std::int32_t a = t[std::size_t(c)], b = t[std::size_t((c + 1) % 3)];
            if (!both_ends_ || (marked(a) && marked(b))) f(directed(a, b));
        }
    }
    bool holds(std::uint32_t i, std::int32_t a, std::int32_t b) const {
        const Triangle& t = triangles_[i];
        for (int c = 0; c < 3; ++c)
            if (t[std::size_t(c)] == a && t[std::size_t((c + 1) % 3)] == b) return true;
        return false;
    }
    const std::vector<Triangle>& triangles_;
    const std::vector<std::uint8_t>& near_;
    bool both_ends_;
    std::vector<std::pair<std::uint64_t, std::uint32_t>> start_; ///< (edge, triangle) at the start, sorted
    std::unordered_map<std::uint64_t, std::uint32_t> entered_;   ///< the last triangle entered with each edge since
};

} // namespace

void split_across_sharp_edges(std::vector<Eigen::Vector3d>& vertices, std::vector<std::array<std::int32_t, 3>>& triangles, const std::vector<Eigen::Vector3d>& normals,
                              double cos_feature, const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& edges, const SparseVoxmap& voxmap,
                              std::vector<std::array<std::int32_t, 3>>& made_splits) {
    if (edges.empty()) return;
    const double h = voxmap.voxel_size();
    const double reach = 0.6 * h; // deeper than marching cubes' chamfer of a right-angled edge
    const EdgeGrid grid(edges, voxmap, reach);

    // Each undirected mesh edge once (closed and consistently wound, it runs a -> b with a < b in one of its two
    // triangles); not one whose ends' normals agree (both on one face).
    struct Split {
        std::int32_t a, b;
        Eigen::Vector3d point, along; // the sharp edge's point and direction
    };
    tbb::enumerable_thread_specific<std::vector<Split>> found;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, triangles.size(), 4096), [&](const auto& range) {
        auto& local = found.local();
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
            // A triangle none of whose corners has a normal is far from the feature surface, and so from its edges.
            if (!known(normals, triangles[i][0]) && !known(normals, triangles[i][1]) && !known(normals, triangles[i][2])) continue;
            for (int c = 0; c < 3; ++c) {
                const std::int32_t a = triangles[i][std::size_t(c)], b = triangles[i][std::size_t((c + 1) % 3)];
                if (a > b || (known(normals, a) && known(normals, b) && normals[std::size_t(a)].dot(normals[std::size_t(b)]) >= cos_feature)) continue;
                Eigen::Vector3d point = Eigen::Vector3d::Zero(), along = Eigen::Vector3d::Zero();
                if (grid.nearest(vertices[std::size_t(a)], vertices[std::size_t(b)], 0.02 * h, point, along)) local.push_back({a, b, point, along});
            }
        }
    });
    std::vector<Split> splits;
    for (const auto& local : found) splits.insert(splits.end(), local.begin(), local.end());
    if (splits.empty()) return;
    // Each edge once, so the order is the same for any thread count.
    tbb::parallel_sort(splits.begin(), splits.end(), [](const Split& x, const Split& y) { return std::pair(x.a, x.b) < std::pair(y.a, y.b); });

    // Directed edges of the triangles around the edges to split; only those between touched vertices are asked about.
    std::vector<std::uint8_t> touched(vertices.size(), 0);
    for (const auto& s : splits) touched[std::size_t(s.a)] = touched[std::size_t(s.b)] = 1;
    EdgeHolders holders(triangles, touched, true);
    // The fans' centres and the splits made, by cells of a hundredth of a voxel. Edges that pass a bend of a sharp
    // edge (the end of one of its pieces) have that point nearest, and a fan's centre on the sharp edge may be
    // there already; a split there would be a second vertex on one position, its triangles meeting the first's (the
    // snowden scan at 128 had 600 such). The sharp edge already passes through the first.
    const double apart = 0.01 * h;
    auto cell_of = [&](const Eigen::Vector3d& p) {
        const Eigen::Vector3d q = (p / apart).array().floor();
        return std::array<std::int64_t, 3>{std::int64_t(q.x()), std::int64_t(q.y()), std::int64_t(q.z())};
    };
    std::map<std::array<std::int64_t, 3>, std::vector<std::int32_t>> taken;
    for (std::size_t v = normals.size(); v < vertices.size(); ++v) taken[cell_of(vertices[v])].push_back(std::int32_t(v));
    auto near_one = [&](const Eigen::Vector3d& p) {
        const auto c = cell_of(p);
        for (std::int64_t dz = -1; dz <= 1; ++dz)
            for (std::int64_t dy = -1; dy <= 1; ++dy)
                for (std::int64_t dx = -1; dx <= 1; ++dx)
                    if (const auto it = taken.find({c[0] + dx, c[1] + dy, c[2] + dz}); it != taken.end())
                        for (const std::int32_t v : it->second)
                            if ((vertices[std::size_t(v)] - p).norm() < apart) return true;
        return false;
    };
    for (const auto& [a, b, point, along] : splits) {
        const std::int64_t ab = holders.of(a, b), ba = holders.of(b, a);
        if (ab < 0 || ba < 0) continue;
        const auto t1 = std::uint32_t(ab), t2 = std::uint32_t(ba);
        const std::int32_t c = third(triangles[t1], a, b), d = third(triangles[t2], a, b);
        // A third corner already on the point (a vertex of marching cubes there) would be a second vertex there.
        if ((vertices[std::size_t(c)] - point).norm() < apart || (vertices[std::size_t(d)] - point).norm() < apart) continue;
        const Eigen::Vector3d n1 = area_normal(vertices, triangles[t1]), n2 = area_normal(vertices, triangles[t2]);
        // Seen from outside, a and b lie on either side of the sharp edge; an end on the edge's line is on neither
        // (splitting there would make triangles with three vertices on the line).
        const Eigen::Vector3d across = along.cross(n1.normalized() + n2.normalized());
        const double side_a = (vertices[std::size_t(a)] - point).dot(across), side_b = (vertices[std::size_t(b)] - point).dot(across);
        const double off = 0.01 * h * across.norm();
        if (!((side_a < -off && side_b > off) || (side_a > off && side_b < -off))) continue;
        // Last, as it reads 27 cells of a map: of the bunny ear edit's 17,000 candidate edges at 256, 600 get here.
        if (near_one(point)) continue;
        const auto m = std::int32_t(vertices.size());
        vertices.push_back(point);
        const std::array<Triangle, 4> made{Triangle{a, m, c}, Triangle{m, b, c}, Triangle{b, m, d}, Triangle{m, a, d}};
        bool upright = true;
        for (std::size_t i = 0; i < 4; ++i) upright &= area_normal(vertices, made[i]).dot(i < 2 ? n1 : n2) > 0;
        if (!upright) {
            vertices.pop_back();
            continue;
        }
        made_splits.push_back({m, a, b});
        taken[cell_of(point)].push_back(m);
        triangles[t1] = made[0], triangles[t2] = made[2];
        triangles.push_back(made[1]), triangles.push_back(made[3]);
        for (auto t : {t1, t2, std::uint32_t(triangles.size() - 2), std::uint32_t(triangles.size() - 1)}) holders.enter(t);
    }
}

std::vector<std::uint32_t> unfold(std::vector<Eigen::Vector3d>& vertices, std::vector<std::array<std::int32_t, 3>>& triangles,
                                  const std::vector<Eigen::Vector3d>& normals) {
    auto reference = [&](std::initializer_list<std::int32_t> corners) {
        Eigen::Vector3d m = Eigen::Vector3d::Zero();
        for (auto v : corners)
            if (known(normals, v)) m += normals[std::size_t(v)];
        return m;
    };
    auto folded = [&](const Triangle& t) { return faces_against(vertices, t, reference({t[0], t[1], t[2]})); };
    const std::vector<std::uint32_t> bad = select_in_parallel(triangles.size(), [&](std::size_t i) { return folded(triangles[i]); });
    std::vector<std::uint32_t> rewritten;
    if (bad.empty()) return rewritten;
    // Directed edges of the triangles around the folded ones.
    std::vector<std::uint8_t> near(vertices.size(), 0);
    for (const auto f : bad)
        for (const auto v : triangles[f]) near[std::size_t(v)] = 1;
    EdgeHolders holders(triangles, near, false);
    for (const std::uint32_t f : bad) {
        for (int c = 0; c < 3 && folded(triangles[f]); ++c) {
            const Triangle T = triangles[f];
            const std::int32_t a = T[std::size_t(c)], b = T[std::size_t((c + 1) % 3)], cc = T[std::size_t((c + 2) % 3)];
            const std::int64_t held = holders.of(b, a);
            if (held < 0) continue;
            const auto u = std::uint32_t(held);
            const Triangle U = triangles[u];
            const std::int32_t d = third(U, a, b);
            if (d < 0 || d == cc || holders.of(cc, d) >= 0 || holders.of(d, cc) >= 0) continue;
            const Triangle T2{cc, a, d}, U2{d, b, cc};
            Eigen::Vector3d m = reference({a, b, cc, d});
            if (m.isZero()) continue;
            if (!(area_normal(vertices, T2).dot(m) > 0 && area_normal(vertices, U2).dot(m) > 0)) continue;
            if (folded(T2) || folded(U2)) continue;
            triangles[f] = T2, triangles[u] = U2;
            holders.enter(f), holders.enter(u);
            rewritten.push_back(f), rewritten.push_back(u);
        }
    }
    // Folds no flip undoes: a corner whose triangles all lie in one plane, but which lies past the side of its
    // loop (fans meeting at a concave edge leave a vertex of marching cubes with three triangles so, its loop's
    // sides already edges, where a flip would make one twice; a fan's centre on a sharp edge with three triangles
    // on one face). It moves to the middle of its loop when every one of its triangles then faces the way the plane
    // does: the surface is the same plane, only its triangles change. One plane to a thousandth of the loop's size:
    // a face carried through a warp is flat only that far (the cube turned by the warp, whose corners lie 1e-3
    // voxel off their face's plane).
    std::vector<std::uint32_t> still;
    for (const std::uint32_t f : bad)
        if (folded(triangles[f])) still.push_back(f);
    if (still.empty()) return rewritten;
    std::vector<std::uint8_t> corner(vertices.size(), 0);
    for (const std::uint32_t f : still)
        for (const auto v : triangles[f]) corner[std::size_t(v)] = 1;
    std::unordered_map<std::int32_t, std::vector<std::uint32_t>> around;
    for (const std::uint32_t g : select_in_parallel(triangles.size(), [&](std::size_t i) {
             const Triangle& t = triangles[i];
             return (corner[std::size_t(t[0])] | corner[std::size_t(t[1])] | corner[std::size_t(t[2])]) != 0;
         }))
        for (const auto v : triangles[g])
            if (corner[std::size_t(v)]) around[v].push_back(g);
    for (const std::uint32_t f : still)
        for (int c = 0; c < 3 && folded(triangles[f]); ++c) {
            const std::int32_t v = triangles[f][std::size_t(c)];
            const std::vector<std::uint32_t>& ring = around[v];
            // The loop: each triangle's side across from v, chained into one closed cycle (not so at the region's
            // rim, whose triangles outside it would move unseen).
            std::vector<std::pair<std::int32_t, std::int32_t>> next;
            Eigen::Vector3d reference_sum = Eigen::Vector3d::Zero(), middle = Eigen::Vector3d::Zero(), plane = Eigen::Vector3d::Zero();
            for (const std::uint32_t g : ring) {
                const Triangle& t = triangles[g];
                const int k = t[0] == v ? 0 : t[1] == v ? 1 : 2;
                const std::int32_t a = t[std::size_t((k + 1) % 3)];
                next.push_back({a, t[std::size_t((k + 2) % 3)]});
                reference_sum += reference({t[0], t[1], t[2]});
                middle += vertices[std::size_t(a)];
            }
            std::sort(next.begin(), next.end());
            const bool twice = std::adjacent_find(next.begin(), next.end(), [](const auto& x, const auto& y) { return x.first == y.first; }) != next.end();
            if (ring.size() < 3 || twice || reference_sum.isZero() || closed_cycle(next).empty()) continue;
            middle /= double(ring.size());
            for (const std::uint32_t g : ring) {
                const Eigen::Vector3d n = area_normal(vertices, triangles[g]);
                plane += n.dot(reference_sum) >= 0 ? n : Eigen::Vector3d(-n);
            }
            if (plane.isZero()) continue;
            const Eigen::Vector3d unit = plane.normalized();
            double size = 0, off = std::abs((vertices[std::size_t(v)] - middle).dot(unit));
            for (const auto& [a, b] : next) {
                size = std::max(size, (vertices[std::size_t(a)] - middle).norm());
                off = std::max(off, std::abs((vertices[std::size_t(a)] - middle).dot(unit)));
            }
            if (!(off <= 1e-3 * size)) continue;
            const Eigen::Vector3d was = vertices[std::size_t(v)];
            vertices[std::size_t(v)] = middle;
            const bool upright = std::all_of(ring.begin(), ring.end(), [&](std::uint32_t g) {
                return area_normal(vertices, triangles[g]).dot(unit) > 0 && !folded(triangles[g]);
            });
            if (!upright) {
                vertices[std::size_t(v)] = was;
                continue;
            }
            rewritten.insert(rewritten.end(), ring.begin(), ring.end());
        }
    // Folds left where a corner lies between two of its neighbours on one line (a sharp edge: fans' centres and
    // splits on it): the corner slides along that line, which keeps it on the edge. How each of its triangles faces
    // its corners' normals is linear in the slide, so the slides that unfold them all form an interval; the corner
    // takes the one nearest none, a quarter of the interval inside its ends, and stays between the two.
    for (const std::uint32_t f : still)
        for (int c = 0; c < 3 && folded(triangles[f]); ++c) {
            const std::int32_t v = triangles[f][std::size_t(c)];
            const std::vector<std::uint32_t>& ring = around[v];
            const Eigen::Vector3d x = vertices[std::size_t(v)];
            std::vector<std::int32_t> neighbours;
            for (const std::uint32_t g : ring)
                for (const auto w : triangles[g])
                    if (w != v) neighbours.push_back(w);
            std::sort(neighbours.begin(), neighbours.end());
            neighbours.erase(std::unique(neighbours.begin(), neighbours.end()), neighbours.end());
            // The two neighbours whose line passes nearest the corner (to a fiftieth of their distance), the
            // corner between them.
            double nearest = std::numeric_limits<double>::infinity();
            Eigen::Vector3d p = x, q = x;
            for (std::size_t i = 0; i < neighbours.size(); ++i)
                for (std::size_t j = i + 1; j < neighbours.size(); ++j) {
                    const Eigen::Vector3d &a = vertices[std::size_t(neighbours[i])], &b = vertices[std::size_t(neighbours[j])];
                    const double length = (b - a).norm(), along = (x - a).dot(b - a) / (length * length);
                    const double off = (x - a - along * (b - a)).norm() / length;
                    if (along > 0 && along < 1 && off < 0.02 && off < nearest) nearest = off, p = a, q = b;
                }
            if (!std::isfinite(nearest)) continue;
            const Eigen::Vector3d d = (q - p).normalized();
            double lo_t = (p - x).dot(d), hi_t = (q - x).dot(d); // between the two
            bool feasible = true;
            for (const std::uint32_t g : ring) {
                const Triangle& t = triangles[g];
                const int k = t[0] == v ? 0 : t[1] == v ? 1 : 2;
                const Eigen::Vector3d m = reference({t[0], t[1], t[2]});
                if (m.isZero()) continue;
                const Eigen::Vector3d pa = vertices[std::size_t(t[std::size_t((k + 1) % 3)])] - x, pb = vertices[std::size_t(t[std::size_t((k + 2) % 3)])] - x;
                // ((pa - s d) x (pb - s d)) . m = c0 + e s
                const double c0 = pa.cross(pb).dot(m), e = -(d.cross(pb) + pa.cross(d)).dot(m);
                if (e > 0) lo_t = std::max(lo_t, -c0 / e);
                else if (e < 0) hi_t = std::min(hi_t, -c0 / e);
                else feasible &= c0 > 0;
            }
            if (!feasible || !(lo_t < hi_t)) continue;
            const double inside = 0.25 * (hi_t - lo_t);
            const double slide = std::clamp(0.0, lo_t + inside, hi_t - inside);
            vertices[std::size_t(v)] = x + slide * d;
            if (std::any_of(ring.begin(), ring.end(), [&](std::uint32_t g) { return folded(triangles[g]); })) {
                vertices[std::size_t(v)] = x;
                continue;
            }
            rewritten.insert(rewritten.end(), ring.begin(), ring.end());
        }
    return rewritten;
}

} // namespace voxwarp::extract_internal
