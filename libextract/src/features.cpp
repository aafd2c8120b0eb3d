// Sharp features on marching cubes' output (Extended Marching Cubes, Kobbelt, Botsch, Schwanecke & Seidel 2001):
// normals at the crossings, a vertex where a cell's tangent planes meet, fans around it, and flips that join
// neighbouring feature vertices along the edge; then the edges still cut across a sharp edge are split on it
// (feature_edges.cpp). See extract.h for what it promises; marching_cubes.cpp for the mesh it starts from (every
// vertex on a grid edge, every triangle inside one cell).
#include "features.h"

#include <voxwarp_internal/geometry.h>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <limits>
#include <set>
#include <unordered_map>
#include <unordered_set>

namespace voxwarp::extract_internal {

namespace {

/// A feature surface's triangles filed by the cells their bounding boxes touch (CellBuckets).
class TriangleGrid {
public:
    TriangleGrid(const TriangleMesh& s, const SparseVoxmap& v) : surface_(s), cells_(v), near_(v) {
        cells_.reserve(s.triangles.size());
        for (std::size_t t = 0; t < s.triangles.size(); ++t) {
            const auto [box_lo, box_hi] = box(t);
            const Eigen::Vector3d lo = v.index_of(box_lo), hi = v.index_of(box_hi);
            if (((hi - lo).array() > 64).any()) continue; // not a voxel-sized piece: the surface was not cut for this voxmap
            cells_.add(lo, hi, std::uint32_t(t));
            // Its cells grown by one: hit() and nearest() around a cell read it and its neighbours.
            const Index3 first = cell_containing(lo), last = cell_containing(hi);
            near_.mark({first[0] - 1, first[1] - 1, first[2] - 1}, {last[0] + 1, last[1] + 1, last[2] + 1});
        }
        cells_.build();
    }
    /// False when no cell within one of `c` holds a triangle (true may still mean none: blocks are coarse): hit()
    /// and nearest() around it would find nothing.
    bool near(const Index3& c) const { return near_.any(c, c); }
    /// Likewise for the cells in [lo, hi].
    bool near(const Index3& lo, const Index3& hi) const { return near_.any(lo, hi); }
    /// Where the segment a -> b meets the surface (parameter t in [0, 1] and the face's unit normal), the meeting
    /// nearest to `near_t`; false when it meets none of the triangles in the voxels given.
    bool hit(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const std::array<Index3, 2>& voxels, double near_t, double& t_out, Eigen::Vector3d& normal) const {
        const Eigen::Vector3d d = b - a;
        double best = std::numeric_limits<double>::infinity();
        const Eigen::Vector3d lo = a.cwiseMin(b), hi = a.cwiseMax(b);
        for (const Index3& cell : voxels)
            for (std::uint32_t t : cells_.at(cell)) {
                const auto [box_lo, box_hi] = box(t);
                if ((box_lo.array() > hi.array()).any() || (box_hi.array() < lo.array()).any()) continue; // boxes apart
                const auto& f = surface_.triangles[t];
                const Eigen::Vector3d &p = surface_.vertices[std::size_t(f[0])], &q = surface_.vertices[std::size_t(f[1])], &r = surface_.vertices[std::size_t(f[2])];
                const double t_hit = internal::line_meets_triangle(a, d, p, q, r, 1e-9);
                if (!(t_hit >= 0 && t_hit <= 1) || std::abs(t_hit - near_t) >= best) continue;
                best = std::abs(t_hit - near_t);
                t_out = t_hit;
                normal = (q - p).cross(r - p).normalized();
            }
        return std::isfinite(best);
    }

    /// The nearest point of the surface's triangles in the 3^3 voxels around `p`'s voxel within `radius`, with its
    /// triangle's unit normal; false when none is that near.
    bool nearest(const Eigen::Vector3d& p, const SparseVoxmap& v, double radius, Eigen::Vector3d& point, Eigen::Vector3d& normal) const {
        const Index3 c = cell_containing(v.index_of(p));
        double best = radius;
        bool found = false;
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx)
                    for (std::uint32_t t : cells_.at({c[0] + dx, c[1] + dy, c[2] + dz})) {
                        // Most triangles in the 27 cells lie beyond the radius: their boxes tell, before the
                        // closest point (which was most of the pass over the vertices).
                        const auto [lo, hi] = box(t);
                        if ((p.cwiseMax(lo).cwiseMin(hi) - p).squaredNorm() >= best * best) continue;
                        const auto& f = surface_.triangles[t];
                        const Eigen::Vector3d x = internal::closest_on_triangle(p, surface_.vertices[std::size_t(f[0])], surface_.vertices[std::size_t(f[1])], surface_.vertices[std::size_t(f[2])]);
                        const double d = (x - p).norm();
                        if (d < best) {
                            best = d, point = x, found = true;
                            const Eigen::Vector3d n = (surface_.vertices[std::size_t(f[1])] - surface_.vertices[std::size_t(f[0])]).cross(surface_.vertices[std::size_t(f[2])] - surface_.vertices[std::size_t(f[0])]);
                            normal = n.normalized();
                        }
                    }
        return found;
    }

private:
    const TriangleMesh& surface_;
    CellBuckets cells_;
    CoarseMarks near_; ///< the cells within one of a triangle's
    /// Triangle t's bounding box, world units: worked out where asked, as a list of them (2.8 MiB for the bunny at
    /// 256) cost more in fresh pages than the few multiplies.
    std::pair<Eigen::Vector3d, Eigen::Vector3d> box(std::size_t t) const {
        const auto& f = surface_.triangles[t];
        const Eigen::Vector3d &a = surface_.vertices[std::size_t(f[0])], &b = surface_.vertices[std::size_t(f[1])], &c = surface_.vertices[std::size_t(f[2])];
        return {a.cwiseMin(b).cwiseMin(c), a.cwiseMax(b).cwiseMax(c)};
    }
};

/// A set of cells, a bit each, in 8^3 blocks kept where one of their cells is in it.
class CellSet {
public:
    explicit CellSet(const SparseVoxmap& v) : grid_(v), slot_(grid_.block_count(), -1) {}
    /// Adds the cells in [lo, hi] (inclusive; those beyond the grid are left out), a row of a block at a time.
    void insert(const Index3& lo, const Index3& hi) {
        for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
            for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
                for (std::int64_t x = lo[0]; x <= hi[0];) {
                    const Index3 c{x, y, z};
                    const std::size_t at = BlockGrid::local(c); // bit x + 8 y of word z
                    const std::int64_t run = std::min<std::int64_t>(hi[0] - x + 1, 8 - std::int64_t(at % 8));
                    if (const std::int64_t b = grid_.block_of(c); b >= 0) {
                        std::int32_t& s = slot_[std::size_t(b)];
                        if (s < 0) s = std::int32_t(bits_.size()), bits_.emplace_back();
                        bits_[std::size_t(s)][at / 64] |= ((std::uint64_t(1) << run) - 1) << (at % 64);
                    }
                    x += run;
                }
    }
    /// False when no cell in [lo, hi] is in the set (true may still mean none: blocks are coarse).
    bool any(const Index3& lo, const Index3& hi) const {
        return grid_.visit_blocks(lo, hi, [&](std::size_t b) { return slot_[b] >= 0; });
    }
    bool contains(const Index3& c) const {
        const std::int64_t b = grid_.block_of(c);
        if (b < 0 || slot_[std::size_t(b)] < 0) return false;
        const std::size_t at = BlockGrid::local(c);
        return (bits_[std::size_t(slot_[std::size_t(b)])][at / 64] >> (at % 64) & 1) != 0;
    }

private:
    BlockGrid grid_;
    std::vector<std::int32_t> slot_; ///< per block: its place in bits_, or -1
    std::vector<std::array<std::uint64_t, 8>> bits_;
};

/// A vertex's grid edge: the low voxel and the axis (or axis -1 for a vertex that is not on one, a fan centre).
struct GridEdge {
    Index3 low{};
    int axis = -1;
    double t = 0;
};

GridEdge edge_of(const SparseVoxmap& v, const Eigen::Vector3d& p) {
    const Eigen::Vector3d q = v.index_of(p);
    GridEdge e;
    int fractional = 0;
    for (int a = 0; a < 3; ++a) {
        const double r = std::round(q[a]);
        if (std::abs(q[a] - r) > 1e-5) ++fractional, e.axis = a;
    }
    if (fractional == 0) { // on a grid node: the surface passes through a voxel centre; its +x edge stands in
        for (int a = 0; a < 3; ++a) e.low[std::size_t(a)] = std::int64_t(std::round(q[a]));
        e.axis = 0, e.t = 0;
        return e;
    }
    if (fractional != 1) return {};
    for (int a = 0; a < 3; ++a) e.low[std::size_t(a)] = a == e.axis ? std::int64_t(std::floor(q[a])) : std::int64_t(std::round(q[a]));
    e.t = q[e.axis] - double(e.low[std::size_t(e.axis)]);
    return e;
}

/// Outward normal from the density's gradient (it decreases outwards), linear along the edge between its ends'
/// central differences.
Eigen::Vector3d gradient_normal(const SparseVoxmap& v, const GridEdge& e) {
    auto grad = [&](const Index3& c) {
        return Eigen::Vector3d(double(v.at(c[0] + 1, c[1], c[2])) - v.at(c[0] - 1, c[1], c[2]), double(v.at(c[0], c[1] + 1, c[2])) - v.at(c[0], c[1] - 1, c[2]),
                               double(v.at(c[0], c[1], c[2] + 1)) - v.at(c[0], c[1], c[2] - 1));
    };
    Index3 high = e.low;
    ++high[std::size_t(e.axis)];
    const Eigen::Vector3d g = (1 - e.t) * grad(e.low) + e.t * grad(high);
    const double n = g.norm();
    return n > 0 ? Eigen::Vector3d(-g / n) : Eigen::Vector3d::Zero();
}

/// The least-squares x of A x = b smallest in norm, singular values below a tenth of the largest dropped (a
/// direction the equations barely hold stays free); `rank` counts those kept.
Eigen::Vector3d truncated_solve(const Eigen::Matrix3d& A, const Eigen::Vector3d& b, int& rank) {
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Vector3d sigma = svd.singularValues();
    Eigen::Vector3d inverse = Eigen::Vector3d::Zero();
    rank = 0;
    for (int i = 0; i < 3; ++i)
        if (sigma[i] > 0.1 * sigma[0]) inverse[i] = 1.0 / sigma[i], ++rank;
    return svd.matrixV() * inverse.asDiagonal() * svd.matrixU().transpose() * b;
}

/// The point nearest the mass point `centre` where tangent planes (point, normal) meet (an edge leaves one
/// direction free, a plane two).
Eigen::Vector3d qef_point(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3d>& normals, const Eigen::Vector3d& centre, int& rank) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < points.size(); ++i) {
        A += normals[i] * normals[i].transpose();
        b += normals[i] * normals[i].dot(points[i] - centre);
    }
    return centre + truncated_solve(A, b, rank);
}

/// The stretches of the input's sharp edges inside one cell, and the point that stands for them. Where edges meet
/// at a corner in the cell, a plain mean of the stretches' middles lies off every edge, between them (turned cubes
/// lost up to 0.18 voxel of edge to such points).
class EdgeStretches {
public:
    void add(const Eigen::Vector3d& middle, const Eigen::Vector3d& direction, double length) {
        if (length > 0) stretches_.push_back({middle, direction.normalized(), length});
    }
    bool empty() const { return stretches_.empty(); }
    /// The point nearest all the stretches' lines (a corner in the cell), nearest their length-weighted middle
    /// along the directions the lines leave free (for one straight edge, that middle).
    Eigen::Vector3d point() const {
        Eigen::Matrix3d lines = Eigen::Matrix3d::Zero();
        Eigen::Vector3d moment = Eigen::Vector3d::Zero(), centre = Eigen::Vector3d::Zero();
        double length = 0;
        for (const auto& s : stretches_) {
            const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - s.direction * s.direction.transpose();
            lines += s.length * across, moment += s.length * across * s.middle, centre += s.length * s.middle, length += s.length;
        }
        centre /= length;
        int rank = 0;
        return centre + truncated_solve(lines, moment - lines * centre, rank);
    }

private:
    struct Stretch {
        Eigen::Vector3d middle, direction;
        double length;
    };
    std::vector<Stretch> stretches_;
};

/// Each pair (a, b), a < b, of the items of `by_x` (x, item) whose x lie within `apart` of each other: `by_x` is
/// sorted, then the pairs go to `f` by the place of their lower x, then the higher. The points themselves are
/// compared by the caller.
template <class F>
void pairs_near_in_x(std::vector<std::pair<double, std::uint32_t>>& by_x, double apart, F&& f) {
    tbb::parallel_sort(by_x.begin(), by_x.end());
    for (std::size_t i = 0; i < by_x.size(); ++i)
        for (std::size_t j = i + 1; j < by_x.size() && by_x[j].first - by_x[i].first < apart; ++j)
            f(std::min(by_x[i].second, by_x[j].second), std::max(by_x[i].second, by_x[j].second));
}

} // namespace

bool on_grid_edge(const SparseVoxmap& voxmap, const Eigen::Vector3d& p) { return edge_of(voxmap, p).axis >= 0; }

TriangleMesh restore_features(TriangleMesh mesh, const SparseVoxmap& voxmap, const ExtractOptions& options, const std::vector<MarchingBlock>& blocks) {
    const double h = voxmap.voxel_size(), margin = edge_margin(voxmap);
    const double cos_feature = std::cos(options.feature_angle * M_PI / 180.0);
    const std::size_t nv = mesh.vertices.size();
    // Per vertex: whether it lies on a grid edge, has a normal, and was moved by the pass below. Normals are kept
    // where known only, and where marching cubes made a vertex only for those moved: at 512 a copy of every
    // vertex and a normal each took 40 MiB of fresh pages, 0.07 s of page faults.
    enum : std::uint8_t { kOnEdge = 1, kKnown = 2, kMoved = 4, kProjected = 8 };
    std::vector<std::uint8_t> flags(nv);
    std::vector<Eigen::Vector3d> normals(nv); // Eigen's vectors start unset: pages are touched where written
    tbb::enumerable_thread_specific<std::vector<std::pair<std::uint32_t, Eigen::Vector3d>>> moved_by_thread;
    std::unique_ptr<TriangleGrid> grid;
    if (options.feature_surface && !options.feature_surface->faces.triangles.empty()) grid = std::make_unique<TriangleGrid>(options.feature_surface->faces, voxmap);
    const std::size_t nt = mesh.triangles.size();
    // The runs of marching cubes' vertices and triangles, by block, that the passes over all of them visit: given a
    // feature surface, those of blocks within two cells of a cell it marks as near. A vertex of a block lies on an
    // edge of one of its cells; one farther off gets no normal, and no triangle of its has a corner with one, so
    // none is looked at; the vertices within a cell of those that get one (a loop's corners, which it asks whether
    // they lie on a grid edge) are in these blocks too. The output is the same; at 512 the bunny ear's passes visit
    // 30 % of the vertices, and its extraction (less snapping) took 0.409 s against 0.425 (medians of 5).
    auto runs_where = [&](const auto& wanted) {
        // Blocks one after another join into runs of some thousands, each a task.
        auto add = [](auto& runs, std::uint32_t first, std::uint32_t end) {
            if (!runs.empty() && runs.back().second == first && end - runs.back().first <= 4096) runs.back().second = end;
            else runs.push_back({first, end});
        };
        std::vector<std::pair<std::uint32_t, std::uint32_t>> vertex_runs, triangle_runs;
        for (std::size_t n = 0; n < blocks.size(); ++n) {
            if (!wanted(blocks[n].first_cell)) continue;
            const std::uint32_t v_end = n + 1 < blocks.size() ? blocks[n + 1].first_vertex : std::uint32_t(nv);
            const std::uint32_t t_end = n + 1 < blocks.size() ? blocks[n + 1].first_triangle : std::uint32_t(nt);
            add(vertex_runs, blocks[n].first_vertex, v_end), add(triangle_runs, blocks[n].first_triangle, t_end);
        }
        return std::pair(vertex_runs, triangle_runs);
    };
    constexpr std::int64_t kBlockCells = MarchingBlock::kCells;
    const auto [near_vertices, near_triangles] = runs_where([&](const Index3& c) {
        return !grid || grid->near({c[0] - 2, c[1] - 2, c[2] - 2}, {c[0] + kBlockCells + 1, c[1] + kBlockCells + 1, c[2] + kBlockCells + 1});
    });

    // Normals, and near the feature surface the crossings themselves: where the vertex's grid edge meets it (the
    // density's linear zero is off near an edge or corner, where the distance it ramps is not linear along the
    // grid edge). Given a feature surface, only near it: a smooth warp makes no sharp part the input's sharp edges
    // do not carry, and this pass over every vertex was a third of the mesher's cost. A vertex left without a
    // normal is in no candidate cell's loop.
    tbb::parallel_for(std::size_t(0), near_vertices.size(), [&](std::size_t r) {
        for (std::size_t i = near_vertices[r].first; i != near_vertices[r].second; ++i) {
            GridEdge e = edge_of(voxmap, mesh.vertices[i]);
            flags[i] = e.axis >= 0 ? kOnEdge : 0;
            if (e.axis < 0 || (grid && !grid->near(e.low))) continue;
            normals[i] = gradient_normal(voxmap, e);
            const Eigen::Vector3d made = mesh.vertices[i];
            auto settle = [&] {
                if (!normals[i].isZero()) flags[i] |= kKnown;
                if (mesh.vertices[i] != made) flags[i] |= kMoved, moved_by_thread.local().push_back({std::uint32_t(i), made});
            };
            if (!grid) {
                settle();
                continue;
            }
            const Eigen::Vector3d a = voxmap.world(double(e.low[0]), double(e.low[1]), double(e.low[2]));
            Eigen::Vector3d b = a;
            b[e.axis] += h;
            Index3 high = e.low;
            ++high[std::size_t(e.axis)];
            double t = e.t;
            Eigen::Vector3d n = Eigen::Vector3d::Zero();
            Eigen::Vector3d x;
            if (grid->hit(a, b, {e.low, high}, e.t, t, n) && n.dot(normals[i]) > 0) {
                t = std::clamp(t, margin, 1 - margin); // as marching cubes keeps its crossings off the edge's ends
                mesh.vertices[i] = a + t * (b - a);
                normals[i] = n;
                e.t = t;
            } else if (grid->nearest(mesh.vertices[i], voxmap, 0.6 * h, x, n) && n.dot(normals[i]) > 0 &&
                       std::abs((x - mesh.vertices[i]).dot(n)) >= 0.5 * (x - mesh.vertices[i]).norm()) {
                // The density put a crossing on a grid edge the surface misses (resampled by a warp, it rounds sharp
                // parts a little): the vertex goes to the surface, off its grid edge. Not along the surface: a
                // vertex on a flat face beyond the feature surface's rim (three voxels from the sharp edges) would
                // be drawn sideways onto the rim, apart from its neighbours, and fold their triangles over in the
                // face's plane (turned cubes: 12 triangles facing against the cube), where marching cubes' own
                // crossing is exact. A vertex on a rounded edge goes to it across both faces, at 45 degrees or more.
                mesh.vertices[i] = x;
                normals[i] = n;
                flags[i] |= kProjected;
            }
            settle();
        }
    });
    // Where marching cubes made each vertex moved, by vertex.
    std::vector<std::pair<std::uint32_t, Eigen::Vector3d>> made_at;
    for (const auto& list : moved_by_thread) made_at.insert(made_at.end(), list.begin(), list.end());
    std::sort(made_at.begin(), made_at.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    {
        // Vertices drawn off their grid edges onto one point of the feature surface (a corner of its pieces, nearest
        // to all of them where a scan's creases are jagged): distinct vertices at one position, and the faces
        // around them meeting there. All but one go back where marching cubes made them, with the density's normal.
        // Within a thousandth of a voxel, to round-off apart: points nearest along different triangles of the
        // surface differ by that.
        const double apart = 1e-3 * h;
        std::vector<std::pair<double, std::uint32_t>> by_x(made_at.size());
        for (std::size_t k = 0; k < made_at.size(); ++k) by_x[k] = {mesh.vertices[made_at[k].first].x(), made_at[k].first};
        std::vector<std::uint32_t> back; // projected ones near another moved one that stays
        pairs_near_in_x(by_x, apart, [&](std::uint32_t a, std::uint32_t b) {
            // Of the two, one moved along its own grid edge stays (such never share a point), else the first.
            if (!(flags[b] & kProjected)) std::swap(a, b);
            if ((flags[b] & kProjected) && (mesh.vertices[a] - mesh.vertices[b]).norm() < apart) back.push_back(b);
        });
        std::sort(back.begin(), back.end());
        back.erase(std::unique(back.begin(), back.end()), back.end());
        for (const std::uint32_t v : back) {
            const Eigen::Vector3d made = std::lower_bound(made_at.begin(), made_at.end(), v, [](const auto& x, std::uint32_t w) { return x.first < w; })->second;
            mesh.vertices[v] = made;
            normals[v] = gradient_normal(voxmap, edge_of(voxmap, made));
            flags[v] = std::uint8_t((flags[v] & ~(kMoved | kProjected)) | (normals[v].isZero() ? 0 : kKnown));
        }
    }
    auto marching = [&](std::size_t v) -> const Eigen::Vector3d& {
        if (!(flags[v] & kMoved)) return mesh.vertices[v];
        return std::lower_bound(made_at.begin(), made_at.end(), v, [](const auto& a, std::size_t b) { return a.first < b; })->second;
    };
    auto known = [&](std::size_t v) { return (flags[v] & kKnown) != 0; };
    auto normal_at = [&](std::size_t v) { return known(v) ? normals[v] : Eigen::Vector3d::Zero().eval(); };
    // The feature surface's cells are not read again: their memory goes back before the builds (which lowered the
    // bunny ear's peak at 256 from 161 to 157 MiB).
    const bool on_feature_surface = grid != nullptr;
    grid.reset();

    // The triangles looked at from here on: those with a corner that has a normal (all, without a feature surface).
    // Each one's cell, and whether its corners' normals disagree: its cell is then a candidate.
    const std::vector<std::uint32_t> looked = select_in_runs(near_triangles, [&](std::size_t f) {
        const auto& t = mesh.triangles[f];
        return known(std::size_t(t[0])) || known(std::size_t(t[1])) || known(std::size_t(t[2]));
    });
    std::vector<std::uint64_t> looked_cell(looked.size());
    std::vector<std::uint8_t> sharp(looked.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, looked.size(), 4096), [&](const auto& range) {
        for (std::size_t k = range.begin(); k != range.end(); ++k) {
            const auto& t = mesh.triangles[looked[k]];
            const Eigen::Vector3d centre = (mesh.vertices[std::size_t(t[0])] + mesh.vertices[std::size_t(t[1])] + mesh.vertices[std::size_t(t[2])]) / 3;
            looked_cell[k] = cell_key(cell_containing(voxmap.index_of(centre)));
            if (!known(std::size_t(t[0])) || !known(std::size_t(t[1])) || !known(std::size_t(t[2]))) continue;
            const Eigen::Vector3d &a = normals[std::size_t(t[0])], &b = normals[std::size_t(t[1])], &c = normals[std::size_t(t[2])];
            sharp[k] = std::min({a.dot(b), b.dot(c), c.dot(a)}) < cos_feature;
        }
    });
    std::unordered_set<std::uint64_t> candidate_cells;
    for (std::size_t k = 0; k < looked.size(); ++k)
        if (sharp[k]) candidate_cells.insert(looked_cell[k]);
    // The input's sharp edges, where given: every cell they pass through holds a feature, even one where marching
    // cubes sees only one of the two faces (an edge that clips a cell's corner between its grid edges); there the
    // feature point is the middle of the edge's stretch inside the cell, or the corner where edges meet in it.
    std::unordered_map<std::uint64_t, EdgeStretches> edge_in_cell;
    if (options.feature_surface)
        for (const auto& [a, b] : options.feature_surface->edges) {
            // Every cell the segment passes through (Amanatides & Woo's traversal), with the middle of its stretch
            // there weighted by the stretch's length: clips of any size count.
            const Eigen::Vector3d qa = voxmap.index_of(a), qb = voxmap.index_of(b), d = qb - qa;
            Index3 c = cell_containing(qa);
            const Index3 last = cell_containing(qb);
            double t = 0;
            for (int guard = 0; guard < 4096; ++guard) {
                double exit = 1;
                int axis = -1;
                for (int k = 0; k < 3; ++k) {
                    if (d[k] == 0) continue;
                    const double boundary = double(c[std::size_t(k)]) + (d[k] > 0 ? 1.0 : 0.0);
                    const double tk = (boundary - qa[k]) / d[k];
                    if (tk < exit) exit = tk, axis = k;
                }
                exit = std::max(exit, t);
                const double length = (exit - t) * d.norm();
                edge_in_cell[cell_key(c)].add(a + (b - a) * (0.5 * (t + exit)), b - a, length);
                candidate_cells.insert(cell_key(c));
                if (axis < 0 || c == last || exit >= 1) break;
                c[std::size_t(axis)] += d[axis] > 0 ? 1 : -1;
                t = exit;
            }
        }
    CoarseMarks candidate_blocks(voxmap);
    for (const std::uint64_t key : candidate_cells) candidate_blocks.mark(key_cell(key), key_cell(key));
    // (cell, triangle) for the triangles in candidate cells, sorted: each cell's run in order of key, so that the
    // output does not depend on hashing.
    std::vector<std::pair<std::uint64_t, std::uint32_t>> in_cells;
    for (std::size_t k = 0; k < looked.size(); ++k) {
        const std::uint64_t key = looked_cell[k];
        if (candidate_blocks.any(key_cell(key), key_cell(key)) && candidate_cells.count(key)) in_cells.push_back({key, looked[k]});
    }
    std::sort(in_cells.begin(), in_cells.end());
    std::vector<std::size_t> run_start; // where each cell's run begins in in_cells, and its end
    for (std::size_t i = 0; i < in_cells.size(); ++i)
        if (i == 0 || in_cells[i].first != in_cells[i - 1].first) run_start.push_back(i);
    run_start.push_back(in_cells.size());

    // Per candidate cell, per loop (triangles joined through vertices): where its tangent planes meet.
    struct Loop {
        std::vector<std::uint32_t> triangles;
        Index3 cell;
        Eigen::Vector3d point;
        int rank = 0;
    };
    // Cells are independent: their loops in parallel, then in order of key.
    std::vector<std::vector<Loop>> cell_loops(run_start.size() - 1);
    tbb::parallel_for(std::size_t(0), cell_loops.size(), [&](std::size_t r) {
        const std::uint64_t key = in_cells[run_start[r]].first;
        const Index3 cell = key_cell(key);
        std::vector<std::uint32_t> faces;
        for (std::size_t i = run_start[r]; i < run_start[r + 1]; ++i) faces.push_back(in_cells[i].second);
        std::vector<Loop>& features = cell_loops[r];
        internal::DisjointSets joined_faces(faces.size());
        std::map<std::int32_t, std::size_t> owner;
        for (std::size_t i = 0; i < faces.size(); ++i)
            for (auto v : mesh.triangles[faces[i]]) {
                auto [it, inserted] = owner.try_emplace(v, i);
                if (!inserted) joined_faces.join(i, it->second);
            }
        std::map<std::size_t, std::vector<std::uint32_t>> loops;
        for (std::size_t i = 0; i < faces.size(); ++i) loops[joined_faces.find(i)].push_back(faces[i]);
        for (auto& [root, loop] : loops) {
            std::vector<Eigen::Vector3d> points, ns;
            std::set<std::int32_t> seen;
            bool usable = true;
            for (auto f : loop)
                for (auto v : mesh.triangles[f])
                    if ((flags[std::size_t(v)] & kOnEdge) && seen.insert(v).second) {
                        usable &= known(std::size_t(v));
                        points.push_back(mesh.vertices[std::size_t(v)]);
                        ns.push_back(normal_at(std::size_t(v)));
                    }
            if (!usable || points.size() < 3) continue;
            double worst = 1;
            for (std::size_t i = 0; i < ns.size(); ++i)
                for (std::size_t j = i + 1; j < ns.size(); ++j) worst = std::min(worst, ns[i].dot(ns[j]));
            const auto along = edge_in_cell.find(key);
            if (worst >= cos_feature && along == edge_in_cell.end()) continue;
            Eigen::Vector3d centre = Eigen::Vector3d::Zero();
            for (const auto& p : points) centre += p;
            centre /= double(points.size());
            Loop l{std::move(loop), cell, Eigen::Vector3d::Zero(), 0};
            l.point = qef_point(points, ns, centre, l.rank);
            // On a known sharp edge, the edge's own point, unless the planes find a corner in the cell.
            if (along != edge_in_cell.end() && !along->second.empty() && !(l.rank == 3 && worst < cos_feature))
                l.point = along->second.point(), l.rank = 2;
            if (l.rank >= 2) features.push_back(std::move(l));
        }
    });
    std::vector<Loop> features;
    for (auto& loops : cell_loops)
        for (auto& l : loops) features.push_back(std::move(l));
    // A corner whose tip pokes into a cell no grid corner of which is inside lies outside every cell around it:
    // the loops around it that agree on it (rank 3, within a fifth of a voxel) become one patch, fanned to it.
    internal::DisjointSets group(features.size());
    // Loops beside each other that found one point, of any rank (a corner where sharp edges meet, found from cells
    // on either side of it): as two fans, their centres coincide and the triangles between them fold back to back
    // (the L block's notch, where it meets the top face). Their patches are fanned as one where that is one disk.
    std::vector<std::pair<int, int>> coincident;
    {
        std::map<std::int32_t, std::vector<int>> corner_loops_at; // vertex -> rank-3 loops using it
        std::map<std::int32_t, std::vector<int>> loops_at;        // vertex -> loops using it
        for (std::size_t i = 0; i < features.size(); ++i)
            for (auto f : features[i].triangles)
                for (auto v : mesh.triangles[f]) {
                    loops_at[v].push_back(int(i));
                    if (features[i].rank == 3) corner_loops_at[v].push_back(int(i));
                }
        for (const auto& [v, ls] : corner_loops_at)
            for (std::size_t a = 1; a < ls.size(); ++a)
                if ((features[std::size_t(ls[0])].point - features[std::size_t(ls[a])].point).norm() < 0.2 * h) group.join(std::size_t(ls[a]), std::size_t(ls[0]));
        for (const auto& [v, ls] : loops_at)
            for (std::size_t a = 0; a < ls.size(); ++a)
                for (std::size_t b = a + 1; b < ls.size(); ++b)
                    if ((features[std::size_t(ls[a])].point - features[std::size_t(ls[b])].point).norm() < 0.01 * h) coincident.push_back({ls[a], ls[b]});
    }
    std::map<std::size_t, std::vector<int>> patches;
    for (std::size_t i = 0; i < features.size(); ++i) patches[group.find(i)].push_back(int(i));

    // Each patch's fan, independent of the others: in parallel, then applied in order.
    struct Fan {
        std::vector<std::uint32_t> triangles; // those it replaces
        std::vector<std::int32_t> cycle;      // its boundary, empty when the patch is not one disk or the point strays
        Eigen::Vector3d point = Eigen::Vector3d::Zero();
    };
    // A fan whose centre lies on a sharp edge but past part of its loop along the edge folds the triangles there
    // over, flat in the face's plane (turned cubes: 0.13 % of the triangles faced against the cube's normal). The
    // centre slides along the edge, which keeps it on the edge: how each fan triangle faces is linear in the slide,
    // so the slides for which every triangle faces along its outer corners' normals form an interval. The centre
    // takes the slide nearest none, a quarter of the interval inside its ends; with no such slide it stays.
    auto slid_along_edge = [&](const Eigen::Vector3d& point, const std::vector<std::int32_t>& cycle) {
        Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();
        for (const auto v : cycle)
            if (known(std::size_t(v))) spread += normals[std::size_t(v)].normalized() * normals[std::size_t(v)].normalized().transpose();
        // Along the edge: the direction all the normals leave free, when they span a plane and no more.
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> spread_of(spread);
        const Eigen::Vector3d& lambda = spread_of.eigenvalues(); // ascending
        if (!(lambda[1] > 0.05 * lambda[2] && lambda[0] < 0.1 * lambda[1])) return point;
        const Eigen::Vector3d d = spread_of.eigenvectors().col(0);
        double lo_t = -std::numeric_limits<double>::infinity(), hi_t = std::numeric_limits<double>::infinity();
        bool folds = false;
        for (std::size_t k = 0; k < cycle.size(); ++k) {
            const auto a = std::size_t(cycle[k]), b = std::size_t(cycle[(k + 1) % cycle.size()]);
            const Eigen::Vector3d m = normal_at(a) + normal_at(b);
            if (m.isZero()) continue;
            const Eigen::Vector3d pa = mesh.vertices[a] - point, pb = mesh.vertices[b] - point;
            // ((pa - t d) x (pb - t d)) . m = c + e t
            const double c = pa.cross(pb).dot(m), e = -(d.cross(pb) + pa.cross(d)).dot(m);
            folds |= !(c > 0);
            if (e > 0) lo_t = std::max(lo_t, -c / e);
            else if (e < 0) hi_t = std::min(hi_t, -c / e);
            else if (!(c > 0)) return point;
        }
        if (!folds || !(lo_t < hi_t)) return point;
        // A quarter of the interval inside either end, or a twentieth of a voxel past its one end.
        const double inside = std::isfinite(hi_t - lo_t) ? 0.25 * (hi_t - lo_t) : 0.05 * h;
        const double t = std::isfinite(lo_t) ? (std::isfinite(hi_t) ? std::clamp(0.0, lo_t + inside, hi_t - inside) : std::max(0.0, lo_t + inside))
                                             : std::min(0.0, hi_t - inside);
        return Eigen::Vector3d(point + t * d);
    };
    std::vector<const std::vector<int>*> patch_list;
    std::vector<std::size_t> patch_of(features.size());
    for (const auto& [r, members] : patches) {
        for (const int i : members) patch_of[std::size_t(i)] = patch_list.size();
        patch_list.push_back(&members);
    }
    internal::DisjointSets beside(patch_list.size());
    for (const auto& [a, b] : coincident) beside.join(patch_of[std::size_t(b)], patch_of[std::size_t(a)]);
    std::map<std::size_t, std::vector<std::size_t>> joined_patches; // root -> its patches, in order
    for (std::size_t p = 0; p < patch_list.size(); ++p) joined_patches[beside.find(p)].push_back(p);
    std::vector<const std::vector<std::size_t>*> joined_list;
    for (const auto& [r, ps] : joined_patches) joined_list.push_back(&ps);
    std::vector<Fan> fans(patch_list.size());
    auto directed = [](std::int32_t a, std::int32_t b) { return std::uint64_t(std::uint32_t(a)) << 32 | std::uint32_t(b); };
    // A patch's fan; its cycle left empty where the patch is not one disk or the point strays.
    auto make_fan = [&](const std::vector<int>& members, Fan& fan, const Eigen::Vector3d* tip, const std::vector<std::uint32_t>& extra) {
        std::vector<std::uint32_t>& tris = fan.triangles;
        tris = extra;
        Eigen::Vector3d point = Eigen::Vector3d::Zero();
        Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
        for (int i : members) {
            const Loop& l = features[std::size_t(i)];
            tris.insert(tris.end(), l.triangles.begin(), l.triangles.end());
            point += l.point / double(members.size());
            for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], double(l.cell[std::size_t(a)])), hi[a] = std::max(hi[a], double(l.cell[std::size_t(a)]) + 1);
        }
        // The patch's boundary: directed edges whose reverse it lacks, each used once and each leaving a different
        // vertex, chained into one cycle from the lowest vertex.
        std::vector<std::uint64_t> used;
        for (auto f : tris) {
            const auto& t = mesh.triangles[f];
            for (int c = 0; c < 3; ++c) used.push_back(directed(t[std::size_t(c)], t[std::size_t((c + 1) % 3)]));
        }
        std::sort(used.begin(), used.end());
        std::vector<std::pair<std::int32_t, std::int32_t>> next; // sorted by its first
        for (std::size_t i = 0; i < used.size();) {
            std::size_t j = i;
            while (j < used.size() && used[j] == used[i]) ++j;
            const auto a = std::int32_t(used[i] >> 32), b = std::int32_t(used[i] & 0xffffffffu);
            if (!std::binary_search(used.begin(), used.end(), directed(b, a))) {
                if (j - i != 1 || (!next.empty() && next.back().first == a)) return;
                next.push_back({a, b});
            }
            i = j;
        }
        if (next.size() < 3) return;
        std::vector<std::int32_t> cycle = closed_cycle(next);
        if (cycle.empty()) return; // not one disk
        if (tip) {
            // Gathered by distance, a tip's patch may also hold a closed piece beside it, or a handle, which one
            // boundary cycle does not show: a disk has V - E + F = 1.
            std::vector<std::int32_t> corners;
            for (const auto f : tris)
                for (const auto v : mesh.triangles[f]) corners.push_back(v);
            std::sort(corners.begin(), corners.end());
            const auto v_count = std::ptrdiff_t(std::unique(corners.begin(), corners.end()) - corners.begin());
            const auto e_count = std::ptrdiff_t((3 * tris.size() + next.size()) / 2);
            if (v_count - e_count + std::ptrdiff_t(tris.size()) != 1) return;
            fan.cycle = std::move(cycle);
            fan.point = *tip; // beyond the loops' cells by as far as they fell short of it
            return;
        }
        // Where the point may go: its cells, or for a corner the cells next to them, where its tip may hide. An
        // edge's point, with the input's normals, may lie most of a voxel outside: where the edge clips a grid
        // face none of whose corners is inside, the two cells it joins share no triangle, and marching cubes
        // chamfers the edge between them in cells beside it, whose planes meet on the edge just outside them
        // (these fans took turned cubes' edges from 0.46 voxel off at worst to 0.18). Normals from the density's
        // gradient are not trusted that far.
        const Loop& first = features[std::size_t(members[0])];
        const double slack = first.rank == 3 ? 1.0 : on_feature_surface ? 0.8 : 0.05;
        const Eigen::Vector3d q = voxmap.index_of(point);
        if (((q - lo).array() < -slack).any() || ((q - hi).array() > slack).any()) return;
        if (first.rank == 2 && members.size() == 1)
            if (const Eigen::Vector3d slid = slid_along_edge(point, cycle); slid.allFinite()) {
                const Eigen::Vector3d r = voxmap.index_of(slid);
                if (((r - lo).array() >= -slack).all() && ((r - hi).array() <= slack).all()) point = slid;
            }
        fan.cycle = std::move(cycle);
        fan.point = point;
    };
    tbb::parallel_for(std::size_t(0), joined_list.size(), [&](std::size_t k) {
        const std::vector<std::size_t>& ps = *joined_list[k];
        if (ps.size() > 1) {
            std::vector<int> members;
            for (const std::size_t p : ps) members.insert(members.end(), patch_list[p]->begin(), patch_list[p]->end());
            make_fan(members, fans[ps[0]], nullptr, {});
            if (!fans[ps[0]].cycle.empty()) return;
            fans[ps[0]] = Fan{};
        }
        for (const std::size_t p : ps) make_fan(*patch_list[p], fans[p], nullptr, {});
    });
    // Tips voxelizing lost: a corner of the input where three or more sharp edges meet (an end shared by three of
    // the feature surface's edge segments, to round-off) that no fan reaches, its edges' fans ending short of it (a
    // tetrahedron's corner, thinner than a voxel for about a voxel; or a fan at the corner that is no disk). The
    // patches of the loops within a voxel and a half of the nearest's cell (and those joined with them) become one
    // fan to the corner, where that is one disk; otherwise they stay as they are.
    if (options.feature_surface && !features.empty()) {
        // The segments' ends by x (sorting copies of the ends took 30 ms of 320,000 on 512 small cubes at 256).
        const auto& edges = options.feature_surface->edges;
        std::vector<std::pair<double, std::uint32_t>> by_x(2 * edges.size()); // x, then 2 x segment + which end
        tbb::parallel_for(std::size_t(0), edges.size(), [&](std::size_t e) {
            by_x[2 * e] = {edges[e].first[0], std::uint32_t(2 * e)}, by_x[2 * e + 1] = {edges[e].second[0], std::uint32_t(2 * e + 1)};
        });
        tbb::parallel_sort(by_x.begin(), by_x.end());
        auto end_at = [&](std::size_t k) -> const Eigen::Vector3d& { // the k-th end by x, and the other end of its segment
            const auto& e = edges[by_x[k].second / 2];
            return by_x[k].second % 2 ? e.second : e.first;
        };
        auto other_end = [&](std::size_t k) -> const Eigen::Vector3d& {
            const auto& e = edges[by_x[k].second / 2];
            return by_x[k].second % 2 ? e.first : e.second;
        };
        const double tol = 1e-9 * h; // a segment cut from either end leaves its ends 1e-15 voxel apart
        auto outside_cell = [](const Eigen::Vector3d& q, const Index3& cell) { // voxels from q (index units) to the cell
            const Eigen::Vector3d lo{double(cell[0]), double(cell[1]), double(cell[2])};
            return (q - q.cwiseMax(lo).cwiseMin(lo + Eigen::Vector3d::Ones())).norm();
        };
        // The loops come in order of their cells' keys, x in the low bits: those of a row of cells are one run.
        auto loops_in_row = [&](std::int64_t x_lo, std::int64_t x_hi, std::int64_t y, std::int64_t z) {
            const std::uint64_t first = cell_key({std::max<std::int64_t>(x_lo, -2), y, z}), last = cell_key({x_hi, y, z});
            const auto lo = std::lower_bound(features.begin(), features.end(), first, [](const Loop& l, std::uint64_t k) { return cell_key(l.cell) < k; });
            auto hi = lo;
            while (hi != features.end() && cell_key(hi->cell) <= last) ++hi;
            return std::pair(std::size_t(lo - features.begin()), std::size_t(hi - features.begin()));
        };
        struct Tip {
            Eigen::Vector3d corner;
            double nearest;                 ///< voxels from the corner to the nearest loop's cell
            std::vector<std::size_t> ps;    ///< the patches it joins, ascending
            std::vector<int> members;       ///< their loops
        };
        std::vector<std::uint8_t> in_tip(patch_list.size(), 0);
        std::unordered_map<std::uint64_t, std::vector<std::size_t>> fans_in_cell; // by their points' cells
        auto apply = [&](const std::vector<std::size_t>& ps, Fan&& tip) {
            for (const std::size_t p : ps) fans[p] = Fan{}, in_tip[p] = 1;
            fans[ps[0]] = std::move(tip);
            fans_in_cell[cell_key(cell_containing(voxmap.index_of(fans[ps[0]].point)))].push_back(ps[0]);
        };
        std::vector<std::size_t> group_of(patch_list.size()); // a patch's group of patches beside each other
        for (std::size_t k = 0; k < joined_list.size(); ++k)
            for (const std::size_t p : *joined_list[k]) group_of[p] = k;
        std::vector<Tip> holed; // whose loops leave a hole, for the second pass
        // The corners: the first end of each group at one point that is a tip, found in parallel.
        const std::vector<std::uint32_t> corners = select_in_parallel(by_x.size(), [&](std::size_t i) {
            const Eigen::Vector3d& corner = end_at(i);
            for (std::size_t k = i; k-- > 0 && corner[0] - by_x[k].first <= tol;)
                if ((end_at(k) - corner).norm() <= tol) return false; // not the group's first
            std::size_t shared = 0;
            for (std::size_t k = i; k < by_x.size() && by_x[k].first - corner[0] <= tol; ++k) shared += (end_at(k) - corner).norm() <= tol;
            if (shared < 3) return false;
            std::vector<Eigen::Vector3d> leaving; // the edges' directions from the point
            Eigen::Vector3d axis = Eigen::Vector3d::Zero();
            for (std::size_t k = i; k < by_x.size() && by_x[k].first - corner[0] <= tol; ++k)
                if ((end_at(k) - corner).norm() <= tol) leaving.push_back((other_end(k) - corner).normalized()), axis += leaving.back();
            // A tip: three edges or more, no two along one line (20 degrees), all within 63 degrees of their mean
            // (a triangular prism's corner: 60; a cube's: 55). Where a scan's creases meet on a smoother part they
            // spread wider, and are left to the fans.
            for (std::size_t a = 0; a < leaving.size(); ++a) {
                if (!(leaving[a].dot(axis.normalized()) >= 0.45)) return false;
                for (std::size_t b = a + 1; b < leaving.size(); ++b)
                    if (!(leaving[a].dot(leaving[b]) <= 0.94)) return false;
            }
            return true;
        });
        for (const std::uint32_t i : corners) {
            const Eigen::Vector3d& corner = end_at(i);
            // Reached by a fan: its point within 0.3 voxel (fans filed by their points' cells at the first corner).
            const Eigen::Vector3d q = voxmap.index_of(corner);
            const Index3 c = cell_containing(q);
            if (fans_in_cell.empty())
                for (std::size_t p = 0; p < fans.size(); ++p)
                    if (!fans[p].cycle.empty()) fans_in_cell[cell_key(cell_containing(voxmap.index_of(fans[p].point)))].push_back(p);
            bool reached = false;
            for (std::int64_t dz = -1; dz <= 1; ++dz)
                for (std::int64_t dy = -1; dy <= 1; ++dy)
                    for (std::int64_t dx = -1; dx <= 1; ++dx)
                        if (const auto it = fans_in_cell.find(cell_key({c[0] + dx, c[1] + dy, c[2] + dz})); it != fans_in_cell.end())
                            for (const std::size_t p : it->second) reached |= !fans[p].cycle.empty() && (fans[p].point - corner).norm() <= 0.3 * h;
            if (reached) continue;
            // Each loop within three cells: how far outside its cell the corner lies, in voxels.
            Tip tip{corner, std::numeric_limits<double>::infinity(), {}, {}};
            std::vector<std::pair<double, std::size_t>> near;
            for (std::int64_t dz = -3; dz <= 3; ++dz)
                for (std::int64_t dy = -3; dy <= 3; ++dy)
                    for (auto [l, end] = loops_in_row(c[0] - 3, c[0] + 3, c[1] + dy, c[2] + dz); l < end; ++l) {
                        const double d = outside_cell(q, features[l].cell);
                        tip.nearest = std::min(tip.nearest, d), near.push_back({d, l});
                    }
            if (!(tip.nearest < 2.5)) continue;
            // The patches to join: those of the loops near, each with its whole group of patches beside each other.
            for (const auto& [d, l] : near)
                if (d <= tip.nearest + 1.5)
                    for (const std::size_t p : *joined_list[group_of[patch_of[l]]]) tip.ps.push_back(p);
            std::sort(tip.ps.begin(), tip.ps.end());
            tip.ps.erase(std::unique(tip.ps.begin(), tip.ps.end()), tip.ps.end());
            if (std::any_of(tip.ps.begin(), tip.ps.end(), [&](std::size_t p) { return in_tip[p] != 0; })) continue; // another corner's
            for (const std::size_t p : tip.ps) tip.members.insert(tip.members.end(), patch_list[p]->begin(), patch_list[p]->end());
            Fan fan;
            make_fan(tip.members, fan, &tip.corner, {});
            if (!fan.cycle.empty()) apply(tip.ps, std::move(fan));
            else holed.push_back(std::move(tip));
        }
        // The loops leave holes where cells between them hold marching cubes' triangles and no loop (their normals
        // agree): those join too, where no other fan has them. Only the cells around these corners are looked up.
        if (!holed.empty()) {
            CoarseMarks around(voxmap);
            for (const Tip& tip : holed) {
                const Index3 c = cell_containing(voxmap.index_of(tip.corner));
                around.mark({c[0] - 3, c[1] - 3, c[2] - 3}, {c[0] + 3, c[1] + 3, c[2] + 3});
            }
            std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> looked_in_cell;
            for (std::size_t k = 0; k < looked.size(); ++k)
                if (const Index3 cell = key_cell(looked_cell[k]); around.any(cell, cell)) looked_in_cell[looked_cell[k]].push_back(looked[k]);
            std::unordered_map<std::uint32_t, std::size_t> fan_of_triangle; // for the triangles looked up only
            for (std::size_t p = 0; p < fans.size(); ++p)
                for (const std::uint32_t f : fans[p].triangles) {
                    const auto k = std::size_t(std::lower_bound(looked.begin(), looked.end(), f) - looked.begin());
                    if (k == looked.size() || looked[k] != f) continue; // not so: every fan's triangle is looked at
                    if (const Index3 cell = key_cell(looked_cell[k]); around.any(cell, cell)) fan_of_triangle[f] = p;
                }
            for (Tip& tip : holed) {
                if (std::any_of(tip.ps.begin(), tip.ps.end(), [&](std::size_t p) { return in_tip[p] != 0; })) continue;
                const Eigen::Vector3d q = voxmap.index_of(tip.corner);
                const Index3 c = cell_containing(q);
                std::vector<std::uint32_t> extra;
                bool taken = false;
                for (std::int64_t dz = -3; dz <= 3; ++dz)
                    for (std::int64_t dy = -3; dy <= 3; ++dy)
                        for (std::int64_t dx = -3; dx <= 3; ++dx) {
                            const Index3 cell{c[0] + dx, c[1] + dy, c[2] + dz};
                            if (outside_cell(q, cell) > tip.nearest + 1.5) continue;
                            if (const auto it = looked_in_cell.find(cell_key(cell)); it != looked_in_cell.end())
                                for (const std::uint32_t f : it->second) {
                                    if (const auto owner = fan_of_triangle.find(f); owner == fan_of_triangle.end()) extra.push_back(f);
                                    else taken |= !std::binary_search(tip.ps.begin(), tip.ps.end(), owner->second);
                                }
                        }
                if (taken || extra.empty()) continue;
                // What the patch still surrounds farther off (triangles whose corners are all the patch's): one no
                // fan has joins, and a fan's patch joins whole, with its group, where no other corner has it.
                std::vector<std::int32_t> patch_vertices;
                for (const int m : tip.members)
                    for (const std::uint32_t f : features[std::size_t(m)].triangles)
                        for (const auto v : mesh.triangles[f]) patch_vertices.push_back(v);
                for (const std::uint32_t f : extra)
                    for (const auto v : mesh.triangles[f]) patch_vertices.push_back(v);
                std::sort(patch_vertices.begin(), patch_vertices.end());
                std::vector<std::size_t> surrounded;
                for (std::int64_t dz = -3; dz <= 3; ++dz)
                    for (std::int64_t dy = -3; dy <= 3; ++dy)
                        for (std::int64_t dx = -3; dx <= 3; ++dx) {
                            const Index3 cell{c[0] + dx, c[1] + dy, c[2] + dz};
                            if (outside_cell(q, cell) <= tip.nearest + 1.5) continue; // gathered above
                            if (const auto it = looked_in_cell.find(cell_key(cell)); it != looked_in_cell.end())
                                for (const std::uint32_t f : it->second) {
                                    const auto& t = mesh.triangles[f];
                                    if (!std::all_of(t.begin(), t.end(), [&](std::int32_t v) { return std::binary_search(patch_vertices.begin(), patch_vertices.end(), v); })) continue;
                                    if (const auto owner = fan_of_triangle.find(f); owner == fan_of_triangle.end()) extra.push_back(f);
                                    else if (!std::binary_search(tip.ps.begin(), tip.ps.end(), owner->second))
                                        for (const std::size_t p : *joined_list[group_of[owner->second]]) surrounded.push_back(p);
                                }
                        }
                if (std::any_of(surrounded.begin(), surrounded.end(), [&](std::size_t p) { return in_tip[p] != 0; })) continue;
                std::sort(surrounded.begin(), surrounded.end());
                surrounded.erase(std::unique(surrounded.begin(), surrounded.end()), surrounded.end());
                for (const std::size_t p : surrounded)
                    if (!std::binary_search(tip.ps.begin(), tip.ps.end(), p)) tip.members.insert(tip.members.end(), patch_list[p]->begin(), patch_list[p]->end());
                tip.ps.insert(tip.ps.end(), surrounded.begin(), surrounded.end());
                std::sort(tip.ps.begin(), tip.ps.end());
                tip.ps.erase(std::unique(tip.ps.begin(), tip.ps.end()), tip.ps.end());
                Fan fan;
                make_fan(tip.members, fan, &tip.corner, extra);
                if (fan.cycle.empty()) continue;
                for (const std::uint32_t f : fan.triangles) fan_of_triangle[f] = tip.ps[0];
                apply(tip.ps, std::move(fan));
            }
        }
    }
    // The region the builds below rewrite: the cells within kReach of a cell where something changes (a fan's
    // loop, a sharp edge, a vertex moved onto the feature surface, a triangle folded against its corners'
    // normals), whole cells, each triangle in the cell of its centre as marching cubes made it (as uncross files
    // it). Nothing the builds do moves anything more than a voxel from those cells (a fan's centre, a split, a
    // vertex put back), so no triangle beyond the region can meet one that changes, and the region's triangles
    // that touch one beyond it never change. Built on the whole mesh, the bunny ear edit's two builds took 0.19 s
    // of the feature mesher's 0.28 s at 256 (0.86 of 1.03 s at 512), much of it copying the mesh, where a quarter
    // of its triangles (an eighth at 512) lie in the region. The output is the same, byte for byte.
    constexpr std::int64_t kReach = 3;
    auto home_cell = [&](const std::array<std::int32_t, 3>& t) {
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (const auto v : t) sum += voxmap.index_of(marching(std::size_t(v)));
        return cell_containing(sum / 3);
    };
    // The cells where something changes, each once (a moved vertex's six triangles share one or two).
    constexpr std::uint64_t kNone = ~std::uint64_t(0);
    std::vector<std::uint64_t> changed(looked.size()), slid(looked.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, looked.size(), 4096), [&](const auto& range) {
        for (std::size_t k = range.begin(); k != range.end(); ++k) {
            const auto& t = mesh.triangles[looked[k]];
            Eigen::Vector3d reference = Eigen::Vector3d::Zero();
            bool moved = false, projected = false;
            for (const auto v : t)
                reference += normal_at(std::size_t(v)), moved |= (flags[std::size_t(v)] & kMoved) != 0, projected |= (flags[std::size_t(v)] & kProjected) != 0;
            const bool against = faces_against(mesh.vertices, t, reference);
            changed[k] = projected || against ? cell_key(home_cell(t)) : kNone;
            slid[k] = moved && !projected && !against ? cell_key(home_cell(t)) : kNone;
        }
    });
    for (const std::uint64_t key : candidate_cells) changed.push_back(key);
    for (const auto& [key, f] : in_cells) changed.push_back(cell_key(home_cell(mesh.triangles[f])));
    CellSet region_cells(voxmap);
    // A cell whose vertices only slid along their grid edges (onto the feature surface) changes in the builds only
    // where uncross puts one back along its edge: its triangles stay in it, and the triangles sharing those
    // vertices lie in the cells beside it. One cell around it is enough; the rest (fans, splits, unfolding, vertices
    // drawn off their grid edges) reach kReach.
    for (auto [list, reach] : {std::pair{&changed, kReach}, std::pair{&slid, std::int64_t(1)}}) {
        tbb::parallel_sort(list->begin(), list->end());
        list->erase(std::unique(list->begin(), list->end()), list->end());
        if (!list->empty() && list->back() == kNone) list->pop_back();
        for (const std::uint64_t key : *list) {
            const Index3 c = key_cell(key);
            region_cells.insert({c[0] - reach, c[1] - reach, c[2] - reach}, {c[0] + reach, c[1] + reach, c[2] + reach});
        }
    }
    // Each triangle's home cell lies in its block (a cell beyond, where its corners are all on one face).
    const auto region_triangles_runs = runs_where([&](const Index3& c) { return region_cells.any({c[0] - 1, c[1] - 1, c[2] - 1}, {c[0] + kBlockCells, c[1] + kBlockCells, c[2] + kBlockCells}); }).second;
    const std::vector<std::uint32_t> region = select_in_runs(region_triangles_runs, [&](std::size_t f) { return region_cells.contains(home_cell(mesh.triangles[f])); });
    if (region.empty()) return mesh;
    // The region as a mesh of its own: its vertices in their order, then those the builds add.
    std::vector<std::uint8_t> in_region(nv, 0);
    for (const std::uint32_t f : region)
        for (const auto v : mesh.triangles[f]) in_region[std::size_t(v)] = 1;
    const std::vector<std::uint32_t> region_vertices = select_in_parallel(nv, [&](std::size_t v) { return in_region[v] != 0; });
    const std::size_t nr = region_vertices.size(), ntr = region.size();
    std::unique_ptr<std::int32_t[]> local_of(new std::int32_t[nv]); // written for the region's vertices only
    std::vector<Eigen::Vector3d> region_positions(nr), region_marching(nr), region_normals(nr);
    for (std::size_t i = 0; i < nr; ++i) {
        const std::size_t v = region_vertices[i];
        local_of[v] = std::int32_t(i), region_positions[i] = mesh.vertices[v], region_marching[i] = marching(v), region_normals[i] = normal_at(v);
    }
    std::vector<std::array<std::int32_t, 3>> region_triangles(ntr);
    for (std::size_t i = 0; i < ntr; ++i)
        for (int c = 0; c < 3; ++c) region_triangles[i][std::size_t(c)] = local_of[std::size_t(mesh.triangles[region[i]][std::size_t(c)])];
    for (Fan& fan : fans) {
        bool inside = true; // always, as the region holds every fan's cells; were one outside, the fan is dropped
        for (auto& f : fan.triangles) {
            const auto at = std::lower_bound(region.begin(), region.end(), f);
            inside &= at != region.end() && *at == f;
            f = std::uint32_t(at - region.begin());
        }
        if (!inside) fan.cycle.clear();
        for (auto& v : fan.cycle) v = local_of[std::size_t(v)];
    }

    // The fans not rejected, the flips between them, the splits on sharp edges and the unfolding, on a copy of
    // the region's triangles; then the crossings put back (uncross). Where something still crosses once every
    // corner is back, the fans on the crossing triangles or beside them are rejected and the region built again:
    // their cells keep marching cubes' triangles. Four builds at most (the bundled edits need two).
    std::vector<std::uint8_t> rejected(fans.size(), 0);
    {
        // Separate fans on one point pinch the surface there: two sheets of a scan's thin shell through one cell,
        // both fanned to the sharp edge's point in it (the snowden scan at 128: 651 vertices on another's position,
        // 18,703 pairs of triangles meeting, the deepest crossing by 0.41 voxel). The first keeps the point; the
        // others' cells keep marching cubes' triangles.
        std::vector<std::pair<double, std::uint32_t>> by_x;
        for (std::size_t i = 0; i < fans.size(); ++i)
            if (!fans[i].cycle.empty()) by_x.push_back({fans[i].point.x(), std::uint32_t(i)});
        const double apart = 0.01 * h;
        // Only fans that face apart: fans on one point that face one way are a sharp edge's run of cells reaching
        // a corner, or the edges around a tip (rejecting those as well lost the polyhedra 7 triangles to folds and a
        // tetrahedron's corner by 0.39 voxel). The scan's pinched fans face apart by 135 to 180 degrees, those of
        // the polyhedra within 53 degrees of each other.
        auto facing = [&](const Fan& fan) {
            Eigen::Vector3d n = Eigen::Vector3d::Zero();
            for (const auto v : fan.cycle) n += region_normals[std::size_t(v)];
            return n;
        };
        pairs_near_in_x(by_x, apart, [&](std::uint32_t a, std::uint32_t b) {
            if (!rejected[a] && (fans[a].point - fans[b].point).norm() < apart && facing(fans[a]).dot(facing(fans[b])) < 0) rejected[b] = 1;
        });
    }
    struct Built {
        TriangleMesh mesh;
        std::vector<std::uint32_t> crossing; ///< the triangles that still cross
        std::vector<std::uint32_t> closed;   ///< the places of triangles removed and not filled, closed up
    };
    auto build = [&](std::vector<std::int32_t>& fan_of_centre) {
        Built built;
        TriangleMesh& out = built.mesh;
        out.vertices = region_positions;
        std::vector<std::uint8_t> removed(ntr, 0);
        std::vector<std::array<std::int32_t, 3>> added;
        for (std::size_t i = 0; i < fans.size(); ++i) {
            const Fan& fan = fans[i];
            if (fan.cycle.empty() || rejected[i]) continue;
            fan_of_centre.push_back(std::int32_t(i));
            const auto centre_index = std::int32_t(out.vertices.size());
            out.vertices.push_back(fan.point);
            for (auto f : fan.triangles) removed[f] = 1;
            for (std::size_t k = 0; k < fan.cycle.size(); ++k) added.push_back({centre_index, fan.cycle[k], fan.cycle[(k + 1) % fan.cycle.size()]});
        }
        // The fans' triangles take the removed ones' places, then go after the rest.
        std::vector<std::array<std::int32_t, 3>> triangles = region_triangles;
        std::vector<std::size_t> fan_triangles; // where each added triangle went
        fan_triangles.reserve(added.size());
        {
            std::size_t free = 0;
            for (const auto& t : added) {
                while (free < ntr && !removed[free]) ++free;
                if (free < ntr) triangles[free] = t, fan_triangles.push_back(free++);
                else fan_triangles.push_back(triangles.size()), triangles.push_back(t);
            }
            // Removed places left over (the fans have fewer triangles than the loops they replace) lie after every
            // fan triangle: close them up.
            std::size_t kept = free;
            for (std::size_t f = free; f < triangles.size(); ++f)
                if (f >= ntr || !removed[f]) triangles[kept++] = triangles[f];
                else built.closed.push_back(std::uint32_t(f));
            triangles.resize(kept);
        }
        // Flip the edge between two fans whose centres both are feature vertices: the two centres join, along the
        // sharp edge. Only where the centres are not joined yet and neither triangle turns over.
        auto undirected = [&](std::int32_t a, std::int32_t b) { return a < b ? directed(a, b) : directed(b, a); };
        std::vector<std::pair<std::uint64_t, std::size_t>> outer; // (the fan's outer edge, triangle), sorted
        for (const std::size_t f : fan_triangles) outer.push_back({undirected(triangles[f][1], triangles[f][2]), f});
        std::sort(outer.begin(), outer.end());
        // The centres joined by a flip. No fan's triangle joins two centres (its outer corners are marching cubes'
        // vertices), so these are all the edges between centres: the only ones asked about.
        std::unordered_set<std::uint64_t> joined;
        auto normal = [&](const std::array<std::int32_t, 3>& t) {
            return Eigen::Vector3d((out.vertices[std::size_t(t[1])] - out.vertices[std::size_t(t[0])]).cross(out.vertices[std::size_t(t[2])] - out.vertices[std::size_t(t[0])]));
        };
        for (std::size_t i = 0, j = 0; i < outer.size(); i = j) {
            while (j < outer.size() && outer[j].first == outer[i].first) ++j;
            if (j - i < 2) continue;
            auto &A = triangles[outer[i].second], &B = triangles[outer[j - 1].second];
            // A = (f, v, w), B = (g, w, v) with f, g the fans' centres.
            const std::int32_t f = A[0], g = B[0], v = A[1], w = A[2];
            if (B[1] != w || B[2] != v || f == g || joined.count(undirected(f, g))) continue;
            const std::array<std::int32_t, 3> A2{f, v, g}, B2{f, g, w};
            const Eigen::Vector3d before = normal(A) + normal(B);
            if (normal(A2).dot(before) <= 0 || normal(B2).dot(before) <= 0) continue;
            if (normal(A2).dot(normal(B2)) <= -0.5 * normal(A2).norm() * normal(B2).norm()) continue; // folded
            joined.insert(undirected(f, g));
            A = A2, B = B2;
        }
        out.triangles = std::move(triangles);
        std::vector<std::array<std::int32_t, 3>> splits;
        if (options.feature_surface) split_across_sharp_edges(out.vertices, out.triangles, region_normals, cos_feature, options.feature_surface->edges, voxmap, splits);
        const std::vector<std::uint32_t> unfolded = unfold(out.vertices, out.triangles, region_normals);
        built.crossing = uncross(out.vertices, out.triangles, region_marching, splits, unfolded, voxmap);
        return built;
    };
    Built built;
    for (int attempt = 0;; ++attempt) {
        std::vector<std::int32_t> fan_of_centre;
        built = build(fan_of_centre);
        // The fans with a centre on a crossing triangle or next to one of its corners (a split on a sharp edge
        // between fans is not a fan's own).
        if (built.crossing.empty() || attempt == 3) break;
        const TriangleMesh& out = built.mesh;
        std::vector<std::uint8_t> near_crossing(out.vertices.size(), 0);
        for (const std::uint32_t f : built.crossing)
            for (const auto v : out.triangles[f]) near_crossing[std::size_t(v)] = 1;
        auto fan_at = [&](std::int32_t v) { return std::size_t(v) >= nr && std::size_t(v) - nr < fan_of_centre.size() ? fan_of_centre[std::size_t(v) - nr] : -1; };
        bool again = false;
        for (const auto& t : out.triangles)
            if (near_crossing[std::size_t(t[0])] || near_crossing[std::size_t(t[1])] || near_crossing[std::size_t(t[2])])
                for (const auto v : t)
                    if (const std::int32_t fan = fan_at(v); fan >= 0 && !rejected[std::size_t(fan)]) rejected[std::size_t(fan)] = 1, again = true;
        if (!again) break;
    }

    // The region back in the mesh, in the order a build on the whole mesh gives: its triangles in the region's
    // places, those closed up taken out, the rest after the mesh's; its vertices in theirs, those added after.
    const TriangleMesh& out = built.mesh;
    auto in_mesh = [&](const std::array<std::int32_t, 3>& t) {
        std::array<std::int32_t, 3> g;
        for (std::size_t c = 0; c < 3; ++c) g[c] = std::size_t(t[c]) < nr ? std::int32_t(region_vertices[std::size_t(t[c])]) : std::int32_t(nv + (std::size_t(t[c]) - nr));
        return g;
    };
    std::size_t p = 0;
    for (std::size_t i = 0, c = 0; i < ntr; ++i)
        if (c < built.closed.size() && built.closed[c] == i) ++c;
        else mesh.triangles[region[i]] = in_mesh(out.triangles[p++]);
    if (!built.closed.empty()) {
        std::size_t kept = region[built.closed[0]];
        for (std::size_t f = kept, c = 0; f < nt; ++f)
            if (c < built.closed.size() && region[built.closed[c]] == f) ++c;
            else mesh.triangles[kept++] = mesh.triangles[f];
        mesh.triangles.resize(kept);
    }
    for (; p < out.triangles.size(); ++p) mesh.triangles.push_back(in_mesh(out.triangles[p]));
    for (std::size_t i = 0; i < nr; ++i) mesh.vertices[region_vertices[i]] = out.vertices[i];
    mesh.vertices.insert(mesh.vertices.end(), out.vertices.begin() + std::ptrdiff_t(nr), out.vertices.end());
    // The vertices inside the fans' loops are no triangle's now: taken out (the bar bend at 128 wrote 71 of them,
    // some on another vertex's position). Only the region's can be: its triangles that touch one beyond it never
    // change, so every vertex they share with the rest is still theirs.
    std::vector<std::uint8_t> used(out.vertices.size(), 0);
    for (const auto& t : out.triangles)
        for (const auto v : t) used[std::size_t(v)] = 1;
    std::vector<std::uint32_t> unused;
    for (std::size_t i = 0; i < used.size(); ++i)
        if (!used[i]) unused.push_back(i < nr ? region_vertices[i] : std::uint32_t(nv + (i - nr)));
    if (unused.empty()) return mesh;
    std::sort(unused.begin(), unused.end());
    std::vector<std::int32_t> renumbered(mesh.vertices.size());
    for (std::size_t v = unused[0], k = 0, next = unused[0]; v < mesh.vertices.size(); ++v) {
        while (k < unused.size() && unused[k] < v) ++k;
        if (k < unused.size() && unused[k] == v) continue;
        renumbered[v] = std::int32_t(next), mesh.vertices[next++] = mesh.vertices[v];
    }
    mesh.vertices.resize(mesh.vertices.size() - unused.size());
    const auto first = std::int32_t(unused[0]);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.triangles.size(), 16384), [&](const auto& range) {
        for (std::size_t f = range.begin(); f != range.end(); ++f)
            for (auto& v : mesh.triangles[f])
                if (v > first) v = renumbered[std::size_t(v)];
    });
    return mesh;
}

} // namespace voxwarp::extract_internal
