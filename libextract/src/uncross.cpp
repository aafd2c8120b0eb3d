// The feature mesher's last pass: triangles that cross another are put back towards marching cubes' mesh, which
// never crosses itself. Moving crossings onto the input's surface, fanning cells to where their tangent planes
// meet, and splitting edges on sharp edges each can push a sheet through its neighbour where the model is thin or
// a feature is tight (the bunny's ear edit at 128: 674 pairs of triangles that CGAL finds crossing or touching,
// over 120 places, 239 of them crossing deeper than 1e-4 voxel).
#include "features.h"

#include <voxwarp_internal/geometry.h>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/intersections.h>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <limits>
#include <numeric>

namespace voxwarp::extract_internal {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;

Point point(const Eigen::Vector3d& p) { return {p.x(), p.y(), p.z()}; }

/// Whether triangles a and b cross: each passes through the other's plane, by more than `tiny` (world units) on
/// either side, and they meet (exact predicates) where they share no corner, or beyond a shared corner. Sheets that
/// touch to round-off are not crossing: the mesher puts fans' centres and splits exactly on a model's corners and
/// edges, where slivers lie along an edge. Triangles folded flat onto each other (an in-plane fold) are left to
/// unfold(). `tiny` was a ten-thousandth of a voxel while distinct vertices could share a position (around them
/// every pair of faces touches); it let through crossings that CGAL finds: 37 pairs on the bunny ear edit at 128.
bool cross(const std::vector<Eigen::Vector3d>& v, const std::array<std::int32_t, 3>& a, const std::array<std::int32_t, 3>& b, double tiny) {
    auto straddles = [&](const std::array<std::int32_t, 3>& t, const std::array<std::int32_t, 3>& plane) {
        return internal::straddle_depth(v[std::size_t(t[0])], v[std::size_t(t[1])], v[std::size_t(t[2])], v[std::size_t(plane[0])], v[std::size_t(plane[1])],
                                        v[std::size_t(plane[2])]) > tiny;
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

/// Where the pass may put each vertex: where the mesher made it, and where it goes back to. A vertex of marching
/// cubes goes back to its own place; a fan's centre to the middle of its loop; a split to the middle of the edge it
/// split, whose ends move too. The box of every place a vertex may take is kept for the mesher's vertices only:
/// marching cubes' are the box of their two places.
class Reach {
public:
    Reach(const std::vector<Eigen::Vector3d>& made, const std::vector<Eigen::Vector3d>& marching) : made_(made), marching_(marching) {}
    std::size_t marching_count() const { return marching_.size(); }
    const Eigen::Vector3d& made(std::size_t v) const { return made_[v]; }
    const Eigen::Vector3d& marching(std::size_t v) const { return marching_[v]; }
    /// The mesher's vertices' boxes, filled by the caller.
    std::vector<Eigen::Vector3d> lo, hi;
    void box(std::size_t v, Eigen::Vector3d& l, Eigen::Vector3d& h) const {
        if (v < marching_.size()) l = l.cwiseMin(made_[v]).cwiseMin(marching_[v]), h = h.cwiseMax(made_[v]).cwiseMax(marching_[v]);
        else l = l.cwiseMin(lo[v - marching_.size()]), h = h.cwiseMax(hi[v - marching_.size()]);
    }
    void box(const std::array<std::int32_t, 3>& t, Eigen::Vector3d& l, Eigen::Vector3d& h) const {
        l = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), h = -l;
        for (const auto v : t) box(std::size_t(v), l, h);
    }

private:
    const std::vector<Eigen::Vector3d>& made_;
    const std::vector<Eigen::Vector3d>& marching_;
};

/// cell_bound()'s answer for a triangle that may leave its cell.
constexpr std::uint64_t kFree = ~std::uint64_t(0);

/// A triangle's cell (its key) when it lies in one cell of the grid wherever its corners go, each corner on a grid
/// edge or inside the cell; kFree when not. Such a triangle is one of marching cubes' whose corners were moved along
/// their grid edges, or not at all. Two such triangles in different cells meet only on the plane between the cells,
/// where each holds only what its corners on the cells' common grid edges span: a point, or a chord of the common
/// face. Marching cubes puts one vertex on a grid edge and never joins two of a face's crossings across the face,
/// so the chords of two cells share their ends or lie apart: the triangles touch at a corner or not at all, and
/// need no test (FeatureMesher.MarchingCubesTrianglesOfDifferentCellsNeverCross... in snap_test checks this).
/// Within one cell they can cross once their corners slide. The cell is the one holding the centre of marching
/// cubes' triangle, so that it is marching cubes' own.
std::uint64_t cell_bound(const Reach& reach, const std::array<std::int32_t, 3>& t, const SparseVoxmap& voxmap) {
    constexpr double kOn = 1e-5; // index units: round-off of a point put on a grid edge
    Eigen::Vector3d low = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), high = -low, sum = Eigen::Vector3d::Zero();
    for (const auto corner : t) {
        const auto v = std::size_t(corner);
        if (v >= reach.marching_count()) return kFree;
        const Eigen::Vector3d p = voxmap.index_of(reach.made(v)), q = voxmap.index_of(reach.marching(v));
        if (p != q) { // moved: along one grid edge only
            int along = 0;
            for (int a = 0; a < 3; ++a) {
                const double r = std::round(q[a]);
                if (std::abs(p[a] - r) > kOn || std::abs(q[a] - r) > kOn) ++along;
            }
            if (along > 1) return kFree;
        }
        low = low.cwiseMin(p).cwiseMin(q), high = high.cwiseMax(p).cwiseMax(q), sum += q;
    }
    Index3 c;
    for (int a = 0; a < 3; ++a) {
        c[std::size_t(a)] = std::int64_t(std::floor(sum[a] / 3));
        if (low[a] < double(c[std::size_t(a)]) - kOn || high[a] > double(c[std::size_t(a)]) + 1 + kOn) return kFree;
    }
    return cell_key(c);
}

/// Pairs of triangles, in the lists where threads found them (joining the lists into one took a tenth of the pass).
using Pairs = std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>>;

/// Pairs of triangles that may cross while their corners move within `reach`, one of them marked in `some`, other
/// than two of one cell (crossing_triangles() walks those): a free triangle (kFree in `cell`: a fan's, a split's,
/// one with a corner moved off its grid edge, one unfolded) and another whose box meets its box. Free triangles are
/// filed by the cells of side `side` their boxes cover, and a pair is reported by the cell holding the low corner
/// of the two boxes' overlap only. Filing every triangle by
/// the cells of its box, as at first, took 0.17 s a call on the bunny ear edit at 256, for pairs in different cells
/// that cannot cross.
Pairs pairs_that_may_cross(const Reach& reach, const std::vector<std::array<std::int32_t, 3>>& triangles, const std::vector<std::uint64_t>& cell,
                           const std::vector<std::uint8_t>& some, double side, const SparseVoxmap& voxmap) {
    const std::size_t nt = triangles.size();
    tbb::enumerable_thread_specific<std::vector<std::pair<std::uint32_t, std::uint32_t>>> found;
    const std::vector<std::uint32_t> loose = select_in_parallel(nt, [&](std::size_t t) { return cell[t] == kFree; });
    if (loose.empty()) return {};
    std::vector<Eigen::Vector3d> loose_lo(loose.size()), loose_hi(loose.size());
    tbb::parallel_for(std::size_t(0), loose.size(), [&](std::size_t i) { reach.box(triangles[loose[i]], loose_lo[i], loose_hi[i]); });
    Eigen::Vector3d origin = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    for (const auto& p : loose_lo) origin = origin.cwiseMin(p);
    auto cell_of = [&](const Eigen::Vector3d& p) {
        const Eigen::Vector3d q = ((p - origin) / side).cwiseMax(0.0);
        return std::array<std::uint64_t, 3>{std::uint64_t(q.x()), std::uint64_t(q.y()), std::uint64_t(q.z())};
    };
    auto key = [](std::uint64_t x, std::uint64_t y, std::uint64_t z) { return x | y << 21 | z << 42; };
    auto for_each_cell = [&](const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const auto& f) {
        const auto a = cell_of(lo), b = cell_of(hi);
        for (std::uint64_t z = a[2]; z <= b[2]; ++z)
            for (std::uint64_t y = a[1]; y <= b[1]; ++y)
                for (std::uint64_t x = a[0]; x <= b[0]; ++x) f(key(x, y, z));
    };
    // (cell, place in loose), sorted.
    std::vector<std::size_t> first(loose.size() + 1, 0);
    for (std::size_t i = 0; i < loose.size(); ++i) {
        std::size_t cells = 0;
        for_each_cell(loose_lo[i], loose_hi[i], [&](std::uint64_t) { ++cells; });
        first[i + 1] = first[i] + cells;
    }
    std::vector<std::pair<std::uint64_t, std::uint32_t>> filed(first.back());
    tbb::parallel_for(std::size_t(0), loose.size(), [&](std::size_t i) {
        std::size_t at = first[i];
        for_each_cell(loose_lo[i], loose_hi[i], [&](std::uint64_t k) { filed[at++] = {k, std::uint32_t(i)}; });
    });
    tbb::parallel_sort(filed.begin(), filed.end());
    // Whether triangle a (box lo, hi) and the p-th free one are a pair, reported in cell k: one of them marked, their
    // boxes meeting, and k holding the low corner of the overlap.
    auto reported = [&](std::uint32_t a, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, std::uint32_t p, std::uint64_t k) {
        if (!(some[a] || some[loose[p]]) || (lo.array() > loose_hi[p].array()).any() || (loose_lo[p].array() > hi.array()).any()) return false;
        const auto c = cell_of(lo.cwiseMax(loose_lo[p]));
        return key(c[0], c[1], c[2]) == k;
    };
    // Which cells hold a free triangle, a bit each where they are not too many (a model filling a 512 voxmap: 2 MiB
    // of bits; past 16 MiB, none, and every cell is looked up): most triangles have no free one near them, and are
    // passed by at the cost of a bit.
    const Eigen::Vector3d top = std::accumulate(loose_hi.begin(), loose_hi.end(), origin, [](const Eigen::Vector3d& m, const Eigen::Vector3d& p) { return m.cwiseMax(p); });
    const auto last = cell_of(top);
    const std::uint64_t nx = last[0] + 1, ny = last[1] + 1, nz = last[2] + 1;
    std::vector<std::uint64_t> held;
    if (nx * ny * nz <= (std::uint64_t(1) << 27)) {
        held.assign((nx * ny * nz + 63) / 64, 0);
        for (const auto& [k, i] : filed) {
            const std::uint64_t bit = (k & 0x1fffff) + nx * ((k >> 21 & 0x1fffff) + ny * (k >> 42));
            held[bit / 64] |= std::uint64_t(1) << (bit % 64);
        }
    }
    auto may_hold = [&](std::uint64_t k) {
        const std::uint64_t x = k & 0x1fffff, y = k >> 21 & 0x1fffff, z = k >> 42;
        if (x >= nx || y >= ny || z >= nz) return false;
        if (held.empty()) return true;
        const std::uint64_t bit = x + nx * (y + ny * z);
        return (held[bit / 64] >> (bit % 64) & 1) != 0;
    };
    // Free with free.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, filed.size(), 1024), [&](const auto& range) {
        auto& local = found.local();
        for (std::size_t i = range.begin(); i != range.end(); ++i)
            for (std::size_t j = i + 1; j < filed.size() && filed[j].first == filed[i].first; ++j) {
                const std::uint32_t p = filed[i].second, q = filed[j].second;
                if (reported(loose[p], loose_lo[p], loose_hi[p], q, filed[i].first)) local.push_back({loose[p], loose[q]});
            }
    });
    // The others with free ones, looked up from the others' side.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nt, 4096), [&](const auto& range) {
        auto& local = found.local();
        Eigen::Vector3d lo, hi;
        for (std::size_t a = range.begin(); a != range.end(); ++a) {
            if (cell[a] == kFree) continue;
            // It stays in its cell (cell_bound): the free ones' cells that cell meets are all it may meet. Triangles
            // far from the free ones are passed by without reading their corners (this loop 13 -> 10 ms at 256).
            const Index3 c = key_cell(cell[a]);
            constexpr double kSlack = 1e-3; // index units, over cell_bound's own
            bool near = false;
            for_each_cell(voxmap.world(double(c[0]) - kSlack, double(c[1]) - kSlack, double(c[2]) - kSlack),
                          voxmap.world(double(c[0]) + 1 + kSlack, double(c[1]) + 1 + kSlack, double(c[2]) + 1 + kSlack), [&](std::uint64_t k) { near |= may_hold(k); });
            if (!near) continue;
            reach.box(triangles[a], lo, hi);
            if ((hi.array() < origin.array()).any()) continue;
            for_each_cell(lo, hi, [&](std::uint64_t k) {
                if (!may_hold(k)) return;
                for (auto it = std::lower_bound(filed.begin(), filed.end(), std::pair(k, std::uint32_t(0))); it != filed.end() && it->first == k; ++it) {
                    if (reported(std::uint32_t(a), lo, hi, it->second, k)) local.push_back({std::uint32_t(a), loose[it->second]});
                }
            });
        }
    });
    Pairs pairs;
    for (auto& local : found) pairs.push_back(std::move(local));
    return pairs;
}

/// Those triangles that cross another with one of the two marked in `looked`, ascending: among `pairs`, and among
/// the triangles of each cell (`cell`, in one run of the triangles that are not free, as pairs_that_may_cross says).
std::vector<std::uint32_t> crossing_triangles(const std::vector<Eigen::Vector3d>& v, const std::vector<std::array<std::int32_t, 3>>& triangles,
                                              const Pairs& pairs, const std::vector<std::uint64_t>& cell, const std::vector<std::uint8_t>& looked, double tiny) {
    const std::size_t nt = triangles.size();
    tbb::enumerable_thread_specific<std::vector<std::uint32_t>> found;
    for (const auto& list : pairs)
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, list.size(), 4096), [&](const auto& range) {
            auto& local = found.local();
            for (std::size_t i = range.begin(); i != range.end(); ++i) {
                const auto [a, b] = list[i];
                if ((looked[a] || looked[b]) && cross(v, triangles[a], triangles[b], tiny)) local.push_back(a), local.push_back(b);
            }
        });
    // Each marked triangle with the others in its cell's run (the free ones between do not end a run): those after
    // it, and those before it that are not marked (a marked one found the pair itself). Walking from the marked
    // ones only, later passes (a few hundred marked) skip the rest of the mesh.
    const std::vector<std::uint32_t> marked = select_in_parallel(nt, [&](std::size_t f) { return looked[f] && cell[f] != kFree; });
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, marked.size(), 1024), [&](const auto& range) {
        auto& local = found.local();
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
            const std::size_t x = marked[i];
            for (std::size_t b = x + 1; b < nt && (cell[b] == cell[x] || cell[b] == kFree); ++b)
                if (cell[b] == cell[x] && cross(v, triangles[x], triangles[b], tiny)) local.push_back(std::uint32_t(x)), local.push_back(std::uint32_t(b));
            for (std::size_t a = x; a-- > 0 && (cell[a] == cell[x] || cell[a] == kFree);)
                if (cell[a] == cell[x] && !looked[a] && cross(v, triangles[a], triangles[x], tiny)) local.push_back(std::uint32_t(a)), local.push_back(std::uint32_t(x));
        }
    });
    std::vector<std::uint32_t> out;
    for (const auto& local : found) out.insert(out.end(), local.begin(), local.end());
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

} // namespace

std::vector<std::uint32_t> uncross(std::vector<Eigen::Vector3d>& vertices, const std::vector<std::array<std::int32_t, 3>>& triangles,
                                   const std::vector<Eigen::Vector3d>& marching, const std::vector<std::array<std::int32_t, 3>>& splits,
                                   const std::vector<std::uint32_t>& unfolded, const SparseVoxmap& voxmap) {
    const std::size_t n = vertices.size(), nm = marching.size(), nt = triangles.size();
    const double tiny = 1e-12 * voxmap.voxel_size(); // deeper than round-off
    // A vertex of marching cubes that the mesher moved goes back towards its own place, a split towards the middle
    // of its edge (which undoes it), a fan's centre towards the middle of its loop: a quarter of the way the first
    // time it is on a crossing triangle, half the second, all the third. Most crossings are shallow (the 24-gon
    // prism's: 1e-4 to 0.013 voxel), and a corner put all the way back loses what the mesher gained there. A fan
    // that still crosses is dropped by the caller. Triangles with a corner the mesher added are new, so they are
    // checked as well.
    constexpr double kWay[] = {0.0, 0.25, 0.5, 1.0};
    const std::vector<Eigen::Vector3d> made = vertices;
    std::vector<std::uint8_t> level(n, 0), moved(n, 1), split(n - nm, 0); // level 3: back, or never moved
    tbb::parallel_for(std::size_t(0), nm, [&](std::size_t v) { moved[v] = vertices[v] != marching[v], level[v] = moved[v] ? 0 : 3; });
    for (const auto& s : splits) split[std::size_t(s[0]) - nm] = 1;
    std::vector<Eigen::Vector3d> loop_middle(n - nm, Eigen::Vector3d::Zero()); // a fan centre's: its neighbours' mean
    {
        std::vector<int> count(n - nm, 0);
        for (const auto& t : triangles)
            for (int c = 0; c < 3; ++c) {
                const auto v = std::size_t(t[std::size_t(c)]);
                if (v < nm || split[v - nm]) continue;
                for (int d = 1; d < 3; ++d) loop_middle[v - nm] += made[std::size_t(t[std::size_t((c + d) % 3)])], ++count[v - nm];
            }
        for (std::size_t i = 0; i < n - nm; ++i)
            if (count[i] > 0) loop_middle[i] /= count[i];
            else if (!split[i]) level[nm + i] = 3;
    }
    // The box of every place each vertex may take: from where the mesher put it to where it goes back (a split's
    // edge's ends move too, in the order made).
    Reach reach(made, marching);
    reach.lo.assign(made.begin() + std::ptrdiff_t(nm), made.end()), reach.hi = reach.lo;
    for (std::size_t i = 0; i < n - nm; ++i)
        if (level[nm + i] < 3 && !split[i]) reach.lo[i] = reach.lo[i].cwiseMin(loop_middle[i]), reach.hi[i] = reach.hi[i].cwiseMax(loop_middle[i]);
    for (const auto& [m, a, b] : splits) {
        Eigen::Vector3d l = reach.lo[std::size_t(m) - nm], h = reach.hi[std::size_t(m) - nm];
        reach.box(std::size_t(a), l, h), reach.box(std::size_t(b), l, h);
        reach.lo[std::size_t(m) - nm] = l, reach.hi[std::size_t(m) - nm] = h;
    }
    std::vector<std::uint64_t> cell(nt);
    tbb::parallel_for(std::size_t(0), nt, [&](std::size_t f) { cell[f] = cell_bound(reach, triangles[f], voxmap); });
    for (const std::uint32_t f : unfolded) cell[f] = kFree;
    auto with_a_corner_in = [&](const std::vector<std::uint8_t>& corners) {
        std::vector<std::uint8_t> looked(nt, 0);
        tbb::parallel_for(std::size_t(0), nt, [&](std::size_t f) {
            const auto& t = triangles[f];
            looked[f] = corners[std::size_t(t[0])] || corners[std::size_t(t[1])] || corners[std::size_t(t[2])];
        });
        return looked;
    };
    std::vector<std::uint8_t> looked = with_a_corner_in(moved);
    const Pairs pairs = pairs_that_may_cross(reach, triangles, cell, looked, 2 * voxmap.voxel_size(), voxmap);
    // Only triangles with a corner moved in the last pass can cross anew. What crosses with every corner back is
    // returned.
    std::vector<std::uint8_t> suspect(nt, 0);
    for (int pass = 0; pass < 16; ++pass) {
        const std::vector<std::uint32_t> crossing = crossing_triangles(vertices, triangles, pairs, cell, looked, tiny);
        std::vector<std::uint8_t> back(n, 0);
        bool any = false;
        for (const std::uint32_t f : crossing) {
            suspect[f] = 1;
            for (const auto v : triangles[f])
                if (level[std::size_t(v)] < 3 && !back[std::size_t(v)]) ++level[std::size_t(v)], back[std::size_t(v)] = 1, any = true;
        }
        if (!any) break;
        for (std::size_t v = 0; v < n; ++v)
            if (back[v] && (v < nm || !split[v - nm])) vertices[v] = made[v] + kWay[level[v]] * ((v < nm ? marching[v] : loop_middle[v - nm]) - made[v]);
        for (const auto& [m, a, b] : splits) { // in the order made: a split on a split's edge follows it
            const auto i = std::size_t(m);
            if (level[i] == 0) continue;
            const Eigen::Vector3d to = made[i] + kWay[level[i]] * (0.5 * (vertices[std::size_t(a)] + vertices[std::size_t(b)]) - made[i]);
            if (vertices[i] != to) vertices[i] = to, back[i] = 1;
        }
        looked = with_a_corner_in(back);
    }
    // What still crosses: among the triangles that crossed at some pass, those that cross now, and their partners.
    return crossing_triangles(vertices, triangles, pairs, cell, suspect, tiny);
}

} // namespace voxwarp::extract_internal
