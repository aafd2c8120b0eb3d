// The feature mesher's last pass: triangles that cross another are put back towards marching cubes' mesh, which
// never crosses itself. Moving crossings onto the input's surface, fanning cells to where their tangent planes
// meet, and splitting edges on sharp edges each can push a sheet through its neighbour where the model is thin or
// a feature is tight (the bunny's ear edit at 128: 674 pairs of triangles that CGAL finds crossing or touching,
// over 120 places, 239 of them crossing deeper than 1e-4 voxel).
#include "features.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/box_intersection_d.h>
#include <CGAL/intersections.h>

#include <tbb/parallel_for.h>

#include <algorithm>

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

/// The triangles in `checked` that cross any triangle of the mesh, and those they cross.
std::vector<std::uint32_t> crossing_triangles(const std::vector<Eigen::Vector3d>& v, const std::vector<std::array<std::int32_t, 3>>& triangles,
                                              const std::vector<std::uint32_t>& checked, double tiny) {
    using Box = CGAL::Box_intersection_d::Box_with_info_d<double, 3, std::uint32_t>;
    auto box_of = [&](std::uint32_t t) {
        const auto& f = triangles[t];
        const Eigen::Vector3d &a = v[std::size_t(f[0])], &b = v[std::size_t(f[1])], &c = v[std::size_t(f[2])];
        const Eigen::Vector3d lo = a.cwiseMin(b).cwiseMin(c), hi = a.cwiseMax(b).cwiseMax(c);
        return Box(CGAL::Bbox_3(lo.x(), lo.y(), lo.z(), hi.x(), hi.y(), hi.z()), t);
    };
    std::vector<Box> all(triangles.size()), some;
    tbb::parallel_for(std::size_t(0), triangles.size(), [&](std::size_t t) { all[t] = box_of(std::uint32_t(t)); });
    some.reserve(checked.size());
    for (const std::uint32_t t : checked) some.push_back(box_of(t));
    std::vector<std::pair<std::uint32_t, std::uint32_t>> candidates;
    CGAL::box_intersection_d(some.begin(), some.end(), all.begin(), all.end(),
                             [&](const Box& a, const Box& b) {
                                 if (a.info() != b.info()) candidates.push_back({a.info(), b.info()});
                             });
    std::vector<std::uint8_t> crossing(candidates.size(), 0);
    tbb::parallel_for(std::size_t(0), candidates.size(), [&](std::size_t i) {
        crossing[i] = cross(v, triangles[candidates[i].first], triangles[candidates[i].second], tiny);
    });
    std::vector<std::uint32_t> out;
    for (std::size_t i = 0; i < candidates.size(); ++i)
        if (crossing[i]) out.push_back(candidates[i].first), out.push_back(candidates[i].second);
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
    auto with_a_corner_in = [&](const std::vector<std::uint8_t>& corners) {
        return select_in_parallel(triangles.size(), [&](std::size_t f) {
            const auto& t = triangles[f];
            return corners[std::size_t(t[0])] || corners[std::size_t(t[1])] || corners[std::size_t(t[2])];
        });
    };
    // Only triangles with a corner moved in the last pass can cross anew. What crosses with every corner back is
    // returned.
    std::vector<std::uint32_t> checked = with_a_corner_in(mark), suspects;
    for (int pass = 0; pass < 16 && !checked.empty(); ++pass) {
        const std::vector<std::uint32_t> crossing = crossing_triangles(vertices, triangles, checked, tiny);
        std::vector<std::uint8_t> back(n, 0);
        for (const std::uint32_t f : crossing)
            for (const auto v : triangles[f])
                if (level[std::size_t(v)] < 3 && !back[std::size_t(v)]) ++level[std::size_t(v)], back[std::size_t(v)] = 1;
        for (std::size_t v = 0; v < n; ++v)
            if (back[v] && !split[v]) vertices[v] = made[v] + kWay[level[v]] * ((v < marching.size() ? marching[v] : loop_middle[v]) - made[v]);
        for (const auto& [m, a, b] : splits) { // in the order made: a split on a split's edge follows it
            const auto i = std::size_t(m);
            if (level[i] == 0) continue;
            const Eigen::Vector3d to = made[i] + kWay[level[i]] * (0.5 * (vertices[std::size_t(a)] + vertices[std::size_t(b)]) - made[i]);
            if (vertices[i] != to) vertices[i] = to, back[i] = 1;
        }
        suspects.insert(suspects.end(), crossing.begin(), crossing.end());
        checked = with_a_corner_in(back);
    }
    // What still crosses: among the triangles that crossed at some pass, those that cross now, and their partners.
    std::sort(suspects.begin(), suspects.end());
    suspects.erase(std::unique(suspects.begin(), suspects.end()), suspects.end());
    return suspects.empty() ? suspects : crossing_triangles(vertices, triangles, suspects, tiny);
}

} // namespace voxwarp::extract_internal
