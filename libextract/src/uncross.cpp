// The feature mesher's last pass: triangles that cross another are put back towards marching cubes' mesh, which
// never crosses itself. Moving crossings onto the input's surface, fanning cells to where their tangent planes
// meet, and splitting edges on sharp edges each can push a sheet through its neighbour where the model is thin or
// a feature is tight (the bunny's ear edit at 128: 674 pairs of triangles that CGAL finds crossing or touching,
// over 120 places, 239 of them crossing deeper than 1e-4 voxel).
#include "features.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/intersections.h>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <limits>

namespace voxwarp::extract_internal {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;

Point point(const Eigen::Vector3d& p) { return {p.x(), p.y(), p.z()}; }

/// Whether triangles a and b cross: each passes through the other's plane, by more than `tiny` (world units) on
/// either side, and they meet (exact predicates) where they share no corner, or beyond a shared corner. Sheets that
/// touch are not crossing: the mesher puts fans' centres and splits exactly on a model's corners and edges, where
/// sheets meet at a point or along an edge (a split on one side of an edge only), two corners are one up to
/// round-off, and slivers lie along an edge. Triangles folded flat onto each other (an in-plane fold) are left to
/// unfold().
bool cross(const std::vector<Eigen::Vector3d>& v, const std::array<std::int32_t, 3>& a, const std::array<std::int32_t, 3>& b, double tiny) {
    auto straddles = [&](const std::array<std::int32_t, 3>& t, const std::array<std::int32_t, 3>& plane) {
        const Eigen::Vector3d &p = v[std::size_t(plane[0])], &q = v[std::size_t(plane[1])], &r = v[std::size_t(plane[2])];
        const Eigen::Vector3d n = (q - p).cross(r - p);
        const double length = n.norm();
        if (!(length > 0)) return false;
        bool above = false, below = false;
        for (const auto i : t) {
            const double d = n.dot(v[std::size_t(i)] - p) / length;
            above |= d > tiny, below |= d < -tiny;
        }
        return above && below;
    };
    if (!straddles(a, b) || !straddles(b, a)) return false;
    const std::array<Point, 3> pa{point(v[std::size_t(a[0])]), point(v[std::size_t(a[1])]), point(v[std::size_t(a[2])])};
    const std::array<Point, 3> pb{point(v[std::size_t(b[0])]), point(v[std::size_t(b[1])]), point(v[std::size_t(b[2])])};
    int shared = 0, ia = -1, ib = -1; // a shared corner's place in a and in b
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (a[std::size_t(i)] == b[std::size_t(j)] || (v[std::size_t(a[std::size_t(i)])] - v[std::size_t(b[std::size_t(j)])]).norm() <= tiny)
                ++shared, ia = i, ib = j;
    const Kernel::Triangle_3 ta(pa[0], pa[1], pa[2]), tb(pb[0], pb[1], pb[2]);
    if (shared == 0) return CGAL::do_intersect(ta, tb);
    if (shared == 1) { // the edge facing the shared corner, in either, meets the other triangle
        const Kernel::Segment_3 sa(pa[std::size_t((ia + 1) % 3)], pa[std::size_t((ia + 2) % 3)]);
        const Kernel::Segment_3 sb(pb[std::size_t((ib + 1) % 3)], pb[std::size_t((ib + 2) % 3)]);
        return CGAL::do_intersect(sa, tb) || CGAL::do_intersect(sb, ta);
    }
    return false; // sharing an edge, each lies on one side of the other's plane
}

/// Pairs of triangles whose boxes meet, one of them marked in `some`: each corner's box is given (`lo`, `hi`), the
/// box of every place the corner may take, so that pairs found once serve while corners move. The boxes are filed
/// by the cells of side `cell` they cover, and a pair is reported by the cell holding the low corner of the two
/// boxes' overlap only. CGAL's box_intersection_d took 0.26 s a call on the bunny ear edit at 256, where nearly
/// every triangle is marked; this 0.17 s with cells of two voxels (0.26 s with one: each box in more cells).
std::vector<std::pair<std::uint32_t, std::uint32_t>> meeting_boxes(const std::vector<Eigen::Vector3d>& lo, const std::vector<Eigen::Vector3d>& hi,
                                                                   const std::vector<std::array<std::int32_t, 3>>& triangles, const std::vector<std::uint8_t>& some,
                                                                   double cell) {
    const std::size_t nt = triangles.size();
    std::vector<Eigen::Vector3d> box_lo(nt), box_hi(nt);
    tbb::parallel_for(std::size_t(0), nt, [&](std::size_t t) {
        const auto& f = triangles[t];
        box_lo[t] = lo[std::size_t(f[0])].cwiseMin(lo[std::size_t(f[1])]).cwiseMin(lo[std::size_t(f[2])]);
        box_hi[t] = hi[std::size_t(f[0])].cwiseMax(hi[std::size_t(f[1])]).cwiseMax(hi[std::size_t(f[2])]);
    });
    Eigen::Vector3d origin = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    for (const auto& p : box_lo) origin = origin.cwiseMin(p);
    auto cell_of = [&](const Eigen::Vector3d& p) {
        const Eigen::Vector3d q = (p - origin) / cell;
        return std::array<std::uint64_t, 3>{std::uint64_t(q.x()), std::uint64_t(q.y()), std::uint64_t(q.z())};
    };
    auto key = [](std::uint64_t x, std::uint64_t y, std::uint64_t z) { return x | y << 21 | z << 42; };
    std::vector<std::size_t> first(nt + 1, 0);
    for (std::size_t t = 0; t < nt; ++t) {
        const auto a = cell_of(box_lo[t]), b = cell_of(box_hi[t]);
        first[t + 1] = first[t] + (b[0] - a[0] + 1) * (b[1] - a[1] + 1) * (b[2] - a[2] + 1);
    }
    std::vector<std::pair<std::uint64_t, std::uint32_t>> filed(first[nt]);
    tbb::parallel_for(std::size_t(0), nt, [&](std::size_t t) {
        const auto a = cell_of(box_lo[t]), b = cell_of(box_hi[t]);
        std::size_t at = first[t];
        for (std::uint64_t z = a[2]; z <= b[2]; ++z)
            for (std::uint64_t y = a[1]; y <= b[1]; ++y)
                for (std::uint64_t x = a[0]; x <= b[0]; ++x) filed[at++] = {key(x, y, z), std::uint32_t(t)};
    });
    tbb::parallel_sort(filed.begin(), filed.end());
    std::vector<std::size_t> runs; // where each cell's run starts, and the end
    for (std::size_t i = 0; i < filed.size(); ++i)
        if (i == 0 || filed[i].first != filed[i - 1].first) runs.push_back(i);
    runs.push_back(filed.size());
    tbb::enumerable_thread_specific<std::vector<std::pair<std::uint32_t, std::uint32_t>>> found;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, runs.size() - 1, 256), [&](const auto& range) {
        auto& local = found.local();
        for (std::size_t r = range.begin(); r != range.end(); ++r)
            for (std::size_t i = runs[r]; i < runs[r + 1]; ++i)
                for (std::size_t j = i + 1; j < runs[r + 1]; ++j) {
                    const std::uint32_t a = filed[i].second, b = filed[j].second;
                    if (!some[a] && !some[b]) continue;
                    if ((box_lo[a].array() > box_hi[b].array()).any() || (box_lo[b].array() > box_hi[a].array()).any()) continue;
                    const auto c = cell_of(box_lo[a].cwiseMax(box_lo[b]));
                    if (key(c[0], c[1], c[2]) == filed[i].first) local.push_back({a, b});
                }
    });
    std::vector<std::pair<std::uint32_t, std::uint32_t>> pairs;
    for (const auto& local : found) pairs.insert(pairs.end(), local.begin(), local.end());
    return pairs;
}

/// Among `pairs`, those with a triangle marked in `looked` that cross: their triangles, ascending.
std::vector<std::uint32_t> crossing_triangles(const std::vector<Eigen::Vector3d>& v, const std::vector<std::array<std::int32_t, 3>>& triangles,
                                              const std::vector<std::pair<std::uint32_t, std::uint32_t>>& pairs, const std::vector<std::uint8_t>& looked,
                                              double tiny) {
    std::vector<std::uint8_t> crossing(pairs.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pairs.size(), 4096), [&](const auto& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
            const auto [a, b] = pairs[i];
            if (looked[a] || looked[b]) crossing[i] = cross(v, triangles[a], triangles[b], tiny);
        }
    });
    std::vector<std::uint32_t> out;
    for (std::size_t i = 0; i < pairs.size(); ++i)
        if (crossing[i]) out.push_back(pairs[i].first), out.push_back(pairs[i].second);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

} // namespace

std::vector<std::uint32_t> uncross(std::vector<Eigen::Vector3d>& vertices, const std::vector<std::array<std::int32_t, 3>>& triangles,
                                   const std::vector<Eigen::Vector3d>& marching, const std::vector<std::array<std::int32_t, 3>>& splits, double voxel_size) {
    const std::size_t n = vertices.size();
    const double tiny = 1e-4 * voxel_size;
    // A vertex of marching cubes that the mesher moved goes back towards its own place, a split towards the middle
    // of its edge (which undoes it), a fan's centre towards the middle of its loop: a quarter of the way the first
    // time it is on a crossing triangle, half the second, all the third. Most crossings are shallow (the 24-gon
    // prism's: 1e-4 to 0.013 voxel), and a corner put all the way back loses what the mesher gained there. A fan
    // that still crosses is dropped by the caller. Triangles with a corner the mesher added are new, so they are
    // checked as well.
    constexpr double kWay[] = {0.0, 0.25, 0.5, 1.0};
    const std::vector<Eigen::Vector3d> made = vertices;
    std::vector<std::uint8_t> level(n, 0), mark(n, 1), split(n, 0); // level 3: back, or never moved
    for (std::size_t v = 0; v < marching.size(); ++v) mark[v] = vertices[v] != marching[v], level[v] = mark[v] ? 0 : 3;
    for (const auto& s : splits) split[std::size_t(s[0])] = 1;
    std::vector<Eigen::Vector3d> loop_middle(n, Eigen::Vector3d::Zero()); // a fan centre's: its neighbours' mean
    {
        std::vector<int> count(n, 0);
        for (const auto& t : triangles)
            for (int c = 0; c < 3; ++c) {
                const auto v = std::size_t(t[std::size_t(c)]);
                if (v < marching.size() || split[v]) continue;
                for (int d = 1; d < 3; ++d) loop_middle[v] += made[std::size_t(t[std::size_t((c + d) % 3)])], ++count[v];
            }
        for (std::size_t v = marching.size(); v < n; ++v)
            if (count[v] > 0) loop_middle[v] /= count[v];
            else if (!split[v]) level[v] = 3;
    }
    // Each corner's box over every place it may take: from where the mesher put it to where it goes back (a
    // split's edge's ends move too, in the order made). The pairs of triangles whose boxes meet, found once.
    std::vector<Eigen::Vector3d> lo = made, hi = made;
    for (std::size_t v = 0; v < n; ++v)
        if (level[v] < 3 && !split[v]) {
            const Eigen::Vector3d& to = v < marching.size() ? marching[v] : loop_middle[v];
            lo[v] = lo[v].cwiseMin(to), hi[v] = hi[v].cwiseMax(to);
        }
    for (const auto& [m, a, b] : splits) {
        const auto i = std::size_t(m);
        lo[i] = lo[i].cwiseMin(lo[std::size_t(a)]).cwiseMin(lo[std::size_t(b)]), hi[i] = hi[i].cwiseMax(hi[std::size_t(a)]).cwiseMax(hi[std::size_t(b)]);
    }
    auto with_a_corner_in = [&](const std::vector<std::uint8_t>& corners) {
        std::vector<std::uint8_t> looked(triangles.size(), 0);
        tbb::parallel_for(std::size_t(0), triangles.size(), [&](std::size_t f) {
            const auto& t = triangles[f];
            looked[f] = corners[std::size_t(t[0])] || corners[std::size_t(t[1])] || corners[std::size_t(t[2])];
        });
        return looked;
    };
    std::vector<std::uint8_t> looked = with_a_corner_in(mark);
    const std::vector<std::pair<std::uint32_t, std::uint32_t>> pairs = meeting_boxes(lo, hi, triangles, looked, 2 * voxel_size);
    // Only triangles with a corner moved in the last pass can cross anew. What crosses with every corner back is
    // returned.
    std::vector<std::uint8_t> suspect(triangles.size(), 0);
    for (int pass = 0; pass < 16; ++pass) {
        const std::vector<std::uint32_t> crossing = crossing_triangles(vertices, triangles, pairs, looked, tiny);
        std::vector<std::uint8_t> back(n, 0);
        bool any = false;
        for (const std::uint32_t f : crossing) {
            suspect[f] = 1;
            for (const auto v : triangles[f])
                if (level[std::size_t(v)] < 3 && !back[std::size_t(v)]) ++level[std::size_t(v)], back[std::size_t(v)] = 1, any = true;
        }
        if (!any) break;
        for (std::size_t v = 0; v < n; ++v)
            if (back[v] && !split[v]) vertices[v] = made[v] + kWay[level[v]] * ((v < marching.size() ? marching[v] : loop_middle[v]) - made[v]);
        for (const auto& [m, a, b] : splits) { // in the order made: a split on a split's edge follows it
            const auto i = std::size_t(m);
            if (level[i] == 0) continue;
            const Eigen::Vector3d to = made[i] + kWay[level[i]] * (0.5 * (vertices[std::size_t(a)] + vertices[std::size_t(b)]) - made[i]);
            if (vertices[i] != to) vertices[i] = to, back[i] = 1;
        }
        looked = with_a_corner_in(back);
    }
    // What still crosses: among the triangles that crossed at some pass, those that cross now, and their partners.
    return crossing_triangles(vertices, triangles, pairs, suspect, tiny);
}

} // namespace voxwarp::extract_internal
