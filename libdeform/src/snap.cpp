// Correspondence between a re-polygonized mesh and its input, and snapping onto the exact warped surface.
//
// Marching cubes puts a vertex where the density's linear interpolant crosses 0.5, which is the surface only to
// within the voxmap's sampling (a tenth of a voxel on a curved bunny, more where a sharp tip is rounded off or the
// warp's box filter smeared the ramp). The input surface and the maps are both known exactly, so the vertex can
// ask where it came from: pull it back through the maps, take the nearest input point facing the same way, and
// push that point forward again.
#include <voxwarp/errors.h>
#include <voxwarp/snap.h>
#include <voxwarp_internal/geometry.h>

#include <Eigen/LU>

#include <atomic>

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <memory>
#include <map>
#include <numeric>
#include <numbers>
#include <optional>
#include <unordered_map>

namespace voxwarp {

namespace snap_internal {

using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Triangle = Kernel::Triangle_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, Iterator>;

Eigen::Vector3d closest_barycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c);

/// CGAL's AABB traits with the two tests a nearest-point query makes, per node and per triangle, done directly:
/// a box's squared distance, and the closest point of a triangle by Ericson's regions. CGAL's generic ones build
/// a sphere per node and a plane per triangle: with these, the bunny's queries at 512 took 0.18 s instead of 0.25.
struct Traits : CGAL::AABB_traits<Kernel, Primitive> {
    struct Closest_point {
        /// The point of `primitive` nearest `p` when it is no farther than `bound`, else `bound` itself (CGAL's
        /// traversal checks for that very point to see that nothing changed).
        Point operator()(const Point& p, const Primitive& primitive, const Point& bound) const {
            const Triangle& t = primitive.datum();
            const auto eigen = [](const Point& x) { return Eigen::Vector3d(x.x(), x.y(), x.z()); };
            const Eigen::Vector3d q = eigen(p), a = eigen(t[0]), b = eigen(t[1]), c = eigen(t[2]);
            const Eigen::Vector3d w = closest_barycentric(q, a, b, c);
            const Eigen::Vector3d x = w[0] * a + w[1] * b + w[2] * c;
            return (x - q).squaredNorm() > (eigen(bound) - q).squaredNorm() ? bound : Point(x.x(), x.y(), x.z());
        }
    };
    Closest_point closest_point_object() const { return {}; }
    struct Compare_distance {
        /// SMALLER when the box comes within `bound`'s distance of `p` (CGAL's closed sphere-box test).
        CGAL::Comparison_result operator()(const Point& p, const CGAL::Bbox_3& box, const Point& bound) const {
            double d2 = 0;
            for (int a = 0; a < 3; ++a) {
                const double x = p[a], below = box.min(a) - x, above = x - box.max(a);
                if (below > 0) d2 += below * below;
                else if (above > 0) d2 += above * above;
            }
            return d2 <= CGAL::squared_distance(p, bound) ? CGAL::SMALLER : CGAL::LARGER;
        }
    };
    Compare_distance compare_distance_object() const { return {}; }
};
using Tree = CGAL::AABB_tree<Traits>;
using Hint = Tree::Point_and_primitive_id;

/// The parameter of `world` on lattice `L` by Newton's method from `stu` (Lattice::parameter_of without its
/// exception and its check for an undeformed lattice, a pass over the points), and the Jacobian there; `tolerance`
/// is in world units.
std::optional<Eigen::Vector3d> invert(const Lattice& L, const Eigen::Vector3d& world, Eigen::Vector3d stu, Eigen::Matrix3d& J, double tolerance) {
    for (int iteration = 0; iteration < 60; ++iteration) {
        const Eigen::Vector3d residual = L.evaluate(stu, J) - world;
        if (residual.norm() <= tolerance) return stu;
        Eigen::Vector3d step = J.partialPivLu().solve(residual);
        if (!step.allFinite()) return std::nullopt;
        const double limit = 0.5; // half a region per step keeps Newton within reach of one polynomial piece
        if (step.cwiseAbs().maxCoeff() > limit) step *= limit / step.cwiseAbs().maxCoeff();
        stu -= step;
    }
    return std::nullopt;
}

Eigen::Vector3d undeformed_parameter(const Lattice& L, const Eigen::Vector3d& world) { return (world - L.rest_origin()).cwiseQuotient(L.spacing()); }

/// Pulls points back through the steps. Consecutive output vertices are neighbours (extraction walks the grid
/// block by block), so each Newton solve starts from the previous point's answer, a step away, when that point
/// was near: one or two evaluations instead of four or five from the undeformed guess.
class Puller {
public:
    /// `near`: how close the previous point must be to start from its answer; `tolerance`: how far from the point
    /// its pullback's image may land (world units).
    Puller(const std::vector<WarpStep>& steps, double near, double tolerance) : steps_(steps), previous_(steps.size()), near_(near), tolerance_(tolerance) {}

    std::optional<Eigen::Vector3d> operator()(Eigen::Vector3d point, Eigen::Matrix3d& jacobian) {
        jacobian.setIdentity();
        for (std::size_t k = steps_.size(); k-- > 0;) {
            const WarpStep& s = steps_[k];
            Previous& p = previous_[k];
            const Eigen::Vector3d guess = p.valid && (point - p.world).norm() < near_ ? Eigen::Vector3d(p.stu + p.inverse * (point - p.world))
                                                                                     : undeformed_parameter(s.moved, point);
            Eigen::Matrix3d moved;
            const auto stu = invert(s.moved, point, guess, moved, tolerance_);
            p.inverse = moved.inverse(); // closed form, once per point (the next guess needs only a product)
            p.valid = bool(stu) && p.inverse.allFinite();
            if (!stu) return std::nullopt;
            p.world = point, p.stu = *stu;
            // d moved / d rest = (d moved / d stu) (d rest / d stu)^-1; the steps compose last-to-first on the right.
            if (s.rest.placement() == Placement::uniform) {
                jacobian = jacobian * moved * s.rest.spacing().cwiseInverse().asDiagonal();
                point = s.rest.rest_origin() + stu->cwiseProduct(s.rest.spacing());
            } else {
                jacobian = jacobian * moved * s.rest.jacobian(*stu).inverse();
                point = s.rest.evaluate(*stu);
            }
        }
        return point;
    }

private:
    struct Previous {
        bool valid = false;
        Eigen::Vector3d world, stu;
        Eigen::Matrix3d inverse; ///< of the moved lattice's Jacobian at stu
    };
    const std::vector<WarpStep>& steps_;
    std::vector<Previous> previous_;
    double near_, tolerance_;
};

/// A rest lattice's parameter of a world point: affine for the uniform placement.
Eigen::Vector3d rest_parameter(const Lattice& rest, const Eigen::Vector3d& p) {
    if (rest.placement() == Placement::uniform) return (p - rest.rest_origin()).cwiseQuotient(rest.spacing());
    return rest.parameter_of(p);
}

/// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection 5.1.5), as barycentric weights.
Eigen::Vector3d closest_barycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
    const Eigen::Vector3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const double v = d1 / (d1 - d3);
        return {1 - v, v, 0};
    }
    const Eigen::Vector3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        const double w = d2 / (d2 - d6);
        return {1 - w, 0, w};
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return {0, 1 - w, w};
    }
    const double denom = 1 / (va + vb + vc);
    const double v = vb * denom, w = vc * denom;
    return {1 - v - w, v, w};
}

/// Area-weighted vertex normals (unnormalized sums of face cross products; a quad counts by the cross product of
/// its diagonals, twice its vector area).
std::vector<Eigen::Vector3d> vertex_normals(const TriangleMesh& mesh) {
    const auto& V = mesh.vertices;
    const std::size_t nv = V.size();
    std::vector<Eigen::Vector3d> n;
    n.resize(nv); // (each chunk zeroes its own vertices: the pages are first touched by the thread that fills them)
    // Each chunk of vertices, in parallel, takes every face with a corner in it, in the faces' order: a vertex's sum
    // adds up in the same order as one pass over the faces would, whatever the chunks. Extraction numbers the
    // vertices block by block, so most faces fall in one chunk (the bunny's 505,000 at 256: 19 ms on one core).
    const std::size_t chunks = std::clamp<std::size_t>(std::size_t(tbb::this_task_arena::max_concurrency()), 1, 64);
    const std::size_t per = (nv + chunks - 1) / std::max<std::size_t>(chunks, 1);
    tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t k) {
        const std::size_t lo = std::min(nv, k * per), hi = std::min(nv, lo + per);
        if (lo == hi) return;
        std::fill(n.begin() + std::ptrdiff_t(lo), n.begin() + std::ptrdiff_t(hi), Eigen::Vector3d::Zero());
        auto mine = [&](std::int32_t i) { return std::size_t(i) >= lo && std::size_t(i) < hi; };
        for (const auto& t : mesh.triangles) {
            if (!mine(t[0]) && !mine(t[1]) && !mine(t[2])) continue;
            const Eigen::Vector3d c = (V[t[1]] - V[t[0]]).cross(V[t[2]] - V[t[0]]);
            for (auto i : t)
                if (mine(i)) n[std::size_t(i)] += c;
        }
        for (const auto& q : mesh.quads) {
            if (!mine(q[0]) && !mine(q[1]) && !mine(q[2]) && !mine(q[3])) continue;
            const Eigen::Vector3d c = (V[q[2]] - V[q[0]]).cross(V[q[3]] - V[q[1]]);
            for (auto i : q)
                if (mine(i)) n[std::size_t(i)] += c;
        }
    });
    return n;
}

} // namespace snap_internal

/// The input's triangles with unit normals, and a CGAL tree over those that have area.
struct SourceSurface::Impl {
    using Point = snap_internal::Point;
    using Triangle = snap_internal::Triangle;
    using Iterator = snap_internal::Iterator;
    using Tree = snap_internal::Tree;
    using Hint = snap_internal::Hint;
    TriangleMesh storage;
    const std::vector<std::array<std::int32_t, 3>>& faces;
    const std::vector<Eigen::Vector3d>& V;
    std::vector<Eigen::Vector3d> normal;
    std::vector<Triangle> triangles;
    std::vector<std::int32_t> face_of; ///< triangles[i] is faces[face_of[i]]
    Tree tree;

    const TriangleMesh& input;

    explicit Impl(const TriangleMesh& mesh) : faces(all_triangles(mesh, storage)), V(mesh.vertices), input(mesh) {
        normal.resize(faces.size());
        auto point = [&](std::int32_t i) { return Point(V[std::size_t(i)].x(), V[std::size_t(i)].y(), V[std::size_t(i)].z()); };
        for (std::size_t f = 0; f < faces.size(); ++f) {
            const auto& t = faces[f];
            const Eigen::Vector3d c = (V[t[1]] - V[t[0]]).cross(V[t[2]] - V[t[0]]);
            normal[f] = c.norm() > 0 ? Eigen::Vector3d(c.normalized()) : Eigen::Vector3d::Zero();
            if (c.norm() > 0) {
                triangles.emplace_back(point(t[0]), point(t[1]), point(t[2]));
                face_of.push_back(std::int32_t(f));
            }
        }
        if (triangles.empty()) throw InvalidInput("snap: the input mesh has no faces with area");
        tree.insert(triangles.begin(), triangles.end());
        tree.build();
        tree.accelerate_distance_queries();
    }

    Eigen::Vector3d position(const SourcePoint& s) const {
        const auto& t = faces[std::size_t(s.face)];
        return s.barycentric[0] * V[t[0]] + s.barycentric[1] * V[t[1]] + s.barycentric[2] * V[t[2]];
    }

    /// The nearest point within `reach` of q on a face whose normal has a positive dot product with `n`. `hint` is
    /// the previous query's answer, which starts the tree's search when it lies within `near` of q (and is updated).
    SourcePoint nearest(const Eigen::Vector3d& q, const Eigen::Vector3d& n, double reach, std::optional<Hint>& hint, double near) const {
        const Point p(q.x(), q.y(), q.z());
        const bool close = hint && CGAL::squared_distance(p, hint->first) < near * near;
        const auto hit = close ? tree.closest_point_and_primitive(p, *hint) : tree.closest_point_and_primitive(p);
        hint = hit;
        const std::int32_t f = face_of[std::size_t(hit.second - triangles.begin())];
        const Eigen::Vector3d c(hit.first.x(), hit.first.y(), hit.first.z());
        SourcePoint best;
        if ((c - q).norm() > reach) return best;
        if (normal[std::size_t(f)].dot(n) > 0) {
            const auto& t = faces[std::size_t(f)];
            best.face = f;
            best.barycentric = snap_internal::closest_barycentric(q, V[t[0]], V[t[1]], V[t[2]]);
            return best;
        }
        // The nearest face looks the other way (the far side of a thin wall or gap): the nearest one that agrees.
        std::vector<Iterator> candidates;
        const CGAL::Bbox_3 box(q.x() - reach, q.y() - reach, q.z() - reach, q.x() + reach, q.y() + reach, q.z() + reach);
        tree.all_intersected_primitives(box, std::back_inserter(candidates));
        double nearest = reach * reach;
        for (const Iterator& it : candidates) {
            const std::int32_t g = face_of[std::size_t(it - triangles.begin())];
            if (!(normal[std::size_t(g)].dot(n) > 0)) continue;
            const auto& t = faces[std::size_t(g)];
            const Eigen::Vector3d b = snap_internal::closest_barycentric(q, V[t[0]], V[t[1]], V[t[2]]);
            const double d = (b[0] * V[t[0]] + b[1] * V[t[1]] + b[2] * V[t[2]] - q).squaredNorm();
            if (d <= nearest) nearest = d, best.face = g, best.barycentric = b;
        }
        return best;
    }
};

SourceSurface::SourceSurface(const TriangleMesh& input) : impl_(std::make_unique<Impl>(input)) {}
SourceSurface::~SourceSurface() = default;
const TriangleMesh& SourceSurface::mesh() const { return impl_->input; }

SourcePoint SourceSurface::nearest(const Eigen::Vector3d& point, const Eigen::Vector3d& normal, double reach) const {
    std::optional<Impl::Hint> hint;
    if (!normal.isZero()) return impl_->nearest(point, normal, reach, hint, 0);
    const auto hit = impl_->tree.closest_point_and_primitive(Impl::Point(point.x(), point.y(), point.z()));
    SourcePoint s;
    if ((Eigen::Vector3d(hit.first.x(), hit.first.y(), hit.first.z()) - point).norm() > reach) return s;
    s.face = impl_->face_of[std::size_t(hit.second - impl_->triangles.begin())];
    const auto& t = impl_->faces[std::size_t(s.face)];
    s.barycentric = snap_internal::closest_barycentric(point, impl_->V[t[0]], impl_->V[t[1]], impl_->V[t[2]]);
    return s;
}

namespace snap_internal {

/// Per vertex, the nearest vertex of another sheet of the surface within `radius`, or -1: the nearest vertex whose
/// normal looks the other way (the far side of a thin wall or gap, which the extraction may have put a hundredth of
/// a voxel away, or a voxel away all over a scan's thin shell). A snap must not push a vertex through that sheet.
///
/// Vertices are sorted by cell of `radius` (keys z-major, then y, then x), so the three x-neighbours of a cell are
/// one run of the sorted array, and walking the cells in order, each of the nine runs a cell needs starts at or
/// after where the previous cell's did: nine cursors that only move forward, no hash table and no cache misses.
/// Most of a surface has no other sheet within reach, so each cell keeps the cone of its vertices' normals (a unit
/// axis and the half-angle about it), and a cell whose cone cannot hold a normal looking against the vertex's, or
/// against the whole cone of the cell at hand, is passed over without reading its vertices.
std::vector<std::int32_t> other_sheet(const std::vector<Eigen::Vector3d>& P, const std::vector<Eigen::Vector3d>& normal, double radius) {
    const std::size_t n = P.size();
    const double inverse = 1 / radius;
    constexpr std::int64_t kOffset = 1 << 20; // cells are 21-bit fields, offset to stay positive
    auto key = [&](const Eigen::Vector3d& p) {
        const auto bits = [&](double x) { return std::uint64_t(std::int64_t(std::floor(x * inverse)) + kOffset) & 0x1fffff; };
        return bits(p.x()) | bits(p.y()) << 21 | bits(p.z()) << 42;
    };
    std::vector<std::pair<std::uint64_t, std::int32_t>> sorted(n);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) sorted[v] = {key(P[v]), std::int32_t(v)};
    });
    tbb::parallel_sort(sorted.begin(), sorted.end());
    std::vector<std::size_t> cells; // first index of each cell's run
    std::vector<std::int32_t> cell_of(n);
    for (std::size_t i = 0; i < n; ++i) {
        if (i == 0 || sorted[i].first != sorted[i - 1].first) cells.push_back(i);
        cell_of[i] = std::int32_t(cells.size() - 1);
    }
    cells.push_back(n);
    // Each cell's normal cone: unit normals (zero for a vertex in no face, which never counts), their mean
    // direction, and the sine and cosine of the widest angle from it (an empty or degenerate cone: half-angle pi).
    struct Cone {
        Eigen::Vector3d axis = Eigen::Vector3d::Zero();
        double sin = 0, cos = -1;
    };
    // Unit normals are worked out where they are needed rather than kept: at 218,000 vertices, an array of them
    // and one of distances were 7 MB of fresh pages, a third of this function's time on this machine.
    auto unit = [&](std::size_t a) -> Eigen::Vector3d {
        const Eigen::Vector3d& m = normal[std::size_t(sorted[a].second)];
        const double length = m.norm();
        return length > 0 && std::isfinite(length) ? Eigen::Vector3d(m / length) : Eigen::Vector3d::Zero();
    };
    std::vector<Cone> cone(cells.size() - 1);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cone.size(), 1024), [&](const auto& r) {
        for (std::size_t c = r.begin(); c != r.end(); ++c) {
            Eigen::Vector3d sum = Eigen::Vector3d::Zero();
            for (std::size_t a = cells[c]; a < cells[c + 1]; ++a) sum += unit(a);
            Cone& k = cone[c];
            if (!(sum.norm() > 0)) continue;
            k.axis = sum.normalized();
            k.cos = 1;
            for (std::size_t a = cells[c]; a < cells[c + 1]; ++a)
                if (const Eigen::Vector3d u = unit(a); !u.isZero()) k.cos = std::min(k.cos, u.dot(k.axis));
            k.cos = std::clamp(k.cos - 1e-9, -1.0, 1.0); // rounding must not narrow the cone
            k.sin = std::sqrt(1 - k.cos * k.cos);
        }
    });
    // Every normal within the cones of c and d has a non-negative dot product with every other when the angle
    // between the axes plus both half-angles stays under 90 degrees: cos(angle) > sin(half c + half d), with
    // cos(half c + half d) > 0.
    auto agree = [](const Cone& c, const Cone& d) {
        if (c.cos < 0 || d.cos < 0 || c.cos * d.cos - c.sin * d.sin <= 0) return false;
        return c.axis.dot(d.axis) > c.sin * d.cos + c.cos * d.sin;
    };
    std::vector<std::int32_t> out(n, -1);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells.size() - 1, 256), [&](const auto& r) {
        std::array<std::size_t, 9> cursor{};
        bool started = false;
        std::vector<double> nearest; // per vertex of the cell at hand, its nearest other sheet's distance squared
        for (std::size_t c = r.begin(); c != r.end(); ++c) {
            const std::uint64_t k = sorted[cells[c]].first;
            nearest.assign(cells[c + 1] - cells[c], radius * radius);
            for (int d = 0; d < 9; ++d) {
                const std::int64_t dy = d % 3 - 1, dz = d / 3 - 1;
                const std::uint64_t lo = std::uint64_t(std::int64_t(k) - 1 + dy * (std::int64_t(1) << 21) + dz * (std::int64_t(1) << 42));
                const std::uint64_t hi = lo + 2;
                std::size_t& i = cursor[std::size_t(d)];
                if (!started)
                    i = std::size_t(std::lower_bound(sorted.begin(), sorted.end(), std::pair<std::uint64_t, std::int32_t>(lo, -1)) - sorted.begin());
                while (i < n && sorted[i].first < lo) ++i;
                for (std::size_t j = i; j < n && sorted[j].first <= hi;) {
                    const std::size_t e = std::size_t(cell_of[j]), end = cells[e + 1];
                    const Cone& other = cone[e];
                    if (!agree(cone[c], other)) {
                        for (std::size_t a = cells[c]; a < cells[c + 1]; ++a) {
                            // A unit normal is a cone of half-angle 0: it agrees with the cell's when their dot
                            // product exceeds the cell's sine.
                            if (const Eigen::Vector3d u = unit(a); !u.isZero() && other.cos >= 0 && u.dot(other.axis) > other.sin) continue;
                            const std::size_t v = std::size_t(sorted[a].second);
                            double& least = nearest[a - cells[c]];
                            for (std::size_t b = j; b < end; ++b) {
                                const std::size_t w = std::size_t(sorted[b].second);
                                const double d2 = (P[w] - P[v]).squaredNorm();
                                if (d2 < least && normal[w].dot(normal[v]) < 0) least = d2, out[v] = std::int32_t(w);
                            }
                        }
                    }
                    j = end;
                }
            }
            started = true;
        }
    });
    return out;
}

/// Joins the lists of a parallel_reduce.
template <class T>
std::vector<T> concat(std::vector<T> a, const std::vector<T>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
}

/// Calls each(i, out) for every i in [0, n), in parallel over fixed blocks of `block`, and returns what the calls
/// appended to `out`, in the order of i (for lists of megabytes, which parallel_reduce with concat copies over and
/// over).
template <class T, class Each>
std::vector<T> gather_in_order(std::size_t n, std::size_t block, const Each& each) {
    std::vector<std::vector<T>> found((n + block - 1) / block);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, found.size()), [&](const auto& r) {
        for (std::size_t b = r.begin(); b != r.end(); ++b)
            for (std::size_t i = b * block; i != std::min(n, (b + 1) * block); ++i) each(i, found[b]);
    });
    std::size_t total = 0;
    for (const auto& f : found) total += f.size();
    std::vector<T> out;
    out.reserve(total);
    for (const auto& f : found) out.insert(out.end(), f.begin(), f.end());
    return out;
}

void check_options(const SnapOptions& options) {
    if (!(options.voxel_size > 0) || !std::isfinite(options.voxel_size))
        throw InvalidInput("snap: voxel size must be positive, got " + std::to_string(options.voxel_size));
}

} // namespace snap_internal

using namespace snap_internal;

Eigen::Vector3d push_forward(const std::vector<WarpStep>& steps, Eigen::Vector3d point) {
    for (const WarpStep& s : steps) point = s.moved.evaluate(rest_parameter(s.rest, point));
    return point;
}

namespace {

/// push_normal for several normals at one point: each step's Jacobians evaluated once for all of them.
template <std::size_t N>
std::array<Eigen::Vector3d, N> push_normals(const std::vector<WarpStep>& steps, Eigen::Vector3d point, std::array<Eigen::Vector3d, N> normals) {
    for (const WarpStep& s : steps) {
        const Eigen::Vector3d stu = rest_parameter(s.rest, point);
        Eigen::Matrix3d moved, rest;
        point = s.moved.evaluate(stu, moved);
        s.rest.evaluate(stu, rest);
        // The step's Jacobian is moved rest^-1, so its inverse transpose is moved^-T rest^T.
        const auto lu = moved.transpose().partialPivLu();
        for (auto& normal : normals) normal = lu.solve(rest.transpose() * normal);
    }
    for (auto& normal : normals) normal = normal.norm() > 0 && normal.allFinite() ? Eigen::Vector3d(normal.normalized()) : Eigen::Vector3d::Zero();
    return normals;
}

} // namespace

Eigen::Vector3d push_normal(const std::vector<WarpStep>& steps, Eigen::Vector3d point, Eigen::Vector3d normal) {
    return push_normals<1>(steps, point, {normal})[0];
}

std::optional<Eigen::Vector3d> pull_back(const std::vector<WarpStep>& steps, Eigen::Vector3d point, Eigen::Matrix3d* jacobian) {
    Eigen::Matrix3d J;
    double size = 0;
    for (const WarpStep& s : steps) size = std::max(size, s.moved.spacing().maxCoeff());
    // A trillionth of a region, or a few ulps of the point where it lies far from the origin (Newton stalls there).
    const auto q = Puller(steps, 0, std::max(1e-12 * size, 1e-14 * point.norm()))(point, J);
    if (jacobian) *jacobian = J;
    return q;
}

std::vector<SourcePoint> find_sources(const TriangleMesh& output, const TriangleMesh& input, const std::vector<WarpStep>& steps,
                                      const SnapOptions& options) {
    check_options(options);
    return find_sources(output, SourceSurface(input), steps, options);
}

namespace {

/// find_sources, given the output's vertex normals (snap needs them too).
std::vector<SourcePoint> find_sources(const TriangleMesh& output, const SourceSurface& input, const std::vector<WarpStep>& steps,
                                      const SnapOptions& options, const std::vector<Eigen::Vector3d>& normals) {
    check_options(options);
    const SourceSurface::Impl& surface = input.impl();
    const double reach = options.reach_voxels * options.voxel_size;
    std::vector<SourcePoint> out;
    out.reserve(output.vertices.capacity()); // the output's room for refinement's vertices: theirs are added here
    out.resize(output.vertices.size());
    const double near = 4 * options.voxel_size;
    // Newton's warm start and the tree's hint carry from one vertex to the next within a block, so the blocks are
    // fixed (not the scheduler's ranges, which vary from run to run): the answers, equal only to Newton's
    // tolerance whatever the start, are then the same bits for any thread count.
    constexpr std::size_t kBlock = 512;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, (out.size() + kBlock - 1) / kBlock), [&](const auto& blocks) {
        for (std::size_t block = blocks.begin(); block != blocks.end(); ++block) {
            Puller pull(steps, near, 1e-5 * options.voxel_size); // a hundred-thousandth of a voxel is exact for a mesh
            std::optional<Hint> hint;
            for (std::size_t v = block * kBlock; v != std::min(out.size(), (block + 1) * kBlock); ++v) {
                if (normals[v].squaredNorm() == 0) continue; // in no face
                Eigen::Matrix3d J;
                const auto q = pull(output.vertices[v], J);
                if (!q) continue;
                // Normals go back with the transpose of the map's Jacobian (they are covectors).
                out[v] = surface.nearest(*q, J.transpose() * normals[v], reach, hint, near);
            }
        }
    });
    return out;
}

} // namespace

std::vector<SourcePoint> find_sources(const TriangleMesh& output, const SourceSurface& input, const std::vector<WarpStep>& steps,
                                      const SnapOptions& options) {
    return find_sources(output, input, steps, options, vertex_normals(output));
}

namespace {

/// Whether the segment p-q passes through triangle abc.
bool segment_meets(const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const double u = internal::line_meets_triangle(p, q - p, a, b, c);
    return u >= 0 && u <= 1;
}

/// Whether triangles a and b (vertex indices into P) cross: a side of either passes through the other, sides that
/// share a corner with the other not counted (they meet there).
/// `at(i)`: the position of corner i.
template <class At>
bool triangles_cross(const At& at, const std::array<std::int32_t, 3>& a, const std::array<std::int32_t, 3>& b) {
    auto side_through = [&](const std::array<std::int32_t, 3>& s, const std::array<std::int32_t, 3>& t) {
        for (int k = 0; k < 3; ++k) {
            const std::int32_t e0 = s[std::size_t(k)], e1 = s[std::size_t((k + 1) % 3)];
            if (std::find(t.begin(), t.end(), e0) != t.end() || std::find(t.begin(), t.end(), e1) != t.end()) continue;
            if (segment_meets(at(e0), at(e1), at(t[0]), at(t[1]), at(t[2]))) return true;
        }
        return false;
    };
    return side_through(a, b) || side_through(b, a);
}

/// Voxels: the least a snapped vertex keeps from the other sheet's plane, and the gap under which sheets count as
/// touching (snap).
constexpr double kSheetMargin = 0.05;
/// How far (in max_move) an exact image may lie for its vertex to move part of the way toward it (snap).
constexpr double kPartReach = 2;
/// The cosine of the angle from a corner's extracted normal past which a snapped triangle is tested for crossing
/// those around it (snap, refinement), and how deep (voxels) two must pass through each other's planes to count as
/// crossing (snap): deeper than round-off. A ten-thousandth of a voxel let the feature mesher's snapped output keep
/// crossings CGAL finds (the snowden scan at 128: 74 pairs deeper than 1e-9 voxel, the deepest 4.8e-5; now 1.2e-6).
constexpr double kSteep = 0.7071;
constexpr double kCrossDepth = 1e-12;

/// A compressed adjacency: start[k] .. start[k + 1] index the items of key k. `each(visit)` calls visit(key, item)
/// for every pair, the same pairs in the same order each time it is called.
struct Adjacency {
    std::vector<std::uint32_t> start, items;
    template <class Each>
    Adjacency(std::size_t keys, const Each& each) : start(keys + 1, 0) {
        each([&](std::size_t k, std::uint32_t) { ++start[k + 1]; });
        for (std::size_t k = 0; k < keys; ++k) start[k + 1] += start[k];
        items.resize(start[keys]);
        std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
        each([&](std::size_t k, std::uint32_t v) { items[fill[k]++] = v; });
    }
    const std::uint32_t* begin(std::size_t k) const { return items.data() + start[k]; }
    const std::uint32_t* end(std::size_t k) const { return items.data() + start[k + 1]; }
};

/// Whether a face that turned from `before` to `after` (unnormalized normals) now looks away from the extracted
/// normal at one of its corners `t` that it looked along before: a fold with its neighbours, which need not flip it.
bool turns_from_corners(const Eigen::Vector3d& before, const Eigen::Vector3d& after, const std::array<std::int32_t, 3>& t,
                        const std::vector<Eigen::Vector3d>& normal) {
    return std::any_of(t.begin(), t.end(), [&](std::int32_t i) { return after.dot(normal[std::size_t(i)]) <= 0 && before.dot(normal[std::size_t(i)]) > 0; });
}

/// Whether a face with normal `n` (unnormalized) at a point of a crease, whose faces' exact normals are `e` (unit),
/// turns from either of them by more than the crease turns (its normals' angle) and a margin: a face on the crease
/// faces between them. The margin is 45 degrees, or half what the crease leaves to a half turn where that is less,
/// so that even a knife edge rejects a face turned fully away from one side. A piece lying flat on one face but
/// facing away from it (an in-plane fold) can still look along the other face's normal where the crease is sharper
/// than a right angle (the bar bend's ends, whose walls the map leans 30-50 degrees over the bottom face).
bool off_crease(const Eigen::Vector3d& n, const std::array<Eigen::Vector3d, 2>& e) {
    const double turn = std::atan2(e[0].cross(e[1]).norm(), e[0].dot(e[1]));
    if (!(turn > 1e-6)) return false; // one face: judged as any other face is
    constexpr double kPi = std::numbers::pi;
    const double bound = std::cos(std::max(0.5 * kPi, turn + std::min(0.25 * kPi, 0.5 * (kPi - turn))));
    const double length = n.norm();
    return n.dot(e[0]) < bound * length || n.dot(e[1]) < bound * length;
}

/// Whether a face with normal `n` (unnormalized) turns further than kSteep from the extracted normal at one of its
/// corners `t`: where a snapped or split face may pass through one a few triangles away.
bool steep_at_corners(const Eigen::Vector3d& n, const std::array<std::int32_t, 3>& t, const std::vector<Eigen::Vector3d>& normal) {
    return std::any_of(t.begin(), t.end(), [&](std::int32_t i) { return n.dot(normal[std::size_t(i)]) < kSteep * n.norm() * normal[std::size_t(i)].norm(); });
}

/// What snapping finds out about the output as extracted, which refinement's first round needs again.
struct Sheets {
    std::vector<Eigen::Vector3d> normal; ///< vertex_normals
    std::vector<std::int32_t> partner;   ///< other_sheet within 1.5 voxels
    std::vector<std::int32_t> left;      ///< the vertices of faces that snapping left where extraction made them
};

/// `normal`: vertex_normals(output), or empty (worked out here).
SnapReport snap(TriangleMesh& output, const TriangleMesh& input, const std::vector<WarpStep>& steps, const std::vector<SourcePoint>& sources,
                const SnapOptions& options, Sheets* keep, std::vector<Eigen::Vector3d> normal = {}) {
    check_options(options);
    if (sources.size() != output.vertices.size())
        throw InvalidInput("snap: " + std::to_string(sources.size()) + " source points for " + std::to_string(output.vertices.size()) + " vertices");
    TriangleMesh storage;
    const auto& faces = all_triangles(input, storage);
    const auto& V = input.vertices;
    const std::size_t n = output.vertices.size();
    const double max_move = options.max_move_voxels * options.voxel_size;
    std::vector<Eigen::Vector3d> target(n);
    // A vertex whose image lies farther than max_move, but within kPartReach times that, moves max_move toward
    // it: where the thin-part carry thickens a wall a voxel thin (the scan at 64), the thick side's vertices lie
    // 0.5-1 voxel off the exact warp (output to exact warp p99 0.55 voxel, 0.40 so). Going all the way did no
    // better (0.41): the checks below put more of those vertices back.
    std::vector<char> snapped(n, 0), in_face(n, 0), partial(n, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 512), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) {
            const SourcePoint& s = sources[v];
            if (s.face < 0 || std::size_t(s.face) >= faces.size()) continue;
            const auto& t = faces[std::size_t(s.face)];
            target[v] = push_forward(steps, s.barycentric[0] * V[t[0]] + s.barycentric[1] * V[t[1]] + s.barycentric[2] * V[t[2]]);
            if (!target[v].allFinite()) continue;
            const double d = (target[v] - output.vertices[v]).norm();
            if (d > max_move && d <= kPartReach * max_move) {
                target[v] = output.vertices[v] + (max_move / d) * (target[v] - output.vertices[v]);
                partial[v] = 1;
            }
            snapped[v] = partial[v] || d <= max_move;
        }
    });

    // The faces to check, as triangles: quads by all four corner triangles, so neither diagonal may fold.
    std::vector<std::array<std::int32_t, 3>> corners;
    if (!output.quads.empty()) {
        corners = output.triangles;
        for (const auto& q : output.quads)
            for (int c = 0; c < 4; ++c) corners.push_back({q[std::size_t((c + 3) % 4)], q[std::size_t(c)], q[std::size_t((c + 1) % 4)]});
    }
    const auto& checks = output.quads.empty() ? output.triangles : corners;
    for (const auto& t : checks)
        for (auto i : t) in_face[std::size_t(i)] = 1;
    const auto& P = output.vertices;
    auto at = [&](std::int32_t i) -> const Eigen::Vector3d& { return snapped[std::size_t(i)] ? target[std::size_t(i)] : P[std::size_t(i)]; };
    const double tiny = 1e-4 * options.voxel_size * options.voxel_size;
    if (normal.size() != n) normal = vertex_normals(output); // as extracted
    // The far side of a thin wall or gap: each vertex's nearest vertex of another sheet, and the side of that sheet
    // (its tangent plane there) the vertex is on.
    std::vector<std::int32_t> partner = snap_internal::other_sheet(P, normal, 1.5 * options.voxel_size);
    // Where the extracted sheets all but touch (the thin-part carry leaves them hundredths of a voxel apart), the
    // pair check below, which keeps a twentieth of a voxel between a vertex and its own partner's plane, is coarser
    // than the gap: there a vertex moves at most a third of the way to the other sheet of any corner of a face
    // around it. With the pair check alone the scan's output, edited again at 96, pushed two vertices 0.19 and
    // 0.14 voxel through faces whose vertices' partners held them.
    const double touching = kSheetMargin * options.voxel_size;
    {
        std::vector<double> room(n, std::numeric_limits<double>::infinity());
        for (const auto& t : checks) {
            double least = std::numeric_limits<double>::infinity();
            for (auto i : t)
                if (partner[std::size_t(i)] >= 0) least = std::min(least, (P[std::size_t(i)] - P[std::size_t(partner[std::size_t(i)])]).norm());
            for (auto i : t) room[std::size_t(i)] = std::min(room[std::size_t(i)], least);
        }
        for (std::size_t v = 0; v < n; ++v)
            if (snapped[v] && room[v] < touching && (target[v] - P[v]).norm() > room[v] / 3) snapped[v] = 0;
    }
    // Anchors: a tip or thin edge that the voxmap rounds off has no output vertex whose source lies on it, and a
    // move's target there was missed by most of a voxel (the bunny's ear tip: 0.83). The vertex nearest the
    // anchor's image goes onto the image; the fold checks below still apply.
    std::vector<char> anchored(n, 0);
    for (const auto& a : options.anchors) {
        const Eigen::Vector3d image = push_forward(steps, a);
        if (!image.allFinite()) continue;
        std::size_t best = n;
        double nearest = options.anchor_reach_voxels * options.voxel_size;
        for (std::size_t v = 0; v < n; ++v) {
            const double d = (P[v] - image).norm();
            if (in_face[v] && d < nearest) nearest = d, best = v;
        }
        if (best == n || anchored[best]) continue;
        // The pull fades over the anchor reach (or three times the pull) around the vertex, flat at first, so that
        // the faces near it move with it and those farther out turn a little each, rather than a few folding (a
        // thin tip's faces stand steep to each other). Only the vertex's own sheet follows, not the far side of a
        // thin part. The pull moves the surface as extracted, not as snapped: on a thin tip both sheets snap onto
        // the input's sharper tip, and the pull on top of that folded the bunny's ear.
        const Eigen::Vector3d from = P[best], pull = image - from;
        const double reach = std::max(options.anchor_reach_voxels * options.voxel_size, 3 * pull.norm());
        std::vector<std::pair<std::size_t, Eigen::Vector3d>> moves;
        for (std::size_t v = 0; v < n; ++v) {
            const double d = (P[v] - P[best]).norm();
            if (!in_face[v] || anchored[v] || d >= reach || normal[v].dot(normal[best]) <= 0) continue;
            const double w = (1 - (d / reach) * (d / reach)) * (1 - (d / reach) * (d / reach));
            moves.push_back({v, P[v] + w * pull});
        }
        for (const auto& [v, p] : moves) target[v] = p, snapped[v] = 1, anchored[v] = 1;
    }
    // A triangle fails when a snapped corner turns it by more than 90 degrees, collapses it, or turns it away from
    // the surface's normal as extracted at a corner (a fold with its neighbours, which need not flip it).
    auto fails = [&](const std::array<std::int32_t, 3>& t) {
        if (!snapped[std::size_t(t[0])] && !snapped[std::size_t(t[1])] && !snapped[std::size_t(t[2])]) return false;
        const Eigen::Vector3d before = (P[t[1]] - P[t[0]]).cross(P[t[2]] - P[t[0]]);
        const Eigen::Vector3d after = (at(t[1]) - at(t[0])).cross(at(t[2]) - at(t[0]));
        if (before.norm() == 0) return false; // a face that had no area has no side to flip to
        if (after.dot(before) <= 0 || (after.norm() < tiny && after.norm() < 0.1 * before.norm())) return true;
        return turns_from_corners(before, after, t, normal);
    };
    // Put back the snapped corners of every face that fails, and of every pair of sheets that would cross, until
    // none does (each pass puts back at least one vertex, and a face or pair with no snapped vertex cannot fail).
    // Only a face or pair with a vertex put back in the last pass can fail anew, so later passes look at those
    // alone. Failures are rare: a few short passes.
    // Whether vertex v and its partner u, either snapped, would cross.
    auto pair_crosses = [&](std::size_t v, std::size_t u) {
        if (!(snapped[v] || snapped[u]) || anchored[v] || anchored[u]) return false;
        const Eigen::Vector3d m = normal[u].normalized();
        const double before = (P[v] - P[u]).dot(m), after = (at(std::int32_t(v)) - at(std::int32_t(u))).dot(m);
        return (before < 0 ? -after : after) < std::min(std::abs(before) / 3, touching);
    };
    std::vector<char> tried(n, 0);
    auto settle = [&](std::vector<char> changed) {
        for (;;) {
            std::vector<std::int32_t> put_back = tbb::parallel_reduce(
                tbb::blocked_range<std::size_t>(0, checks.size(), 4096), std::vector<std::int32_t>(),
                [&](const auto& r, std::vector<std::int32_t> found) {
                    for (std::size_t f = r.begin(); f != r.end(); ++f) {
                        const auto& t = checks[f];
                        if (!changed.empty() && !changed[std::size_t(t[0])] && !changed[std::size_t(t[1])] && !changed[std::size_t(t[2])]) continue;
                        if (!fails(t)) continue;
                        // An anchor carries the user's target: its face's other snapped corners go back first.
                        const bool others = std::any_of(t.begin(), t.end(), [&](auto i) { return snapped[std::size_t(i)] && !anchored[std::size_t(i)]; });
                        for (auto i : t)
                            if (snapped[std::size_t(i)] && !(others && anchored[std::size_t(i)])) found.push_back(i);
                    }
                    return found;
                },
                concat<std::int32_t>);
            // A vertex stays on its side of the other sheet's tangent plane, at least a third of the gap extracted or a
            // twentieth of a voxel from it, wherever both end up: both sides of a thin wall or gap snap onto the input's
            // two sides (the scan's shell at 64: walls a voxel thick all over), but one that snaps alone, or onto the
            // wrong side, could cross the other. An anchor's pull is along its tip, where the sheets meet: the fold
            // checks alone judge it.
            const std::vector<std::int32_t> crossing = tbb::parallel_reduce(
                tbb::blocked_range<std::size_t>(0, n, 4096), std::vector<std::int32_t>(),
                [&](const auto& r, std::vector<std::int32_t> found) {
                    for (std::size_t v = r.begin(); v != r.end(); ++v) {
                        const std::int32_t u = partner[v];
                        if (u < 0 || (!changed.empty() && !changed[v] && !changed[std::size_t(u)]) || !pair_crosses(v, std::size_t(u))) continue;
                        for (const std::size_t i : {v, std::size_t(u)})
                            if (snapped[i]) found.push_back(std::int32_t(i));
                    }
                    return found;
                },
                concat<std::int32_t>);
            for (auto i : put_back) tried[std::size_t(i)] = 1;
            for (auto i : crossing) tried[std::size_t(i)] = 0;
            put_back.insert(put_back.end(), crossing.begin(), crossing.end());
            if (put_back.empty()) break;
            changed.assign(n, 0);
            for (auto i : put_back) snapped[std::size_t(i)] = 0, changed[std::size_t(i)] = 1;
        }
    };
    settle({});
    // A failing face puts back all its snapped corners, where one of them alone may have turned it: each vertex a
    // face put back tries again alone, in order, against its faces and pairs as they now stand (the bunny ear's
    // rim: a vertex half a voxel from its image stayed there, 0.53 voxel under the exact warp). Not those the pair
    // check put back: letting them try too gave the feature mesher's output more crossings (the scan's 327 -> 365).
    std::optional<Adjacency> faces_of; // vertex -> the faces around it, built when first needed
    auto faces_around = [&]() -> const Adjacency& {
        if (!faces_of)
            faces_of.emplace(n, [&](auto visit) {
                for (std::size_t f = 0; f < checks.size(); ++f)
                    for (auto i : checks[f]) visit(std::size_t(i), std::uint32_t(f));
            });
        return *faces_of;
    };
    if (std::find(tried.begin(), tried.end(), 1) != tried.end()) {
        const Adjacency& faces = faces_around();
        const Adjacency partnered(n, [&](auto visit) { // v -> u with partner[u] == v
            for (std::size_t u = 0; u < n; ++u)
                if (partner[u] >= 0) visit(std::size_t(partner[u]), std::uint32_t(u));
        });
        for (std::size_t v = 0; v < n; ++v) {
            if (!tried[v] || snapped[v]) continue;
            snapped[v] = 1;
            bool fine = std::none_of(faces.begin(v), faces.end(v), [&](std::uint32_t f) { return fails(checks[f]); });
            if (fine && partner[v] >= 0) fine = !pair_crosses(v, std::size_t(partner[v]));
            for (const std::uint32_t* u = partnered.begin(v); fine && u != partnered.end(v); ++u) fine = !pair_crosses(*u, v);
            snapped[v] = fine;
        }
    }
    // A sheet folded through itself a few triangles from the move: the feature mesher's output has faces that
    // meet at sharp edges and fans of slivers, where a snapped corner can push a triangle through one two or three
    // triangles away that the checks above, per face and per pair of sheets, do not look at (the bunny ear edit at
    // 128: 27 pairs crossing deeper than a thousandth of a voxel after snapping, 6 with this test). The triangles that
    // turn more than 45 degrees from a corner's extracted normal are tested against those two rings around them;
    // where two cross, their snapped corners go back, and the checks above run again on what that changed, until
    // none crosses. Marching cubes' smoother output has fewer such triangles, and none found crossing on the bundled
    // edits.
    std::vector<char> near_changed; // after the first pass: the corners of the faces around a vertex put back
    for (;;) {
        const std::vector<std::uint32_t> steep = tbb::parallel_reduce(
            tbb::blocked_range<std::size_t>(0, checks.size(), 4096), std::vector<std::uint32_t>(),
            [&](const auto& r, std::vector<std::uint32_t> found) {
                for (std::size_t f = r.begin(); f != r.end(); ++f) {
                    const auto& t = checks[f];
                    if (!snapped[std::size_t(t[0])] && !snapped[std::size_t(t[1])] && !snapped[std::size_t(t[2])]) continue;
                    if (!near_changed.empty() && !near_changed[std::size_t(t[0])] && !near_changed[std::size_t(t[1])] && !near_changed[std::size_t(t[2])]) continue;
                    const Eigen::Vector3d after = (at(t[1]) - at(t[0])).cross(at(t[2]) - at(t[0]));
                    if (steep_at_corners(after, t, normal)) found.push_back(std::uint32_t(f));
                }
                return found;
            },
            concat<std::uint32_t>);
        if (steep.empty()) break;
        const Adjacency& faces = faces_around();
        // The faces around face t: those with a corner on a face with a corner of t.
        auto around = [&](const std::array<std::int32_t, 3>& t, std::vector<std::uint32_t>& out) {
            out.clear();
            for (const auto c : t)
                for (const std::uint32_t* g = faces.begin(std::size_t(c)); g != faces.end(std::size_t(c)); ++g)
                    for (const auto d : checks[*g]) out.insert(out.end(), faces.begin(std::size_t(d)), faces.end(std::size_t(d)));
            std::sort(out.begin(), out.end());
            out.erase(std::unique(out.begin(), out.end()), out.end());
        };
        auto straddles = [&](const std::array<std::int32_t, 3>& a, const std::array<std::int32_t, 3>& plane) {
            return internal::straddle_depth(at(a[0]), at(a[1]), at(a[2]), at(plane[0]), at(plane[1]), at(plane[2])) > kCrossDepth * options.voxel_size;
        };
        const std::vector<std::int32_t> crossing = tbb::parallel_reduce(
            tbb::blocked_range<std::size_t>(0, steep.size(), 64), std::vector<std::int32_t>(),
            [&](const auto& r, std::vector<std::int32_t> found) {
                std::vector<std::uint32_t> others;
                for (std::size_t k = r.begin(); k != r.end(); ++k) {
                    const auto& a = checks[steep[k]];
                    around(a, others);
                    for (const std::uint32_t g : others) {
                        const auto& b = checks[g];
                        if (g == steep[k] || !straddles(a, b) || !straddles(b, a) || !triangles_cross(at, a, b)) continue;
                        for (const auto& t : {a, b})
                            for (const auto i : t)
                                if (snapped[std::size_t(i)]) found.push_back(i);
                    }
                }
                return found;
            },
            concat<std::int32_t>);
        if (crossing.empty()) break;
        const std::vector<char> was_snapped = snapped;
        std::vector<char> changed(n, 0);
        for (auto i : crossing) snapped[std::size_t(i)] = 0, changed[std::size_t(i)] = 1;
        settle(std::move(changed));
        // What the next pass looks at: only a pair with a corner put back can cross anew, so the faces around (as
        // around() has it) each face of a vertex put back in this one.
        near_changed.assign(n, 0);
        std::vector<std::uint32_t> ring;
        for (std::size_t v = 0; v < n; ++v) {
            if (was_snapped[v] == snapped[v]) continue;
            for (const std::uint32_t* g = faces.begin(v); g != faces.end(v); ++g) {
                around(checks[*g], ring);
                for (const std::uint32_t f : ring)
                    for (const auto c : checks[f]) near_changed[std::size_t(c)] = 1;
            }
        }
    }
    SnapReport report;
    for (std::size_t v = 0; v < n; ++v) {
        if (snapped[v]) {
            output.vertices[v] = target[v];
            ++(partial[v] && !anchored[v] ? report.partly_snapped : report.snapped);
        } else if (in_face[v]) {
            ++report.unsnapped;
        }
    }
    if (keep) {
        keep->normal = std::move(normal), keep->partner = std::move(partner);
        keep->left.clear();
        for (std::size_t v = 0; v < n; ++v)
            if (!snapped[v] && in_face[v] && target[v].allFinite() && sources[v].face >= 0) keep->left.push_back(std::int32_t(v));
    }
    return report;
}

} // namespace

SnapReport snap_to_sources(TriangleMesh& output, const TriangleMesh& input, const std::vector<WarpStep>& steps, const std::vector<SourcePoint>& sources,
                           const SnapOptions& options) {
    return snap(output, input, steps, sources, options, nullptr);
}

namespace {

/// A corner of a refined triangle: a vertex of the mesh (>= 0) or the new vertex of split e (-(e + 1)).
using Corner = std::int32_t;

/// The pieces of triangle (v0, v1, v2) whose edges (v0 v1), (v1 v2), (v2 v0) are split where `split[k]`, as
/// corners, in the triangle's own orientation: 1, 2, 3 or 4 of them. `middle` gives a split edge's corner and
/// `length2` the squared length of a diagonal (the shorter one cuts a four-sided piece, the longer with
/// `other_diagonal`).
template <class Middle, class Length2>
void pieces(const std::array<std::int32_t, 3>& v, const std::array<bool, 3>& split, Middle middle, Length2 length2,
            std::vector<std::array<Corner, 3>>& out, bool other_diagonal = false) {
    const int count = int(split[0]) + int(split[1]) + int(split[2]);
    if (count == 0) {
        out.push_back(v);
    } else if (count == 3) {
        const Corner m0 = middle(0), m1 = middle(1), m2 = middle(2);
        out.insert(out.end(), {{v[0], m0, m2}, {v[1], m1, m0}, {v[2], m2, m1}, {m0, m1, m2}});
    } else if (count == 1) {
        const int k = split[0] ? 0 : split[1] ? 1 : 2;
        const Corner a = v[std::size_t(k)], b = v[std::size_t((k + 1) % 3)], c = v[std::size_t((k + 2) % 3)], m = middle(k);
        out.insert(out.end(), {{a, m, c}, {m, b, c}});
    } else {
        const int k = !split[0] ? 0 : !split[1] ? 1 : 2; // the edge left whole: (a b)
        const Corner a = v[std::size_t(k)], b = v[std::size_t((k + 1) % 3)], c = v[std::size_t((k + 2) % 3)];
        const Corner bc = middle((k + 1) % 3), ca = middle((k + 2) % 3);
        out.push_back({bc, c, ca});
        if ((length2(a, bc) <= length2(b, ca)) != other_diagonal) out.insert(out.end(), {{a, b, bc}, {a, bc, ca}});
        else out.insert(out.end(), {{a, b, ca}, {b, bc, ca}});
    }
}

/// Where faces f and g of the input share an edge, the point of that edge nearest to segment pa pb (pa on f, pb on
/// g): where the output's edge between them crosses the crease, so that the pieces on either side lie on f and on
/// g exactly (the straight edges of a box or a low-poly model stay straight). As a source point on f.
std::optional<SourcePoint> crease_point(const SourceSurface::Impl& surface, std::int32_t f, std::int32_t g, const Eigen::Vector3d& pa, const Eigen::Vector3d& pb) {
    const auto &A = surface.faces[std::size_t(f)], &B = surface.faces[std::size_t(g)];
    std::array<std::int32_t, 2> shared{};
    int count = 0;
    for (auto i : A)
        if (std::find(B.begin(), B.end(), i) != B.end() && count < 2) shared[std::size_t(count++)] = i;
    if (count != 2) return std::nullopt;
    // Closest points of two segments (Ericson 5.1.9), kept on the shared edge u w.
    const Eigen::Vector3d u = surface.V[std::size_t(shared[0])], w = surface.V[std::size_t(shared[1])];
    const Eigen::Vector3d d1 = pb - pa, d2 = w - u, r = pa - u;
    const double a = d1.squaredNorm(), e = d2.squaredNorm(), c = d1.dot(r), b = d1.dot(d2), fr = d2.dot(r), denominator = a * e - b * b;
    if (!(e > 0)) return std::nullopt;
    const double sp = denominator > 1e-12 * a * e ? std::clamp((b * fr - c * e) / denominator, 0.0, 1.0) : 0.5; // along pa pb
    const double t = std::clamp((b * sp + fr) / e, 0.0, 1.0);
    SourcePoint s;
    s.face = f;
    s.barycentric = snap_internal::closest_barycentric(u + t * d2, surface.V[std::size_t(A[0])], surface.V[std::size_t(A[1])], surface.V[std::size_t(A[2])]);
    return s;
}

/// Voxels: how far a corner's or crease point's image may lie from the output for it to be put in (insert_points).
constexpr double kCornerReach = 1.5;

/// Passes of insert_points: a point refused beside one just put in is tried again in the next pass. Along a
/// crease every other point waits, so more passes bring a box's edges closer: mean 0.093 / 0.079 voxel (bent box at
/// 64 / 128) after 3 passes, 0.074 / 0.056 after 6, no closer after 12. A pass costs about what its waiting points
/// do (OutputIndex; the bunny's ear edit at 256: 0.05 s for the first, 2 400 points, under 0.01 s from the fourth,
/// under 500). But on a scan, whose every vertex is a corner, tens of thousands wait after three passes (the
/// snowden scan at 128: 31 660 of 82 637), and eight passes took its snapping from 2.0 to 4.0 s. So the passes
/// after kInsertRoundsAlways go on only while at most kLatePassPoints points wait.
constexpr int kInsertRounds = 8;
constexpr int kInsertRoundsAlways = 3;
constexpr std::ptrdiff_t kLatePassPoints = 4096;

/// Sides a segment joining two points of a crease may cross (join_creases): points half a voxel apart cross a few.
constexpr std::size_t kJoinCrossings = 32;

/// A corner's piece may turn from the neighbour across its side by at most acos(-kCornerFold) (150 degrees).
constexpr double kCornerFold = 0.866;

/// A corner whose nearest point on its output triangle has a barycentric weight under this lies over the side
/// opposite that weight's vertex, and splits the side (a three-way split would leave a piece standing on it).
constexpr double kCornerSide = 0.1;
/// A feature point whose nearest triangle cannot be split soundly tries this many of the next nearest.
constexpr std::size_t kFartherTriangles = 8;

/// Voxels between the points put in along a crease (insert_points).
constexpr double kCreaseSpacing = 0.5;

/// An input vertex whose faces meet at more than this angle (degrees) is a corner: a tip, or where creases meet.
constexpr double kCornerAngle = 10;

/// A point of the input where its faces meet at an angle (a corner, or a point of a crease), the faces it lies on
/// and a source point for it.
struct FeaturePoint {
    static constexpr std::size_t kFaces = 8; ///< a corner's faces beyond these are not looked at
    Eigen::Vector3d at = Eigen::Vector3d::Zero(), image = Eigen::Vector3d::Zero(); ///< on the input; pushed forward
    std::array<std::uint32_t, kFaces> faces{};
    std::size_t count = 0;
    SourcePoint source;
};

/// The input's faces with area around each of its vertices.
Adjacency faces_with_area(const SourceSurface::Impl& surface) {
    return Adjacency(surface.V.size(), [&](auto visit) {
        for (std::size_t f = 0; f < surface.faces.size(); ++f)
            if (!surface.normal[f].isZero())
                for (const auto v : surface.faces[f]) visit(std::size_t(v), std::uint32_t(f));
    });
}

/// A crease of the input: side (first, second), first < second, of face f, shared with exactly one other face g
/// (both with area), their normals more than kCornerAngle apart.
struct Crease {
    std::int32_t first, second;
    std::uint32_t f, g;
};

/// The input's creases, each once from the face that has it running from its lower vertex to its higher, in the
/// faces' order (feature_points and join_creases). `around`: faces_with_area(surface).
std::vector<Crease> input_creases(const SourceSurface::Impl& surface, const Adjacency& around) {
    const double cos_corner = std::cos(kCornerAngle * M_PI / 180.0);
    const auto& F = surface.faces;
    return gather_in_order<Crease>(F.size(), 4096, [&](std::size_t f, std::vector<Crease>& creases) {
        if (surface.normal[f].isZero()) return;
        for (int k = 0; k < 3; ++k) {
            const std::int32_t first = F[f][std::size_t(k)], second = F[f][std::size_t((k + 1) % 3)];
            if (first > second) continue;
            std::int64_t g = -1;
            int sharing = 0;
            for (const std::uint32_t* q = around.begin(std::size_t(first)); q != around.end(std::size_t(first)); ++q)
                if (*q != f && std::find(F[*q].begin(), F[*q].end(), second) != F[*q].end()) g = *q, ++sharing;
            if (sharing == 1 && surface.normal[f].dot(surface.normal[std::size_t(g)]) < cos_corner)
                creases.push_back({first, second, std::uint32_t(f), std::uint32_t(g)});
        }
    });
}

/// The input's corners (vertices whose faces' normals spread by more than kCornerAngle) and points along its creases
/// (edges whose faces meet at more than that), half a voxel apart after `steps`, where the faces are large enough to
/// matter at voxel size `h`: a corner with an edge half a voxel long, a crease half a voxel long.
std::vector<FeaturePoint> feature_points(const SourceSurface::Impl& surface, const std::vector<WarpStep>& steps, double h) {
    const double cos_corner = std::cos(kCornerAngle * M_PI / 180.0);
    const auto& F = surface.faces;
    const auto& V = surface.V;
    const Adjacency around = faces_with_area(surface);
    auto slot = [&](std::uint32_t f, std::size_t v) { // barycentric weights of vertex v in face f
        Eigen::Vector3d b = Eigen::Vector3d::Zero();
        for (int k = 0; k < 3; ++k) b[k] = std::size_t(F[f][std::size_t(k)]) == v ? 1.0 : 0.0;
        return b;
    };
    // Corners, then crease points, each in the input's order (in parallel: a scan of 600,000 faces took 0.29 s on
    // one core).
    std::vector<FeaturePoint> points = gather_in_order<FeaturePoint>(V.size(), 4096, [&](std::size_t v, auto& found) {
        const std::uint32_t *fs = around.begin(v), *end = around.end(v);
        if (end - fs < 2) return;
        double widest = 1, longest = 0;
        for (const std::uint32_t* a = fs; a != end; ++a) {
            for (const std::uint32_t* b = a + 1; b != end; ++b) widest = std::min(widest, surface.normal[*a].dot(surface.normal[*b]));
            for (const auto w : F[*a]) longest = std::max(longest, (V[std::size_t(w)] - V[v]).norm());
        }
        if (widest >= cos_corner || longest < 0.5 * h) return;
        FeaturePoint p;
        p.at = V[v];
        p.count = std::min(std::size_t(end - fs), FeaturePoint::kFaces);
        std::copy_n(fs, p.count, p.faces.begin());
        p.source.face = std::int32_t(fs[0]);
        p.source.barycentric = slot(fs[0], v);
        found.push_back(p);
    });
    const std::vector<Crease> creases = input_creases(surface, around);
    const auto on_creases = gather_in_order<FeaturePoint>(creases.size(), 256, [&](std::size_t c, auto& found) {
        const Crease& crease = creases[c];
        const Eigen::Vector3d a = V[std::size_t(crease.first)], b = V[std::size_t(crease.second)];
        // Half a voxel apart where the map has taken the crease (an edit may stretch it).
        const double length = steps.empty() ? (b - a).norm() : (push_forward(steps, b) - push_forward(steps, a)).norm();
        const int samples = int(std::min(1000.0, std::floor(length / (kCreaseSpacing * h))));
        for (int j = 1; j <= samples; ++j) {
            const double t = double(j) / (samples + 1);
            FeaturePoint p;
            p.at = (1 - t) * a + t * b;
            p.count = 2;
            p.faces = {crease.f, crease.g};
            p.source.face = std::int32_t(crease.f);
            p.source.barycentric = (1 - t) * slot(crease.f, std::size_t(crease.first)) + t * slot(crease.f, std::size_t(crease.second));
            found.push_back(p);
        }
    });
    points.insert(points.end(), on_creases.begin(), on_creases.end());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 1024), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) points[i].image = push_forward(steps, points[i].at);
    });
    return points;
}

/// The output's triangles around each vertex, and filed by the cell (of side `cell`) of their middles, kept up to
/// date as insert_points changes them: built once; after each pass the triangles it replaced or added are filed
/// apart (a few thousand against the output's hundreds of thousands), so that a later pass costs what its points do.
class OutputIndex {
public:
    OutputIndex(const TriangleMesh& output, double cell)
        : base_(output.vertices.size(), [&](auto visit) {
              for (std::size_t f = 0; f < output.triangles.size(); ++f)
                  for (auto v : output.triangles[f]) visit(std::size_t(v), std::uint32_t(f));
          }),
          cell_(cell), base_count_(output.vertices.size()), patch_(output.vertices.size(), -1), stale_(output.triangles.size(), 0) {
        const auto& P = output.vertices;
        const auto& T = output.triangles;
        origin_ = P.empty() ? Eigen::Vector3d::Zero() : P[0];
        Eigen::Vector3d top_corner = origin_;
        for (const auto& p : P) origin_ = origin_.cwiseMin(p), top_corner = top_corner.cwiseMax(p);
        // Floats hold a middle to about 1e-7 of its distance from the origin (new vertices lie a little beyond).
        slack_ = 1e-6 * (top_corner - origin_).norm() + 1e-9 * cell_;
        // Cells of middles start at 0 (origin_ is the least corner); rows run along x, one per (y, z). The items
        // are counted into their rows, then each row sorted: no key per item, and no sort of the whole (a fifth
        // of the index's memory, and a quarter of its time).
        // Middles lie in the vertices' box: its top corner's cell, and one more for rounding, bounds the rows.
        const std::uint64_t top = key(top_corner);
        const std::size_t F = T.size();
        rows_y_ = std::min(std::int64_t(top >> 21 & kMask) + 1, std::int64_t(kMask)) + 1;
        rows_z_ = std::min(std::int64_t(top >> 42) + 1, std::int64_t(kMask)) + 1;
        row_start_.assign(std::size_t(rows_y_ * rows_z_ + 1), 0);
        for (std::size_t f = 0; f < F; ++f) ++row_start_[std::size_t(row_of(key(middle(output, f)))) + 1];
        for (std::size_t r = 1; r < row_start_.size(); ++r) row_start_[r] += row_start_[r - 1];
        // Not zeroed first: each item is written once, by the threads that file them (a serial fill of the 10 MB at
        // 256 cost more than the filing itself, on this VM's fresh pages).
        items_ = std::make_unique_for_overwrite<Item[]>(F);
        std::vector<std::atomic<std::uint32_t>> next(row_start_.size() - 1);
        for (std::size_t r = 0; r + 1 < row_start_.size(); ++r) next[r].store(row_start_[r], std::memory_order_relaxed);
        radius_ = tbb::parallel_reduce(
            tbb::blocked_range<std::size_t>(0, F, 4096), 0.0,
            [&](const auto& r, double widest) {
                for (std::size_t f = r.begin(); f != r.end(); ++f) {
                    const auto [k, i] = filed(output, f);
                    items_[next[std::size_t(row_of(k))].fetch_add(1, std::memory_order_relaxed)] = i;
                    widest = std::max(widest, double(i.r));
                }
                return widest;
            },
            [](double a, double b) { return std::max(a, b); });
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, row_start_.size() - 1, 64), [&](const auto& r) {
            for (std::size_t row = r.begin(); row != r.end(); ++row) std::sort(items_.get() + row_start_[row], items_.get() + row_start_[row + 1]);
        });
    }

    /// Calls visit(f) for every triangle f that may meet the box [lo, hi] (those whose cells, grown by the widest
    /// triangle's radius, meet it), and some others.
    template <class Visit>
    void near(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Visit& visit) const {
        const Eigen::Vector3d grow = Eigen::Vector3d::Constant(radius_);
        const auto first = clamped_cell(lo - grow), last = clamped_cell(hi + grow);
        for (std::int64_t z = first[2]; z <= last[2]; ++z)
            for (std::int64_t y = first[1]; y <= last[1]; ++y) row(y, z, first[0], last[0], [&](const Item& i) { visit(i.f); });
        for (const Filed& w : wide_)
            if (ball_meets(w.second, lo, hi)) visit(w.second.f);
    }

    /// Calls visit(f) for every triangle f whose ball as filed (its middle, out to its farthest corner) meets the
    /// box [lo, hi], without reading a corner.
    template <class Visit>
    void meeting(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Visit& visit) const {
        const Eigen::Vector3d grow = Eigen::Vector3d::Constant(radius_);
        const auto first = clamped_cell(lo - grow), last = clamped_cell(hi + grow);
        for (std::int64_t z = first[2]; z <= last[2]; ++z)
            for (std::int64_t y = first[1]; y <= last[1]; ++y)
                row(y, z, first[0], last[0], [&](const Item& i) {
                    if (ball_meets(i, lo, hi)) visit(i.f);
                });
        for (const Filed& w : wide_)
            if (ball_meets(w.second, lo, hi)) visit(w.second.f);
    }

    /// Calls visit(f) for every triangle f that may lie within `bound` of p, and some others. visit may lower
    /// `bound` (the nearest found so far): rows, cells and triangles beyond it are then passed over.
    template <class Visit>
    void within(const Eigen::Vector3d& p, const double& bound, const Visit& visit) const {
        auto reach = [&] { return bound + radius_ + 1e-9 * cell_; };
        const Eigen::Vector3d grow = Eigen::Vector3d::Constant(reach());
        const auto first = clamped_cell(p - grow), last = clamped_cell(p + grow);
        for (std::int64_t z = first[2]; z <= last[2]; ++z) {
            const double dz = gap(p, 2, z);
            for (std::int64_t y = first[1]; y <= last[1]; ++y) {
                const double dy = gap(p, 1, y), r = reach(), left = r * r - dy * dy - dz * dz;
                if (left < 0) continue;
                const double dx = std::sqrt(left);
                const std::int64_t x0 = std::max<std::int64_t>(0, cell_of(p - Eigen::Vector3d(dx, 0, 0))[0]);
                const std::int64_t x1 = std::max<std::int64_t>(0, cell_of(p + Eigen::Vector3d(dx, 0, 0))[0]);
                row(y, z, x0, x1, [&](const Item& i) {
                    if (ball_within(i, p, bound)) visit(i.f);
                });
            }
        }
        for (const Filed& w : wide_)
            if (ball_within(w.second, p, bound)) visit(w.second.f);
    }

    /// Calls visit(f) for the triangles whose middles lie in the cells x0 .. x1 of the row (y, z) of point p's cell.
    template <class Visit>
    void row_of_point(const Eigen::Vector3d& p, std::int64_t reach, const Visit& visit) const {
        const auto c = cell_of(p);
        row(c[1], c[2], c[0] - reach, c[0] + reach, [&](const Item& i) { visit(i.f); }, true);
    }

    /// The triangles around vertex v.
    std::pair<const std::uint32_t*, const std::uint32_t*> ring(std::size_t v) const {
        if (v >= patch_.size() || (patch_[v] < 0 && v >= base_count_)) return {nullptr, nullptr}; // added since the last update
        if (patch_[v] >= 0) {
            const auto& list = patches_[std::size_t(patch_[v])];
            return {list.data(), list.data() + list.size()};
        }
        return {base_.begin(v), base_.end(v)};
    }

    /// After triangles `changed` were replaced or added (and vertices added): their rings and cells.
    void update(const TriangleMesh& output, const std::vector<std::uint32_t>& changed) {
        const auto& T = output.triangles;
        patch_.resize(output.vertices.size(), -1);
        stale_.resize(T.size(), 0);
        std::vector<std::pair<std::int32_t, std::uint32_t>> corners; // (vertex, changed triangle), by vertex
        for (const std::uint32_t f : changed) {
            stale_[f] = 1;
            for (const std::int32_t v : T[f]) corners.push_back({v, f});
        }
        std::sort(corners.begin(), corners.end());
        std::vector<std::uint32_t> sorted(changed);
        std::sort(sorted.begin(), sorted.end());
        sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
        // Each vertex's new ring from its old one, in parallel (a ring reads only its own), then filed in order.
        std::vector<std::size_t> runs; // where each vertex's run of corners begins
        for (std::size_t i = 0; i < corners.size(); ++i)
            if (i == 0 || corners[i].first != corners[i - 1].first) runs.push_back(i);
        runs.push_back(corners.size());
        std::vector<std::vector<std::uint32_t>> lists(runs.size() - 1);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, lists.size(), 256), [&](const auto& r) {
            for (std::size_t k = r.begin(); k != r.end(); ++k) {
                const std::int32_t v = corners[runs[k]].first;
                const auto [b, e] = ring(std::size_t(v));
                std::vector<std::uint32_t>& list = lists[k];
                for (const std::uint32_t* q = b; q != e; ++q) // triangles that still hold v, and are not among the changed
                    if (!std::binary_search(sorted.begin(), sorted.end(), *q) && std::find(T[*q].begin(), T[*q].end(), v) != T[*q].end()) list.push_back(*q);
                for (std::size_t i = runs[k]; i < runs[k + 1]; ++i) list.push_back(corners[i].second);
            }
        });
        for (std::size_t k = 0; k < lists.size(); ++k) {
            const auto v = std::size_t(corners[runs[k]].first);
            if (patch_[v] < 0) patch_[v] = std::int32_t(patches_.size()), patches_.emplace_back();
            patches_[std::size_t(patch_[v])] = std::move(lists[k]);
        }
        // Only the changed triangles are filed anew: their old entries out, theirs merged in (refiling every moved
        // triangle each time cost step 8 a few milliseconds a pass at 256).
        auto before = [](const Filed& a, const Filed& b) { return a.first < b.first || (a.first == b.first && a.second.f < b.second.f); };
        auto changed_one = [&](const Filed& i) { return std::binary_search(sorted.begin(), sorted.end(), i.second.f); };
        extra_.erase(std::remove_if(extra_.begin(), extra_.end(), changed_one), extra_.end());
        wide_.erase(std::remove_if(wide_.begin(), wide_.end(), changed_one), wide_.end());
        const std::size_t kept = extra_.size();
        for (const std::uint32_t f : sorted) {
            Filed i = filed(output, f);
            if (double(i.second.r) > radius_) wide_.push_back(i);
            else extra_.push_back(i);
        }
        std::sort(extra_.begin() + std::ptrdiff_t(kept), extra_.end(), before);
        std::inplace_merge(extra_.begin(), extra_.begin() + std::ptrdiff_t(kept), extra_.end(), before);
    }

private:
    /// A triangle filed in its row: its cell along the row, and the ball around it (for the nearest-triangle search).
    struct Item {
        std::uint32_t cx;
        std::uint32_t f;
        float x, y, z, r; ///< its middle (from origin_) and the distance to its farthest corner (rounded up)
        bool operator<(const Item& o) const { return cx < o.cx || (cx == o.cx && f < o.f); }
    };
    using Filed = std::pair<std::uint64_t, Item>; ///< an item and its cell's key
    Filed filed(const TriangleMesh& output, std::size_t f) const {
        const Eigen::Vector3d m = middle(output, f), from = m - origin_;
        double r = 0;
        for (const std::int32_t v : output.triangles[f]) r = std::max(r, (output.vertices[std::size_t(v)] - m).norm());
        const std::uint64_t k = key(m);
        return {k, {std::uint32_t(k & kMask), std::uint32_t(f), float(from.x()), float(from.y()), float(from.z()), std::nextafter(float(r), std::numeric_limits<float>::infinity())}};
    }
    static constexpr std::uint64_t kMask = (1u << 21) - 1;

    static Eigen::Vector3d middle(const TriangleMesh& output, std::size_t f) {
        const auto& t = output.triangles[f];
        return (output.vertices[std::size_t(t[0])] + output.vertices[std::size_t(t[1])] + output.vertices[std::size_t(t[2])]) / 3;
    }
    /// The cell of p, as filed: below the origin counts as cell 0 (where a new middle there is filed).
    std::array<std::int64_t, 3> clamped_cell(const Eigen::Vector3d& p) const {
        auto c = cell_of(p);
        for (auto& i : c) i = std::max<std::int64_t>(i, 0);
        return c;
    }
    /// How far p lies from the slab of cells c along `axis` (cell 0 reaching down without end, as filed).
    double gap(const Eigen::Vector3d& p, int axis, std::int64_t c) const {
        const double lo = origin_[axis] + double(c) * cell_, hi = lo + cell_;
        return std::max({0.0, c > 0 ? lo - p[axis] : 0.0, p[axis] - hi});
    }
    std::array<std::int64_t, 3> cell_of(const Eigen::Vector3d& p) const {
        const Eigen::Vector3d q = (p - origin_) / cell_;
        return {std::int64_t(std::floor(q.x())), std::int64_t(std::floor(q.y())), std::int64_t(std::floor(q.z()))};
    }
    static std::uint64_t key(std::int64_t x, std::int64_t y, std::int64_t z) { // 21 bits an axis, z-major
        auto bits = [](std::int64_t v) { return std::uint64_t(std::clamp<std::int64_t>(v, 0, std::int64_t(kMask))); };
        return bits(z) << 42 | bits(y) << 21 | bits(x);
    }
    std::uint64_t key(const Eigen::Vector3d& p) const {
        const auto c = cell_of(p);
        return key(c[0], c[1], c[2]);
    }
    std::int64_t row_of(std::uint64_t k) const { return std::int64_t(k >> 42) * rows_y_ + std::int64_t(k >> 21 & kMask); }

    /// Whether item i's ball (the triangle lies within i.r of its middle) comes within `bound` of p.
    bool ball_within(const Item& i, const Eigen::Vector3d& p, double bound) const {
        return (origin_ + Eigen::Vector3d(i.x, i.y, i.z) - p).norm() <= bound + double(i.r) + slack_;
    }
    /// Whether item i's ball meets the box [lo, hi].
    bool ball_meets(const Item& i, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
        const Eigen::Vector3d m = origin_ + Eigen::Vector3d(i.x, i.y, i.z);
        const double reach = double(i.r) + slack_;
        return (m.cwiseMax(lo).cwiseMin(hi) - m).squaredNorm() <= reach * reach;
    }

    /// Calls visit(i) for the items filed in row (y, z) whose middles lie in cells x0 .. x1, and with `wide`, the
    /// wide triangles' as well (the other queries look at those by their balls).
    template <class Visit>
    void row(std::int64_t y, std::int64_t z, std::int64_t x0, std::int64_t x1, const Visit& visit, bool wide = false) const {
        if (y < 0 || z < 0 || x1 < 0 || y > std::int64_t(kMask) || z > std::int64_t(kMask)) return; // (new middles may lie below the origin: clamped to 0 like the queries)
        const std::uint64_t from = key(x0, y, z), to = key(x1, y, z);
        if (y < rows_y_ && z < rows_z_) {
            const std::int64_t r = z * rows_y_ + y;
            const Item* b = items_.get() + row_start_[std::size_t(r)];
            const Item* e = items_.get() + row_start_[std::size_t(r) + 1];
            const std::uint32_t cx0 = std::uint32_t(from & kMask), cx1 = std::uint32_t(to & kMask);
            for (const Item* it = std::lower_bound(b, e, cx0, [](const Item& i, std::uint32_t c) { return i.cx < c; }); it != e && it->cx <= cx1; ++it)
                if (!stale_[it->f]) visit(*it);
        }
        for (auto it = std::lower_bound(extra_.begin(), extra_.end(), from, [](const Filed& i, std::uint64_t k) { return i.first < k; });
             it != extra_.end() && it->first <= to; ++it)
            visit(it->second);
        if (wide)
            for (const Filed& w : wide_)
                if (w.first >= from && w.first <= to) visit(w.second);
    }

    Adjacency base_;
    double cell_;
    /// The largest distance from a triangle's middle to a corner, of the triangles filed in rows (as built): the
    /// queries look that far around a box. Triangles that come wider out of an update (split, or a crease joined
    /// across a few cells: up to 6.5 cells against 1.3 on the bunny ear edit at 256) are kept in wide_ and tested
    /// one by one rather than making every later query read up to ten times the rows: 3,901 of them at most there,
    /// 1,140 on the scan at 128, and still cheaper (the scan's snapping 3 % faster; letting the radius grow to
    /// three times and keeping only wider ones apart made its flips 14 % slower, the bunny's 7 % faster).
    double radius_ = 0;
    std::size_t base_count_; ///< vertices in base_
    Eigen::Vector3d origin_;
    std::unique_ptr<Item[]> items_; ///< row by row (row_start_), each row sorted
    std::vector<Filed> extra_; ///< the moved triangles' present cells, sorted by key
    std::vector<Filed> wide_;  ///< the moved triangles wider than radius_
    double slack_ = 0;                      ///< what floats round away from a ball
    std::vector<std::uint32_t> row_start_;
    std::int64_t rows_y_ = 0, rows_z_ = 0;
    std::vector<std::int32_t> patch_;                ///< per vertex: its ring in patches_, or -1 (base_)
    std::vector<std::vector<std::uint32_t>> patches_;
    std::vector<char> stale_;                         ///< per triangle: filed in extra_, not items_
};

/// Up to N items in place (a split's triangles and pieces: no allocation per point).
template <class Item, std::size_t N>
struct Few {
    std::array<Item, N> items{};
    std::size_t count = 0;
    Few() = default;
    Few(std::initializer_list<Item> list) : count(list.size()) { std::copy(list.begin(), list.end(), items.begin()); }
    std::size_t size() const { return count; }
    bool empty() const { return count == 0; }
    void push_back(const Item& item) { items[count++] = item; }
    Item* begin() { return items.data(); }
    Item* end() { return items.data() + count; }
    const Item* begin() const { return items.data(); }
    const Item* end() const { return items.data() + count; }
    const Item& operator[](std::size_t i) const { return items[i]; }
};

/// Boxes filed by the cells (of side `cell`, world units) they overlap, to find those that meet a box. The cells
/// are hashed into a fixed table of lists: cells sharing a slot only cost a box test.
class BoxGrid {
public:
    explicit BoxGrid(double cell) : cell_(cell), head_(kSlots, -1) {}
    void clear() {
        for (const auto& e : entries_) head_[e.slot] = -1;
        boxes_.clear(), seen_.clear(), entries_.clear();
    }
    /// Files box b = the number of boxes added before it.
    void add(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
        const std::uint32_t b = std::uint32_t(boxes_.size());
        boxes_.push_back({lo, hi}), seen_.push_back(0);
        each_slot(lo, hi, [&](std::uint32_t slot) {
            entries_.push_back({b, slot, head_[slot]});
            head_[slot] = std::int32_t(entries_.size() - 1);
        });
    }
    /// Whether test(b) holds for some box b that meets [lo, hi]; each is tested once at most.
    template <class Test>
    bool any_meeting(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Test& test) {
        ++query_;
        bool hit = false;
        each_slot(lo, hi, [&](std::uint32_t slot) {
            for (std::int32_t e = head_[slot]; e >= 0 && !hit; e = entries_[std::size_t(e)].next) {
                const std::uint32_t b = entries_[std::size_t(e)].box;
                if (seen_[b] == query_) continue;
                seen_[b] = query_;
                const auto& [blo, bhi] = boxes_[b];
                hit = (lo.array() <= bhi.array()).all() && (blo.array() <= hi.array()).all() && test(std::size_t(b));
            }
        });
        return hit;
    }

private:
    static constexpr std::uint32_t kSlots = 1u << 17;
    template <class Visit>
    void each_slot(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Visit& visit) const {
        const Eigen::Array3d a = (lo / cell_).array().floor(), b = (hi / cell_).array().floor();
        for (double z = a.z(); z <= b.z(); ++z)
            for (double y = a.y(); y <= b.y(); ++y)
                for (double x = a.x(); x <= b.x(); ++x)
                    visit(std::uint32_t((std::uint64_t(std::int64_t(x)) * 73856093u ^ std::uint64_t(std::int64_t(y)) * 19349663u ^
                                         std::uint64_t(std::int64_t(z)) * 83492791u) &
                                        (kSlots - 1)));
    }
    struct Entry {
        std::uint32_t box, slot;
        std::int32_t next; ///< the slot's next entry, or -1
    };
    double cell_;
    std::vector<std::int32_t> head_; ///< per slot: its last entry, or -1
    std::vector<Entry> entries_;
    std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> boxes_;
    std::vector<std::uint64_t> seen_; ///< per box: the last query that tested it
    std::uint64_t query_ = 0;
};

/// The input's corners and crease points (feature_points) put into the output. Where creases meet at a tip, the
/// output's vertices lie on the exact surface around it, but its triangles cut under the tip: the bunny's ear edit
/// at 128 missed one of the coarse input's corners by 1.09 voxels, with every output vertex near it snapped.
/// Splitting edges on the creases (refine_with) reaches points of the creases, not where they meet, and not where
/// the split would move more than half a voxel. So each point whose exact image lies more than `chord` (and at
/// most `reach`) from the output goes in: it splits the nearest output triangle into three,
/// or, where it lies over one of that triangle's sides, the side (both its triangles into two). Not where a piece
/// would turn over against its triangle, look away from every face at the point (pushed forward), fold back onto a
/// neighbour, or cross the output (the triangles `index` files near the pieces). Points whose pieces would lie near
/// another's are tested against those too; in order of `points`, so the answer does not depend on the thread count.
/// Returns the vertices added; `settled` marks the points put in, and those the output passes within `chord` of or
/// has nothing within `reach` of (not looked at again).
std::size_t insert_points(TriangleMesh& output, std::vector<SourcePoint>& sources, const SourceSurface::Impl& surface, const std::vector<WarpStep>& steps,
                          const std::vector<FeaturePoint>& points, std::vector<char>& settled, double chord, double reach, OutputIndex& index,
                          std::vector<Eigen::Vector3d>* home) {
    std::vector<Eigen::Vector3d>& P = output.vertices;
    auto& T = output.triangles;
    const std::size_t ni = points.size();
    auto near_triangles = [&](const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, std::vector<std::uint32_t>& out) {
        out.clear();
        index.near(lo, hi, [&](std::uint32_t f) { out.push_back(f); });
    };
    auto face_normal = [&](const std::array<std::int32_t, 3>& u) {
        return Eigen::Vector3d((P[std::size_t(u[1])] - P[std::size_t(u[0])]).cross(P[std::size_t(u[2])] - P[std::size_t(u[0])]));
    };
    // The triangle other than `f` with side (a, b), or -1.
    auto across = [&](std::uint32_t f, std::int32_t a, std::int32_t b) -> std::int64_t {
        const auto [b0, e0] = index.ring(std::size_t(a));
        for (const std::uint32_t* q = b0; q != e0; ++q)
            if (*q != f && std::find(T[*q].begin(), T[*q].end(), b) != T[*q].end()) return *q;
        return -1;
    };
    constexpr std::int32_t kNew = -1; // the point's new vertex, in a piece
    struct Insert {
        Few<std::uint32_t, 2> triangles;               // those it replaces (one, or the two of a side)
        Few<std::array<std::int32_t, 3>, 4> pieces;    // two or three per triangle, in order
        Eigen::Vector3d at;
        Eigen::Vector3d home = Eigen::Vector3d::Zero(); ///< on the triangle (or side) it splits, as `home` has its corners
        SourcePoint source;
    };
    // The split each waiting point proposes (its nearest triangle's), from the output as the pass found it.
    auto propose = [&](std::size_t v) -> std::optional<Insert> {
        const FeaturePoint& point = points[v];
        const Eigen::Vector3d& x = point.image;
        // The nearest output triangle within reach. A point the output passes within the chord of, or none
        // within reach of, is done with (putting points in near it does not move the output away from it).
        double best = std::numeric_limits<double>::infinity();
        std::uint32_t nearest = 0;
        Eigen::Vector3d weights;
        auto distance_to = [&](std::uint32_t f, Eigen::Vector3d& b) { // and the nearest point's weights, b
            const auto& t = T[f];
            b = closest_barycentric(x, P[std::size_t(t[0])], P[std::size_t(t[1])], P[std::size_t(t[2])]);
            return (b[0] * P[std::size_t(t[0])] + b[1] * P[std::size_t(t[1])] + b[2] * P[std::size_t(t[2])] - x).norm();
        };
        auto consider = [&](std::uint32_t f) {
            Eigen::Vector3d b;
            if (const double d = distance_to(f, b); d < best || (d == best && f < nearest))
                best = d, nearest = f, weights = b; // (the grid's order is not the faces')
        };
        // Most points lie on the output already: the triangles in the point's row of three cells (one search of
        // the grid) usually hold one that passes within the chord. Otherwise the nearest of those bounds the
        // search for the nearest of all.
        index.row_of_point(x, 1, consider);
        if (best <= chord) {
            settled[v] = 1;
            return std::nullopt;
        }
        double bound = std::min(best, reach);
        index.within(x, bound, [&](std::uint32_t f) {
            consider(f);
            bound = std::min(best, reach);
        });
        if (!(best > chord && best <= reach)) {
            settled[v] = 1;
            return std::nullopt;
        }
        // Triangle f split into three, or its side opposite corner k and the triangle across it into two each.
        auto split_side = [&](std::uint32_t f, int k) -> std::optional<Insert> {
            const auto& t = T[f];
            const std::int32_t a = t[std::size_t((k + 1) % 3)], b = t[std::size_t((k + 2) % 3)], c = t[std::size_t(k)];
            const std::int64_t g = across(f, a, b);
            if (g < 0) return std::nullopt;
            const auto& u = T[std::size_t(g)];
            const std::int32_t y = u[0] != a && u[0] != b ? u[0] : u[1] != a && u[1] != b ? u[1] : u[2];
            Insert in;
            in.at = x;
            in.triangles = {f, std::uint32_t(g)};
            in.pieces = {{a, kNew, c}, {kNew, b, c}, {b, kNew, y}, {kNew, a, y}};
            return in;
        };
        auto split_inside = [&](std::uint32_t f) {
            const auto& t = T[f];
            Insert in;
            in.at = x;
            in.triangles = {f};
            in.pieces = {{t[0], t[1], kNew}, {t[1], t[2], kNew}, {t[2], t[0], kNew}};
            return std::optional<Insert>(in);
        };
        // Not where a piece would turn over, look away from the point's faces, or fold back onto a neighbour.
        auto at = [&](std::int32_t i) -> const Eigen::Vector3d& { return i == kNew ? x : P[std::size_t(i)]; };
        const std::uint32_t* faces = point.faces.data();
        const std::size_t count = point.count;
        auto normal_of = [&](const std::array<std::int32_t, 3>& p) { return Eigen::Vector3d((at(p[1]) - at(p[0])).cross(at(p[2]) - at(p[0]))); };
        std::array<Eigen::Vector3d, FeaturePoint::kFaces> exact{};
        for (std::size_t a = 0; a < count; ++a) exact[a] = surface.normal[faces[a]];
        exact = push_normals<FeaturePoint::kFaces>(steps, point.at, exact);
        auto sound = [&](const Insert& in) {
            bool folds = false;
            for (std::size_t q = 0; q < in.pieces.size() && !folds; ++q) {
                const auto& p = in.pieces[q];
                const std::uint32_t own = in.triangles[q * in.triangles.size() / in.pieces.size()]; // the piece's triangle
                const Eigen::Vector3d before = face_normal(T[own]), after = normal_of(p);
                // Turned over against its triangle, or next to no area.
                folds = after.dot(before) <= 0 || after.norm() < 1e-4 * chord * chord;
                // Facing away from every face of the point, as the map carries them.
                bool along = false;
                for (std::size_t a = 0; a < count; ++a) along |= after.dot(exact[a]) > 0;
                folds |= !along;
                // Folded back onto the neighbour across an old side (a tip's sides may stand at a right angle to
                // the surface around it, and more: the ear's rim turns by 105 degrees).
                for (int k = 0; k < 3 && !folds; ++k) {
                    const std::int32_t a = p[std::size_t(k)], b = p[std::size_t((k + 1) % 3)];
                    if (a == kNew || b == kNew) continue;
                    const std::int64_t g = across(own, a, b);
                    if (g < 0 || std::find(in.triangles.begin(), in.triangles.end(), std::uint32_t(g)) != in.triangles.end()) continue;
                    folds = !(after.normalized().dot(face_normal(T[std::size_t(g)]).normalized()) > -kCornerFold);
                }
            }
            return !folds;
        };
        // The split the point lies nearest first: over a side, that side's; inside, the three; then the other
        // splits of the triangle. Where points crowd (a crease's, half a voxel apart), the nearest triangle is often
        // a sliver of a neighbour's pieces, or the point lies nearest a neighbour's vertex, beyond a ridge the
        // output cuts under: the nearest triangle's splits all turn over, while a triangle a little farther, across
        // the ridge, splits soundly (the bunny ear's top and rim: 0.54 and 0.48 voxel under the exact warp where
        // one point of a crease was refused between two put in).
        auto first_sound = [&](std::uint32_t f, const Eigen::Vector3d& w) -> std::optional<Insert> {
            int least = 0; // the corner opposite the side it lies nearest
            for (int k = 1; k < 3; ++k)
                if (w[k] < w[least]) least = k;
            const bool on_side = w[least] < kCornerSide;
            for (int attempt = 0; attempt < 4; ++attempt) { // each built only when the ones before it fold
                const bool inside = attempt == (on_side ? 1 : 0);
                const int side = attempt < 2 ? least : (least + attempt - 1) % 3;
                std::optional<Insert> in = inside ? split_inside(f) : split_side(f, side);
                if (in && sound(*in)) {
                    in->source = point.source;
                    if (home) {
                        const auto& t = T[f];
                        auto H = [&](int k) -> const Eigen::Vector3d& { return (*home)[std::size_t(t[std::size_t(k)])]; };
                        if (inside) {
                            in->home = w[0] * H(0) + w[1] * H(1) + w[2] * H(2);
                        } else { // on the side opposite corner `side`, where the point's weights put it
                            const double a = w[(side + 1) % 3], b = w[(side + 2) % 3], u = a + b > 0 ? b / (a + b) : 0.5;
                            in->home = (1 - u) * H((side + 1) % 3) + u * H((side + 2) % 3);
                        }
                    }
                    return in;
                }
            }
            return std::nullopt;
        };
        if (auto in = first_sound(nearest, weights)) return in;
        // The next nearest triangles, up to half a voxel (a third of the reach) farther than the nearest.
        struct Near {
            double distance;
            std::uint32_t f;
            Eigen::Vector3d weights;
        };
        std::vector<Near> farther;
        const double farthest = std::min(reach, best + reach / 3);
        index.within(x, farthest, [&](std::uint32_t f) {
            Eigen::Vector3d b;
            if (const double d = distance_to(f, b); f != nearest && d <= farthest) farther.push_back({d, f, b});
        });
        const std::size_t candidates = std::min(farther.size(), kFartherTriangles);
        std::partial_sort(farther.begin(), farther.begin() + std::ptrdiff_t(candidates), farther.end(),
                          [](const Near& a, const Near& b) { return a.distance < b.distance || (a.distance == b.distance && a.f < b.f); });
        for (std::size_t i = 0; i < candidates; ++i)
            if (auto in = first_sound(farther[i].f, farther[i].weights)) return in;
        return std::nullopt;
    };
    // Whether a proposed split's pieces cross the output as the pass found it: the triangles that may meet their
    // box, against the pieces' new sides, and the pieces against the triangles' sides (a test against the other
    // sheet's tangent plane would refuse a thin part's rim, whose tip lies beyond both sheets' planes).
    auto crosses_output = [&](const Insert& in, std::vector<std::uint32_t>& other) {
        const Eigen::Vector3d& x = in.at;
        auto at = [&](std::int32_t i) -> const Eigen::Vector3d& { return i == kNew ? x : P[std::size_t(i)]; };
        Eigen::Vector3d lo = x, hi = x; // the pieces' box
        for (const std::uint32_t f : in.triangles)
            for (const std::int32_t c : T[f]) lo = lo.cwiseMin(P[std::size_t(c)]), hi = hi.cwiseMax(P[std::size_t(c)]);
        near_triangles(lo, hi, other);
        bool crosses = false;
        for (const std::uint32_t f : other) {
            if (std::find(in.triangles.begin(), in.triangles.end(), f) != in.triangles.end()) continue;
            const auto& u = T[f];
            const Eigen::Vector3d &u0 = P[std::size_t(u[0])], &u1 = P[std::size_t(u[1])], &u2 = P[std::size_t(u[2])];
            if ((u0.cwiseMax(u1).cwiseMax(u2).array() < lo.array()).any() || (u0.cwiseMin(u1).cwiseMin(u2).array() > hi.array()).any()) continue;
            auto has = [&](std::int32_t i) { return std::find(u.begin(), u.end(), i) != u.end(); };
            for (const auto& p : in.pieces) {
                for (int k = 0; k < 3 && !crosses; ++k) {
                    const std::int32_t a = p[std::size_t(k)], b = p[std::size_t((k + 1) % 3)];
                    // The piece's new sides against the triangle, unless they meet at a corner.
                    if (b == kNew && !has(a)) crosses |= segment_meets(at(a), x, P[std::size_t(u[0])], P[std::size_t(u[1])], P[std::size_t(u[2])]);
                    // The triangle's sides against the piece, unless they share a corner.
                    const std::int32_t e0 = u[std::size_t(k)], e1 = u[std::size_t((k + 1) % 3)];
                    if (std::find(p.begin(), p.end(), e0) == p.end() && std::find(p.begin(), p.end(), e1) == p.end())
                        crosses |= segment_meets(P[std::size_t(e0)], P[std::size_t(e1)], at(p[0]), at(p[1]), at(p[2]));
                }
                if (crosses) break;
            }
            if (crosses) break;
        }
        return crosses;
    };
    // The proposals in the order of their points (fixed blocks, joined in order): most points propose nothing, and
    // a list of all of them would be megabytes of fresh pages each pass.
    const std::vector<Insert> found = gather_in_order<Insert>(ni, 256, [&](std::size_t v, std::vector<Insert>& out) {
        if (!settled[v])
            if (auto in = propose(v)) out.push_back(std::move(*in));
    });
    const std::size_t nf = found.size();
    // The points go in in order, each unless it is unsound, its triangles or one beside them were split already, or
    // its pieces cross those put in before it. Only the points that order reaches need the soundness test, a few
    // of those proposed where points crowd (a scan's every vertex and edge): the selection is made taking untested
    // points as sound, those it takes are tested (in parallel), and it is made again until it takes no untested
    // point; it is then the selection that tests every point first would make.
    enum : char { untested, passed, failed };
    std::vector<char> verdict(nf, untested);
    const std::size_t n0 = P.size();
    std::vector<char> taken(n0, 0); // the corners of the triangles split
    std::vector<std::size_t> selected, unknown;
    BoxGrid boxes(reach);
    std::vector<std::array<std::int32_t, 3>> put; // the pieces of the points selected, point b's put[put_from[b] ..]
    std::vector<std::size_t> put_from;
    for (;;) {
        std::fill(taken.begin(), taken.end(), 0);
        selected.clear(), unknown.clear(), put.clear(), put_from.assign(1, 0), boxes.clear();
        P.resize(n0);
        for (std::size_t v = 0; v < nf; ++v) {
            if (verdict[v] == failed) continue;
            const Insert& in = found[v];
            // A triangle already split, or one beside it (its side's split would leave the other's neighbour stale):
            // a corner of its triangles is a corner of a taken one.
            auto busy = [&] {
                for (const std::uint32_t f : in.triangles)
                    for (const std::int32_t c : T[f])
                        if (taken[std::size_t(c)]) return true;
                return false;
            };
            if (busy()) continue;
            // The pieces were tested against the output as it was: test them against those put in since.
            const auto x = std::int32_t(P.size());
            auto pieces = in.pieces;
            for (auto& piece : pieces)
                for (auto& i : piece)
                    if (i == kNew) i = x;
            P.push_back(in.at);
            Eigen::Vector3d lo = in.at, hi = in.at;
            for (const auto& piece : pieces)
                for (const std::int32_t c : piece) lo = lo.cwiseMin(P[std::size_t(c)]), hi = hi.cwiseMax(P[std::size_t(c)]);
            const bool crosses = boxes.any_meeting(lo, hi, [&](std::size_t b) {
                for (const auto& piece : pieces)
                    for (std::size_t q = put_from[b]; q < put_from[b + 1]; ++q)
                        if (triangles_cross([&](std::int32_t i) -> const Eigen::Vector3d& { return P[std::size_t(i)]; }, piece, put[q])) return true;
                return false;
            });
            if (crosses) {
                P.pop_back();
                continue;
            }
            boxes.add(lo, hi);
            put.insert(put.end(), pieces.begin(), pieces.end());
            put_from.push_back(put.size());
            for (const std::uint32_t f : in.triangles)
                for (const std::int32_t c : T[f]) taken[std::size_t(c)] = 1;
            selected.push_back(v);
            if (verdict[v] == untested) unknown.push_back(v);
        }
        if (unknown.empty()) break;
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, unknown.size(), 16), [&](const auto& r) {
            std::vector<std::uint32_t> other;
            for (std::size_t i = r.begin(); i != r.end(); ++i) verdict[unknown[i]] = crosses_output(found[unknown[i]], other) ? failed : passed;
        });
    }
    // P holds the selected points' vertices, in order; their pieces replace their triangles.
    std::vector<std::uint32_t> changed; // triangles replaced or added
    for (std::size_t b = 0; b < selected.size(); ++b) {
        const Insert& in = found[selected[b]];
        sources.push_back(in.source);
        if (home) home->push_back(in.home);
        const std::size_t per = (put_from[b + 1] - put_from[b]) / in.triangles.size();
        for (std::size_t q = 0; q < put_from[b + 1] - put_from[b]; ++q) {
            const auto& piece = put[put_from[b] + q];
            if (q % per == 0) T[in.triangles[q / per]] = piece, changed.push_back(in.triangles[q / per]);
            else changed.push_back(std::uint32_t(T.size())), T.push_back(piece);
        }
    }
    index.update(output, changed);
    return selected.size();
}

/// The box of triangle t's corners in P, and whether two boxes meet (join_creases, flip_to_normals, snap_again).
using TriangleBox = std::pair<Eigen::Vector3d, Eigen::Vector3d>;
TriangleBox box_of(const std::vector<Eigen::Vector3d>& P, const std::array<std::int32_t, 3>& t) {
    const Eigen::Vector3d &p = P[std::size_t(t[0])], &q = P[std::size_t(t[1])], &r = P[std::size_t(t[2])];
    return {p.cwiseMin(q).cwiseMin(r), p.cwiseMax(q).cwiseMax(r)};
}
bool boxes_meet(const TriangleBox& x, const TriangleBox& y) { return (x.first.array() <= y.second.array()).all() && (y.first.array() <= x.second.array()).all(); }
/// Whether t runs along its side x -> y.
bool has_side(const std::array<std::int32_t, 3>& t, std::int32_t x, std::int32_t y) {
    for (std::size_t k = 0; k < 3; ++k)
        if (t[k] == x && t[(k + 1) % 3] == y) return true;
    return false;
}
/// The normal of triangle t with corners in X, unnormalized (twice its area long).
Eigen::Vector3d triangle_normal(const std::vector<Eigen::Vector3d>& X, const std::array<std::int32_t, 3>& t) {
    return (X[std::size_t(t[1])] - X[std::size_t(t[0])]).cross(X[std::size_t(t[2])] - X[std::size_t(t[0])]);
}
/// Calls visit(key) for each cell (of side `cell`) that box b meets: the keys of a hash grid.
template <class Visit>
void each_cell_of(const TriangleBox& b, double cell, const Visit& visit) {
    const Eigen::Vector3d lo = (b.first / cell).array().floor(), hi = (b.second / cell).array().floor();
    for (double z = lo.z(); z <= hi.z(); ++z)
        for (double y = lo.y(); y <= hi.y(); ++y)
            for (double x = lo.x(); x <= hi.x(); ++x)
                visit(std::uint64_t(std::int64_t(x) & 0x1fffff) << 42 | std::uint64_t(std::int64_t(y) & 0x1fffff) << 21 | std::uint64_t(std::int64_t(z) & 0x1fffff));
}
/// Triangles changed since the index filed them (it has them where they were), filed by the cells two voxels wide
/// their boxes met when filed; a triangle changed again is filed again (join_creases, flip_to_normals, snap_again).
/// A list of them all, each tested against every query, cost the scan's flips at 128 half a second.
class ChangedCells {
public:
    explicit ChangedCells(double h) : cell_(2 * h) {}
    void file(std::uint32_t f, const TriangleBox& b) { each_cell_of(b, cell_, [&](std::uint64_t k) { cells_[k].push_back(f); }); }
    /// Calls visit(f) for each triangle filed in a cell that box b meets (some more than once).
    template <class Visit>
    void near(const TriangleBox& b, const Visit& visit) const {
        each_cell_of(b, cell_, [&](std::uint64_t k) {
            if (const auto it = cells_.find(k); it != cells_.end())
                for (const std::uint32_t f : it->second) visit(f);
        });
    }
    void clear() { cells_.clear(); }

private:
    double cell_;
    std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> cells_;
};

/// Into `near` (some more than once): the triangles that may meet box `reach`, those `index` files near it where they
/// were and those `changed` files since whose boxes now meet it (flip_to_normals, snap_again, unfold).
void gather_near(const TriangleMesh& output, const OutputIndex& index, const ChangedCells& changed, const TriangleBox& reach, std::vector<std::uint32_t>& near) {
    near.clear();
    index.meeting(reach.first, reach.second, [&](std::uint32_t q) { near.push_back(q); });
    changed.near(reach, [&](std::uint32_t q) {
        if (boxes_meet(box_of(output.vertices, output.triangles[q]), reach)) near.push_back(q);
    });
}

/// Whether a triangle of [begin, end) (those around a vertex moved, or a group's), its corners where they are now,
/// crosses one near it that is not one of them (snap_again, unfold). `near`: scratch.
bool moved_faces_cross(const TriangleMesh& output, const OutputIndex& index, const ChangedCells& changed, const std::uint32_t* begin, const std::uint32_t* end,
                       std::vector<std::uint32_t>& near) {
    const auto& P = output.vertices;
    const auto& T = output.triangles;
    TriangleBox reach = box_of(P, T[*begin]);
    for (const std::uint32_t* f = begin; f != end; ++f) {
        const TriangleBox b = box_of(P, T[*f]);
        reach.first = reach.first.cwiseMin(b.first), reach.second = reach.second.cwiseMax(b.second);
    }
    gather_near(output, index, changed, reach, near);
    auto at = [&](std::int32_t i) -> const Eigen::Vector3d& { return P[std::size_t(i)]; };
    for (const std::uint32_t* f = begin; f != end; ++f) {
        const TriangleBox b = box_of(P, T[*f]);
        for (const std::uint32_t q : near)
            if (std::find(begin, end, q) == end && boxes_meet(box_of(P, T[q]), b) && triangles_cross(at, T[*f], T[q])) return true;
    }
    return false;
}

/// The output's edges along the input's creases. Points of a crease come into the output put in (insert_points),
/// split on it (refine_with) or snapped onto a convex ridge, but two that follow each other along it are often not
/// joined by an edge: the triangles between them cross the crease and cut under it. Of the bunny ear edit's pairs
/// of crease points put in one after the other at 128, 55 of 251 were joined; joining the others took the bent and
/// twisted box's edges from p99 0.067-0.168 voxel off the exact warp to 0.041-0.059. Each pair, both on the exact
/// surface, whose segment's middle lies farther than `chord` from the triangles around its ends is joined by flipping the edges that cross the
/// segment (Sloan's edge insertion, seen along the mean of the crease's two faces' normals as the maps carry
/// them), unless the flips leave a triangle without area, turned against that mean (or, where extraction made the
/// vertices, turned over there: put_back_crossings relies on it), facing away from both faces, folded back onto a
/// neighbour, or crossing the output. No vertex moves. Returns the pairs joined.
std::size_t join_creases(TriangleMesh& output, const std::vector<SourcePoint>& sources, const SourceSurface::Impl& surface, const std::vector<WarpStep>& steps,
                         OutputIndex& index, const std::vector<Eigen::Vector3d>* home, double h, double chord) {
    const auto& F = surface.faces;
    const std::vector<Eigen::Vector3d>& P = output.vertices;
    auto& T = output.triangles;
    const double tiny = 1e-4 * h * h;
    using Key = std::uint64_t;
    auto key = [](std::int32_t a, std::int32_t b) { return Key(std::uint32_t(std::min(a, b))) << 32 | std::uint32_t(std::max(a, b)); };
    // The creases by their sides (a side twice only where the faces' orientations disagree: once).
    std::vector<Crease> creases = input_creases(surface, faces_with_area(surface));
    auto side_key = [&](const Crease& c) { return key(c.first, c.second); };
    std::stable_sort(creases.begin(), creases.end(), [&](const Crease& x, const Crease& y) { return side_key(x) < side_key(y); });
    creases.erase(std::unique(creases.begin(), creases.end(), [&](const Crease& x, const Crease& y) { return side_key(x) == side_key(y); }), creases.end());
    if (creases.empty()) return 0;
    const Adjacency at_vertex(surface.V.size(), [&](auto visit) { // input vertex -> its creases
        for (std::size_t c = 0; c < creases.size(); ++c) visit(std::size_t(creases[c].first), std::uint32_t(c)), visit(std::size_t(creases[c].second), std::uint32_t(c));
    });
    auto crease_of = [&](Key k) -> std::int64_t {
        const auto it = std::lower_bound(creases.begin(), creases.end(), k, [&](const Crease& c, Key x) { return side_key(c) < x; });
        return it != creases.end() && side_key(*it) == k ? it - creases.begin() : -1;
    };
    // The output's vertices on a crease (their sources on its side, or at one of its ends), by crease and along it.
    constexpr double kOnSide = 1e-7; // a barycentric weight this small puts a source on the side
    struct On {
        std::uint32_t crease;
        double t; ///< from the crease's lower input vertex
        std::int32_t v;
        bool operator<(const On& o) const { return crease < o.crease || (crease == o.crease && (t < o.t || (t == o.t && v < o.v))); }
    };
    std::vector<On> on;
    for (std::size_t v = 0; v < sources.size() && v < P.size(); ++v) {
        const SourcePoint& s = sources[v];
        if (s.face < 0) continue;
        const auto& t = F[std::size_t(s.face)];
        int zeros = 0, zero = 0, one = 0;
        for (int k = 0; k < 3; ++k) {
            if (s.barycentric[k] < kOnSide) ++zeros, zero = k;
            if (s.barycentric[k] > s.barycentric[one]) one = k;
        }
        if (zeros == 1) {
            const std::int32_t a = t[std::size_t((zero + 1) % 3)], b = t[std::size_t((zero + 2) % 3)];
            if (const std::int64_t c = crease_of(key(a, b)); c >= 0)
                on.push_back({std::uint32_t(c), a < b ? s.barycentric[(zero + 2) % 3] : s.barycentric[(zero + 1) % 3], std::int32_t(v)});
        } else if (zeros == 2) {
            const auto w = std::size_t(t[std::size_t(one)]);
            for (const std::uint32_t* c = at_vertex.begin(w); c != at_vertex.end(w); ++c)
                on.push_back({*c, std::size_t(creases[*c].first) == w ? 0.0 : 1.0, std::int32_t(v)});
        }
    }
    std::sort(on.begin(), on.end());

    // The rings of the vertices whose triangles the flips changed (the others: the index's), and what a pair's flips
    // changed, to undo them.
    std::vector<std::int32_t> ring_slot(P.size(), -1);
    std::vector<std::vector<std::uint32_t>> rings;
    auto ring = [&](std::int32_t v) -> std::pair<const std::uint32_t*, const std::uint32_t*> {
        if (const std::int32_t slot = ring_slot[std::size_t(v)]; slot >= 0) {
            const auto& r = rings[std::size_t(slot)];
            return {r.data(), r.data() + r.size()};
        }
        return index.ring(std::size_t(v));
    };
    std::vector<std::pair<std::uint32_t, std::array<std::int32_t, 3>>> undo_triangles;
    std::vector<std::pair<std::int32_t, std::vector<std::uint32_t>>> undo_rings; // (vertex, its ring before)
    auto own_ring = [&](std::int32_t v) -> std::vector<std::uint32_t>& {
        std::int32_t& slot = ring_slot[std::size_t(v)];
        if (slot < 0) {
            const auto [b, e] = index.ring(std::size_t(v));
            slot = std::int32_t(rings.size());
            rings.emplace_back(b, e);
            undo_rings.push_back({v, rings.back()});
        } else if (std::none_of(undo_rings.begin(), undo_rings.end(), [&](const auto& u) { return u.first == v; })) {
            undo_rings.push_back({v, rings[std::size_t(slot)]});
        }
        return rings[std::size_t(slot)];
    };
    auto undo = [&] {
        for (auto it = undo_triangles.rbegin(); it != undo_triangles.rend(); ++it) T[it->first] = it->second;
        for (auto& [v, before] : undo_rings) rings[std::size_t(ring_slot[std::size_t(v)])] = std::move(before);
        return false;
    };
    auto has = [](const std::array<std::int32_t, 3>& t, std::int32_t v) { return std::find(t.begin(), t.end(), v) != t.end(); };
    auto joined = [&](std::int32_t a, std::int32_t b) {
        const auto [begin, end] = ring(a);
        return std::any_of(begin, end, [&](std::uint32_t f) { return has(T[f], b); });
    };
    // The triangle with side x -> y (f), and its third corner (-1: none).
    auto with_side = [&](std::int32_t x, std::int32_t y, std::uint32_t& f) -> std::int32_t {
        const auto [begin, end] = ring(x);
        for (const std::uint32_t* g = begin; g != end; ++g)
            for (int k = 0; k < 3; ++k)
                if (T[*g][std::size_t(k)] == x && T[*g][std::size_t((k + 1) % 3)] == y) return f = *g, T[*g][std::size_t((k + 2) % 3)];
        return -1;
    };
    auto normal_of = [](const std::array<std::int32_t, 3>& t, const std::vector<Eigen::Vector3d>& X) { return triangle_normal(X, t); };
    using Box = TriangleBox;
    auto box_of = [&](const std::array<std::int32_t, 3>& t) { return voxwarp::box_of(P, t); };
    auto meet = boxes_meet;
    auto at = [&](std::int32_t v) -> const Eigen::Vector3d& { return P[std::size_t(v)]; };
    // Whether s lies on one side of t's plane (normal n), but for the corners it shares with t: then they do not cross.
    auto apart = [&](const std::array<std::int32_t, 3>& s, const std::array<std::int32_t, 3>& t, const Eigen::Vector3d& n) {
        int above = 0, below = 0, own = 0;
        for (const std::int32_t c : s) {
            if (has(t, c)) continue;
            ++own;
            const double d = n.dot(P[std::size_t(c)] - P[std::size_t(t[0])]);
            above += d > 0, below += d < 0;
        }
        return own > 0 && (above == own || below == own);
    };
    // The triangles flipped so far (the index has them where they were).
    ChangedCells flipped_in(h);
    std::vector<std::uint32_t> flips;
    std::vector<std::pair<std::uint32_t, Box>> near;                  // the triangles a join's may cross, and their boxes
    std::vector<std::pair<std::int32_t, std::int32_t>> crossed;       // (kept from join to join: no allocation per join)
    std::deque<std::pair<std::int32_t, std::int32_t>> queue;
    std::vector<std::uint32_t> changed;

    // Joins a to b, seen along N; false (nothing changed) where it cannot soundly.
    auto join = [&](std::int32_t a, std::int32_t b, const Eigen::Vector3d& N, const std::array<Eigen::Vector3d, 2>& exact) {
        const Eigen::Vector3d u = N.unitOrthogonal(), w = N.cross(u);
        auto orient = [&](std::int32_t p, std::int32_t q, std::int32_t r) {
            const Eigen::Vector3d d1 = P[std::size_t(q)] - P[std::size_t(p)], d2 = P[std::size_t(r)] - P[std::size_t(p)];
            return d1.dot(u) * d2.dot(w) - d1.dot(w) * d2.dot(u);
        };
        // The sides the segment a-b crosses, x on its right and y on its left: from the one triangle around a
        // (facing along N) whose corner at a holds the direction to b, across to b.
        crossed.clear();
        {
            const auto [begin, end] = ring(a);
            for (const std::uint32_t* f = begin; f != end; ++f) {
                const auto& t = T[*f];
                int k = 0;
                while (t[std::size_t(k)] != a) ++k;
                const std::int32_t x = t[std::size_t((k + 1) % 3)], y = t[std::size_t((k + 2) % 3)];
                if (orient(a, x, y) > 0 && orient(a, x, b) > 0 && orient(a, b, y) > 0) crossed.push_back({x, y});
            }
        }
        if (crossed.size() != 1) return false;
        for (;;) {
            if (crossed.size() > kJoinCrossings) return false;
            const auto [x, y] = crossed.back();
            std::uint32_t g;
            const std::int32_t z = with_side(y, x, g);
            if (z < 0) return false;
            if (z == b) break;
            const double s = orient(a, b, z);
            if (s == 0) return false;
            crossed.push_back(s < 0 ? std::pair{z, y} : std::pair{x, z});
        }
        // Flip each crossed side whose two triangles make a convex quad as seen, until none crosses the segment.
        undo_triangles.clear(), undo_rings.clear();
        queue.assign(crossed.begin(), crossed.end());
        changed.clear();
        for (std::size_t tries = 0; !queue.empty() && tries < 16 * crossed.size(); ++tries) {
            const auto [x, y] = queue.front();
            queue.pop_front();
            std::uint32_t f1 = 0, f2 = 0;
            const std::int32_t p = with_side(x, y, f1), q = with_side(y, x, f2);
            if (p < 0 || q < 0) break;
            if (!(orient(p, q, x) * orient(p, q, y) < 0 && orient(x, y, p) * orient(x, y, q) < 0) || joined(p, q)) {
                queue.push_back({x, y});
                continue;
            }
            auto drop = [&](std::int32_t v, std::uint32_t f) {
                auto& r = own_ring(v);
                r.erase(std::remove(r.begin(), r.end(), f), r.end());
            };
            drop(x, f2), drop(y, f1), own_ring(p).push_back(f2), own_ring(q).push_back(f1);
            undo_triangles.push_back({f1, T[f1]}), undo_triangles.push_back({f2, T[f2]});
            T[f1] = {x, q, p}, T[f2] = {q, y, p};
            changed.push_back(f1), changed.push_back(f2);
            if (p != a && p != b && q != a && q != b && orient(a, b, p) * orient(a, b, q) < 0 && orient(p, q, a) * orient(p, q, b) < 0) queue.push_back({p, q});
        }
        if (!queue.empty() || !joined(a, b)) return undo();
        std::sort(changed.begin(), changed.end());
        changed.erase(std::unique(changed.begin(), changed.end()), changed.end());
        // In 3D: area, facing, at home too, and folds with the neighbours.
        Box reach = box_of(T[changed[0]]);
        for (const std::uint32_t f : changed) {
            const auto& t = T[f];
            const Eigen::Vector3d n = normal_of(t, P);
            if (!(n.norm() > tiny && n.dot(N) > 0 && (n.dot(exact[0]) > 0 || n.dot(exact[1]) > 0))) return undo();
            if (home && !(normal_of(t, *home).dot(N) > 0)) return undo();
            for (int k = 0; k < 3; ++k) {
                std::uint32_t g;
                if (with_side(t[std::size_t((k + 1) % 3)], t[std::size_t(k)], g) < 0) return undo();
                if (!(n.normalized().dot(normal_of(T[g], P).normalized()) > -kCornerFold)) return undo();
            }
            const Box b = box_of(t);
            reach.first = reach.first.cwiseMin(b.first), reach.second = reach.second.cwiseMax(b.second);
        }
        // Crossings, against the triangles filed near and those flipped near.
        near.clear();
        auto consider = [&](std::uint32_t g) {
            if (const Box b = box_of(T[g]); meet(b, reach)) near.push_back({g, b});
        };
        index.meeting(reach.first, reach.second, consider);
        flipped_in.near(reach, consider);
        for (const std::uint32_t f : changed) {
            const Box b = box_of(T[f]);
            const Eigen::Vector3d n = normal_of(T[f], P);
            for (const auto& [g, gb] : near)
                if (g != f && meet(gb, b) && !apart(T[g], T[f], n) && triangles_cross(at, T[f], T[g])) return undo();
        }
        for (const std::uint32_t f : changed) flipped_in.file(f, box_of(T[f])), flips.push_back(f);
        return true;
    };

    // The pairs to join: not joined yet, and their segment's middle farther than the chord from the triangles
    // around them (where the crease is cut under), with the normals of the crease's faces there as the maps carry
    // them. Joined in the order of their middles' cells along a Morton curve, each reading much of what the one
    // before read (at 256, a fifth faster than in the creases' order).
    struct Pair {
        std::uint64_t order;
        std::int32_t a, b;
        std::array<Eigen::Vector3d, 2> exact;
    };
    std::vector<Pair> pairs = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, on.size() > 0 ? on.size() - 1 : 0, 1024), std::vector<Pair>(),
        [&](const auto& r, std::vector<Pair> found) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                if (on[i].crease != on[i + 1].crease) continue;
                const std::int32_t a = on[i].v, b = on[i + 1].v;
                if ((P[std::size_t(a)] - P[std::size_t(b)]).norm() < 1e-3 * h || joined(a, b)) continue; // (one point: fans' centres at a corner)
                const Eigen::Vector3d m = 0.5 * (P[std::size_t(a)] + P[std::size_t(b)]);
                double nearest = std::numeric_limits<double>::infinity();
                for (const std::int32_t v : {a, b}) {
                    const auto [begin, end] = ring(v);
                    for (const std::uint32_t* f = begin; f != end; ++f) {
                        const auto& t = T[*f];
                        nearest = std::min(nearest, (internal::closest_on_triangle(m, P[std::size_t(t[0])], P[std::size_t(t[1])], P[std::size_t(t[2])]) - m).norm());
                    }
                }
                if (nearest <= chord) continue;
                // Both on the exact surface: a vertex left where extraction made it (or moved part of the way) keeps
                // its source, but does not lie on the crease.
                auto on_image = [&](std::int32_t v) { return (push_forward(steps, surface.position(sources[std::size_t(v)])) - P[std::size_t(v)]).norm() <= 1e-6 * h; };
                if (!on_image(a) || !on_image(b)) continue;
                const Crease& crease = creases[std::size_t(on[i].crease)];
                const Eigen::Vector3d lo = surface.V[std::size_t(crease.first)], hi = surface.V[std::size_t(crease.second)];
                const auto exact = push_normals<2>(steps, lo + 0.5 * (on[i].t + on[i + 1].t) * (hi - lo), {surface.normal[crease.f], surface.normal[crease.g]});
                const Eigen::Vector3d c = (m / (4 * h)).array().floor();
                std::uint64_t order = 0;
                for (int bit = 20; bit >= 0; --bit)
                    for (int axis = 2; axis >= 0; --axis) order = order << 1 | (std::uint64_t(std::int64_t(c[axis]) & 0x1fffff) >> bit & 1);
                found.push_back({order, a, b, exact});
            }
            return found;
        },
        concat<Pair>);
    std::stable_sort(pairs.begin(), pairs.end(), [](const Pair& x, const Pair& y) { return x.order < y.order; });
    std::size_t count = 0;
    for (const Pair& pair : pairs) {
        const Eigen::Vector3d N = (pair.exact[0].normalized() + pair.exact[1].normalized()).normalized();
        if (!N.allFinite() || joined(pair.a, pair.b)) continue;
        if (join(pair.a, pair.b, N, pair.exact) || join(pair.b, pair.a, N, pair.exact)) ++count;
    }
    // The index, up to date for step 8: the triangles flipped here.
    std::sort(flips.begin(), flips.end());
    flips.erase(std::unique(flips.begin(), flips.end()), flips.end());
    if (!flips.empty()) index.update(output, flips);
    return count;
}

/// Step 8 tries to flip a triangle whose corners' normals, one less the cosine of each's angle to the exact normal
/// there, add up to more than this (three corners 33 degrees off, or one 66).
constexpr double kOffNormals = 0.6;
/// Rounds of steps 7b and 8 (snap_again, flip_to_normals) at most.
constexpr int kAgainRounds = 3;

/// The triangles that meet a neighbour across a side at more than kSteep (a fold, one across a crease, or on
/// either side of one), sorted: where step 8 looks first, and where step 9 looks for folds (of those, the ones
/// still there after steps 7b and 8, which move and flip only around these or refuse a fold).
std::vector<std::uint32_t> steep_sides(const TriangleMesh& output, const OutputIndex& index) {
    const auto& P = output.vertices;
    const auto& T = output.triangles;
    auto normal_of = [&](const std::array<std::int32_t, 3>& t) { return triangle_normal(P, t); };
    // Each side once, from the triangle that has it running from its lower corner to its higher.
    std::vector<std::uint32_t> suspects = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, T.size(), 8192), std::vector<std::uint32_t>(),
        [&](const auto& r, std::vector<std::uint32_t> found) {
            for (std::size_t f = r.begin(); f != r.end(); ++f) {
                Eigen::Vector3d n = Eigen::Vector3d::Zero();
                for (int k = 0; k < 3; ++k) {
                    const std::int32_t a = T[f][std::size_t(k)], b = T[f][std::size_t((k + 1) % 3)];
                    if (a > b) continue;
                    if (n.isZero()) n = normal_of(T[f]);
                    const auto [begin, end] = index.ring(std::size_t(a));
                    for (const std::uint32_t* q = begin; q != end; ++q)
                        if (*q != f && std::find(T[*q].begin(), T[*q].end(), b) != T[*q].end()) {
                            const Eigen::Vector3d m = normal_of(T[*q]);
                            if (n.dot(m) < kSteep * n.norm() * m.norm()) found.push_back(std::uint32_t(f)), found.push_back(*q);
                            break;
                        }
                }
            }
            return found;
        },
        concat<std::uint32_t>);
    tbb::parallel_sort(suspects.begin(), suspects.end());
    suspects.erase(std::unique(suspects.begin(), suspects.end()), suspects.end());
    return suspects;
}

/// Step 8: flips sides where the triangles on either side turn from the exact surface. With every vertex on the
/// exact warp, the triangulation can still cut under it: a triangle from one face of a sharp crease to the other
/// (the ear's rim, 0.37 voxel under the exact warp), or one folded flat onto its neighbours (an in-plane fold, as
/// the feature mesher leaves some where fans of its corners meet at an edge or a tip). A triangle's misfit is its
/// area times, summed over its corners, one less the cosine of the angle between its normal and the exact normal
/// there nearest it (the normals of the faces at the corner's source, as the maps carry them: two or more on a
/// crease or corner). Two triangles trade their shared side for the other diagonal where that lowers their misfit
/// by a tenth, neither new one faces against the exact normal at every corner or has next to no area, and neither
/// crosses a triangle near it. Returns the flips made.
std::size_t flip_to_normals(TriangleMesh& output, const std::vector<SourcePoint>& sources, const SourceSurface::Impl& surface,
                            const std::vector<WarpStep>& steps, OutputIndex& index, const std::vector<Eigen::Vector3d>* home, double h,
                            const std::vector<std::uint32_t>* only = nullptr) {
    const auto& P = output.vertices;
    auto& T = output.triangles;
    if (!output.quads.empty() || T.empty() || sources.size() != P.size()) return 0;
    auto normal_of = [&](const std::array<std::int32_t, 3>& t) { return triangle_normal(P, t); };
    // Cheap first: the triangles steep_sides finds (`only`: these instead); only those are judged by their
    // sources. (Vertex normals would do, but an array of them is megabytes of fresh pages: 40 ms at 256.)
    const std::vector<std::uint32_t> suspects = only ? *only : steep_sides(output, index);
    if (suspects.empty()) return 0;
    // The exact normals at a vertex: of the faces at its source point (one inside a face, those sharing a side or a
    // corner), pushed forward; none without a source. Worked out once each.
    const Adjacency input_rings = faces_with_area(surface);
    using Normals = Few<Eigen::Vector3d, FeaturePoint::kFaces>;
    std::unordered_map<std::int32_t, Normals> exact;
    auto exact_at = [&](std::int32_t v) -> const Normals& {
        auto [it, fresh] = exact.try_emplace(v);
        const SourcePoint& s = sources[std::size_t(v)];
        if (!fresh || s.face < 0) return it->second;
        const auto& F = surface.faces;
        std::array<Eigen::Vector3d, FeaturePoint::kFaces> n{};
        std::size_t count = 0;
        n[count++] = surface.normal[std::size_t(s.face)];
        // The faces with area at each corner of the source's face its weights reach; those that hold the point.
        const Eigen::Vector3d x = surface.position(s);
        for (int k = 0; k < 3; ++k) {
            if (s.barycentric[(k + 1) % 3] > 0 && s.barycentric[(k + 2) % 3] > 0) continue; // not at corner k's side or corner
            const std::size_t corner = std::size_t(F[std::size_t(s.face)][std::size_t(k)]);
            for (const std::uint32_t* g = input_rings.begin(corner); g != input_rings.end(corner) && count < n.size(); ++g) {
                if (std::int32_t(*g) == s.face) continue;
                const auto& t = F[*g];
                if ((internal::closest_on_triangle(x, surface.V[std::size_t(t[0])], surface.V[std::size_t(t[1])], surface.V[std::size_t(t[2])]) - x).norm() > 1e-9 * h) continue;
                bool known = false;
                for (std::size_t j = 0; j < count; ++j) known |= n[j].dot(surface.normal[*g]) > 1 - 1e-12;
                if (!known) n[count++] = surface.normal[*g];
            }
        }
        n = push_normals<FeaturePoint::kFaces>(steps, x, n);
        for (std::size_t j = 0; j < count; ++j)
            if (!n[j].isZero()) it->second.push_back(n[j]);
        return it->second;
    };
    const double tiny = 1e-6 * h * h;
    // Per corner, one less the cosine to the nearest exact normal; a corner without one counts nothing.
    auto misfit = [&](const std::array<std::int32_t, 3>& t) {
        const Eigen::Vector3d n = normal_of(t);
        const double area = n.norm();
        if (area == 0) return 0.0;
        double sum = 0;
        for (const auto c : t) {
            const Normals& exact_here = exact_at(c);
            double best = -1;
            for (const auto& m : exact_here) best = std::max(best, n.dot(m) / area);
            if (!exact_here.empty()) sum += 1 - best;
        }
        return 0.5 * area * sum;
    };
    auto against = [&](const std::array<std::int32_t, 3>& t) {
        const Eigen::Vector3d n = normal_of(t);
        return std::all_of(t.begin(), t.end(), [&](std::int32_t c) {
            return !exact_at(c).empty() && std::all_of(exact_at(c).begin(), exact_at(c).end(), [&](const Eigen::Vector3d& m) { return n.dot(m) < 0; });
        });
    };
    // Worth a try: corners' terms adding up to more than kOffNormals.
    auto off = [&](const std::array<std::int32_t, 3>& t) { return misfit(t) > kOffNormals * 0.5 * normal_of(t).norm(); };
    std::vector<std::uint32_t> folds;
    for (const std::uint32_t f : suspects)
        if (off(T[f])) folds.push_back(f);
    if (folds.empty()) return 0;
    // The triangles around each vertex: the index's, and those a flip in this pass changed kept apart.
    std::unordered_map<std::int32_t, std::vector<std::uint32_t>> changed;
    auto ring = [&](std::int32_t v) -> std::pair<const std::uint32_t*, const std::uint32_t*> {
        if (auto it = changed.find(v); it != changed.end()) return {it->second.data(), it->second.data() + it->second.size()};
        return index.ring(std::size_t(v));
    };
    auto own = [&](std::int32_t v) -> std::vector<std::uint32_t>& {
        auto [it, fresh] = changed.try_emplace(v);
        if (fresh) {
            const auto [b, e] = index.ring(std::size_t(v));
            it->second.assign(b, e);
        }
        return it->second;
    };
    using Box = TriangleBox;
    auto box_of = [&](const std::array<std::int32_t, 3>& t) { return voxwarp::box_of(P, t); };
    auto meet = boxes_meet;
    std::vector<std::uint32_t> flipped; // in this pass (the index files them where they were)
    ChangedCells flipped_in(h);
    auto at = [&](std::int32_t i) -> const Eigen::Vector3d& { return P[std::size_t(i)]; };
    std::vector<std::uint32_t> near;
    std::size_t flips = 0;
    for (int pass = 0; pass < 16 && !folds.empty(); ++pass) {
        const std::size_t before = flips;
        std::vector<std::uint32_t> left;
        for (const std::uint32_t f : folds) {
            if (!off(T[f])) continue; // a flip next to it mended it
            // The sides whose flips lower the misfit, most first; the first that crosses nothing.
            struct Flip {
                double gain;
                std::uint32_t g;
                std::array<std::int32_t, 3> one, two;
            };
            Few<Flip, 3> flips_of_f;
            for (int k = 0; k < 3; ++k) {
                const std::int32_t a = T[f][std::size_t(k)], b = T[f][std::size_t((k + 1) % 3)], c = T[f][std::size_t((k + 2) % 3)];
                // The triangle with side b -> a, and its third corner d.
                std::int64_t g = -1;
                std::int32_t d = -1;
                const auto [b0, e0] = ring(a);
                for (const std::uint32_t* q = b0; q != e0 && g < 0; ++q)
                    for (int j = 0; j < 3; ++j)
                        if (T[*q][std::size_t(j)] == b && T[*q][std::size_t((j + 1) % 3)] == a) g = *q, d = T[*q][std::size_t((j + 2) % 3)];
                if (g < 0 || d == c) continue;
                const auto [b1, e1] = ring(c);
                if (std::any_of(b1, e1, [&](std::uint32_t q) { return std::find(T[q].begin(), T[q].end(), d) != T[q].end(); })) continue; // c-d is a side already
                const std::array<std::int32_t, 3> one{c, a, d}, two{d, b, c};
                if (normal_of(one).norm() <= tiny || normal_of(two).norm() <= tiny || against(one) || against(two)) continue;
                const double was = misfit(T[f]) + misfit(T[std::size_t(g)]), now = misfit(one) + misfit(two);
                if (!(now < 0.9 * was)) continue;
                // Seen along the exact normals at the four corners, both new triangles turn the right way: then they
                // lie on either side of their shared side and cover what the two they replace did (less any fold).
                Eigen::Vector3d N = Eigen::Vector3d::Zero();
                for (const std::int32_t v : {a, b, c, d})
                    for (const auto& m : exact_at(v)) N += m;
                if (!(normal_of(one).dot(N) > 0 && normal_of(two).dot(N) > 0)) continue;
                // Facing along N at home too, where put_back_crossings may take the corners back.
                if (home && !(triangle_normal(*home, one).dot(N) > 0 && triangle_normal(*home, two).dot(N) > 0)) continue;
                flips_of_f.push_back({was - now, std::uint32_t(g), one, two});
            }
            // Most gain first (three at most: std::sort's path for sixteen draws an array-bounds warning).
            for (Flip* x = flips_of_f.begin(); x != flips_of_f.end(); ++x)
                for (Flip* y = x; y != flips_of_f.begin() && y->gain > (y - 1)->gain; --y) std::swap(*y, *(y - 1));
            double gain = 0;
            std::uint32_t best_g = 0;
            std::array<std::int32_t, 3> best_one{}, best_two{};
            for (const Flip& flip : flips_of_f) {
                const std::array<std::int32_t, 3>&one = flip.one, &two = flip.two;
                const std::int32_t c = one[0], d = one[2];
                // Not folded back onto a neighbour across an old side (by more than 150 degrees).
                auto folds_back = [&](const std::array<std::int32_t, 3>& t) {
                    const Eigen::Vector3d n = normal_of(t).normalized();
                    for (int j = 0; j < 3; ++j) {
                        const std::int32_t x = t[std::size_t(j)], y = t[std::size_t((j + 1) % 3)];
                        if ((x == c && y == d) || (x == d && y == c)) continue;
                        const auto [bx, ex] = ring(x);
                        for (const std::uint32_t* q = bx; q != ex; ++q)
                            if (*q != f && *q != flip.g && std::find(T[*q].begin(), T[*q].end(), y) != T[*q].end() &&
                                !(n.dot(normal_of(T[*q]).normalized()) > -kCornerFold) && !against(T[*q]))
                                return true;
                    }
                    return false;
                };
                if (folds_back(one) || folds_back(two)) continue;
                // Not through a triangle near it: those the index files near, and those flipped in this pass.
                const Box box1 = box_of(one), box2 = box_of(two);
                const Box reach{box1.first.cwiseMin(box2.first), box1.second.cwiseMax(box2.second)};
                gather_near(output, index, flipped_in, reach, near);
                const bool crosses = std::any_of(near.begin(), near.end(), [&](std::uint32_t q) {
                    if (q == f || q == flip.g) return false;
                    const Box bq = box_of(T[q]);
                    return (meet(bq, box1) && triangles_cross(at, one, T[q])) || (meet(bq, box2) && triangles_cross(at, two, T[q]));
                });
                if (crosses) continue;
                gain = flip.gain, best_g = flip.g, best_one = one, best_two = two;
                break;
            }
            if (gain == 0) {
                left.push_back(f);
                continue;
            }
            const std::int32_t a = best_one[1], b = best_two[1], c = best_one[0], d = best_one[2];
            T[f] = best_one;
            T[best_g] = best_two;
            auto drop = [&](std::int32_t v, std::uint32_t t) { auto& r = own(v); r.erase(std::remove(r.begin(), r.end(), t), r.end()); };
            drop(a, best_g);
            drop(b, f);
            own(c).push_back(best_g);
            own(d).push_back(f);
            flipped.push_back(f), flipped.push_back(best_g);
            for (const std::uint32_t t : {f, best_g}) flipped_in.file(t, box_of(T[t]));
            ++flips;
        }
        if (flips == before) break;
        // The next pass: what is still off among the triangles flipped and those around their corners (one that
        // failed with nothing changed around it fails again).
        std::sort(flipped.begin(), flipped.end());
        flipped.erase(std::unique(flipped.begin(), flipped.end()), flipped.end());
        left.clear();
        for (const std::uint32_t f : flipped)
            for (const std::int32_t c : T[f]) {
                const auto [b, e] = ring(c);
                for (const std::uint32_t* q = b; q != e; ++q)
                    if (off(T[*q])) left.push_back(*q);
            }
        index.update(output, flipped);
        flipped.clear();
        flipped_in.clear();
        changed.clear();
        std::sort(left.begin(), left.end());
        left.erase(std::unique(left.begin(), left.end()), left.end());
        folds = std::move(left);
    }
    return flips;
}

/// Where each vertex of `left` goes if it can (snap_again): its exact image, or max_move toward one up to
/// kPartReach max_move away, from where extraction made it (as in step 3: a later round moves no farther).
std::vector<Eigen::Vector3d> targets_again(const TriangleMesh& output, const std::vector<SourcePoint>& sources, const SourceSurface::Impl& surface,
                                           const std::vector<WarpStep>& steps, const std::vector<std::int32_t>& left, double max_move) {
    const auto& P = output.vertices;
    std::vector<Eigen::Vector3d> target(left.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, left.size(), 256), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const std::size_t v = std::size_t(left[i]);
            Eigen::Vector3d x = push_forward(steps, surface.position(sources[v]));
            const double d = (x - P[v]).norm();
            if (!x.allFinite() || d > kPartReach * max_move) x = P[v];
            else if (d > max_move) x = P[v] + (max_move / d) * (x - P[v]);
            target[i] = x;
        }
    });
    return target;
}

/// Step 7b: the vertices snapping left where extraction made them (step 3) try again, one at a time, now that
/// refinement has put the input's creases in around them: where several of a face's corners had their sources on
/// one crease (the rim of a thin part the warp's carry thickens), moving them all together collapsed the face,
/// and each alone folded it with the others still off; they stayed up to half a voxel outside the exact warp (the
/// bunny ear's worst place, 0.35 voxel). A vertex moves onto its image (half a voxel toward one up to a voxel
/// away) where no triangle around it turns over, collapses, or faces against the exact normal at each of its
/// corners, and none crosses a triangle near it. Returns the triangles around those it moved; `count` grows by them.
std::vector<std::uint32_t> snap_again(TriangleMesh& output, const std::vector<SourcePoint>& sources, const SourceSurface::Impl& surface,
                                      const std::vector<WarpStep>& steps, const std::vector<std::int32_t>& left, const std::vector<Eigen::Vector3d>& target,
                                      OutputIndex& index, double h, std::size_t& count) {
    auto& P = output.vertices;
    const auto& T = output.triangles;
    auto normal_of = [&](const std::array<std::int32_t, 3>& t) { return triangle_normal(P, t); };
    auto box_of = [&](const std::array<std::int32_t, 3>& t) { return voxwarp::box_of(P, t); };
    auto exact_normal = [&](std::int32_t v) {
        const SourcePoint& s = sources[std::size_t(v)];
        return s.face < 0 ? Eigen::Vector3d::Zero() : push_normal(steps, surface.position(s), surface.normal[std::size_t(s.face)]);
    };
    const double tiny = 1e-4 * h * h;
    std::vector<std::uint32_t> moved; // triangles around a vertex moved (the index files them where they were)
    ChangedCells moved_in(h);
    std::vector<std::uint32_t> near;
    for (std::size_t i = 0; i < left.size(); ++i) {
        const std::int32_t v = left[i];
        if ((target[i] - P[std::size_t(v)]).norm() <= 1e-6 * h) continue; // there already
        const auto [begin, end] = index.ring(std::size_t(v));
        if (begin == end) continue;
        std::vector<Eigen::Vector3d> before;
        for (const std::uint32_t* f = begin; f != end; ++f) before.push_back(normal_of(T[*f]));
        const Eigen::Vector3d from = P[std::size_t(v)];
        P[std::size_t(v)] = target[i];
        bool fine = true;
        for (const std::uint32_t* f = begin; f != end && fine; ++f) {
            const Eigen::Vector3d n = normal_of(T[*f]);
            fine = n.norm() > tiny && n.dot(before[std::size_t(f - begin)]) > 0;
            // Not facing against the exact normal at every corner.
            bool along = false;
            for (const std::int32_t c : T[*f]) along |= n.dot(exact_normal(c)) > 0;
            fine = fine && along;
            // Nor folded flat onto a neighbour (its third corner within a thousandth of a voxel of the neighbour's
            // plane, the two facing apart): such a face can still look along the exact normal of a corner on a sharp
            // crease (the bar bend's ends). A thin part's ridge, as sharp but open, stays.
            const Eigen::Vector3d unit = n.normalized();
            for (int k = 0; k < 3 && fine; ++k) {
                const std::int32_t a = T[*f][std::size_t(k)], b = T[*f][std::size_t((k + 1) % 3)], c = T[*f][std::size_t((k + 2) % 3)];
                const auto [ab, ae] = index.ring(std::size_t(a));
                for (const std::uint32_t* g = ab; g != ae && fine; ++g) {
                    if (*g == *f || !has_side(T[*g], b, a)) continue;
                    const Eigen::Vector3d m = normal_of(T[*g]).normalized();
                    fine = unit.dot(m) > -kCornerFold || std::abs(m.dot(P[std::size_t(c)] - P[std::size_t(a)])) > 1e-3 * h;
                }
            }
        }
        if (!fine || moved_faces_cross(output, index, moved_in, begin, end, near)) {
            P[std::size_t(v)] = from;
            continue;
        }
        ++count;
        moved.insert(moved.end(), begin, end);
        for (const std::uint32_t* f = begin; f != end; ++f) moved_in.file(*f, box_of(T[*f]));
    }
    std::sort(moved.begin(), moved.end());
    moved.erase(std::unique(moved.begin(), moved.end()), moved.end());
    if (!moved.empty()) index.update(output, moved);
    return moved;
}

/// Passes of unfold at most: a corner moved may let one beside it move in the next.
constexpr int kUnfoldPasses = 3;
/// Steps a tangle of fold corners relaxes by together (unfold).
constexpr int kRelaxSteps = 8;
/// Radians two triangles across a side may turn beyond the exact normals at their corners before they count as a
/// fold (unfold): 20 degrees.
constexpr double kFoldSlack = 20.0 * std::numbers::pi / 180.0;

/// Step 9: folds left. Where snapping moved some vertices of a patch and not others, or refinement put points in
/// beside vertices left where extraction made them, two triangles across a side can face apart though neither
/// turned over: a fin standing on a flat side (the bar bend at 128 had 26, along its sides' edges, where marching
/// cubes left slivers: the sides lie on voxel planes), or a pleat. Such a fold is one where the two face apart by
/// more than acos(-kCornerFold) and lie flat on each other, or turn further apart than the exact normals at any
/// two of their corners do, and kFoldSlack more (a thin part's ridge, as sharp, has its two sides' normals). Each
/// corner of a fold left off its exact image tries its image (when within max_move), the middle of the corners
/// around it projected onto the exact tangent plane at the image, and the middle itself; one on its image only
/// the projected middle (on a flat face it stays on the face). It takes the first that leaves fewer folds around
/// it and no triangle there collapsed, facing against the exact normal at every corner, or crossing one near it.
/// Corners that no move of their own mends relax together, by groups joined by triangles (below). Looks at the
/// sides of the triangles `look` lists. Returns the triangles around the corners moved.
std::vector<std::uint32_t> unfold(TriangleMesh& output, const std::vector<SourcePoint>& sources, const SourceSurface::Impl& surface,
                                  const std::vector<WarpStep>& steps, OutputIndex& index, double h, double max_move, const std::vector<std::uint32_t>& look) {
    auto& P = output.vertices;
    const auto& T = output.triangles;
    if (!output.quads.empty() || T.empty() || sources.size() != P.size()) return {};
    auto normal_of = [&](const std::array<std::int32_t, 3>& t) { return triangle_normal(P, t); };
    auto exact_normal = [&](std::int32_t v) {
        const SourcePoint& s = sources[std::size_t(v)];
        return s.face < 0 ? Eigen::Vector3d::Zero() : push_normal(steps, surface.position(s), surface.normal[std::size_t(s.face)]).normalized();
    };
    // The neighbour of triangle f across its side k, or -1.
    auto across = [&](std::uint32_t f, int k) -> std::int64_t {
        const std::int32_t a = T[f][std::size_t(k)], b = T[f][std::size_t((k + 1) % 3)];
        const auto [begin, end] = index.ring(std::size_t(a));
        for (const std::uint32_t* g = begin; g != end; ++g)
            if (*g != f && has_side(T[*g], b, a)) return *g;
        return -1;
    };
    // Whether f and g, across f's side k, fold (cheap test first: facing apart at all).
    auto fold = [&](std::uint32_t f, std::uint32_t g, int k) {
        const Eigen::Vector3d n = normal_of(T[f]), m = normal_of(T[g]);
        if (n.dot(m) >= 0 || n.norm() == 0 || m.norm() == 0) return false;
        const Eigen::Vector3d nu = n.normalized(), mu = m.normalized();
        if (nu.dot(mu) >= -kCornerFold) return false;
        const std::int32_t a = T[f][std::size_t(k)], c = T[f][std::size_t((k + 2) % 3)];
        if (std::abs(mu.dot(P[std::size_t(c)] - P[std::size_t(a)])) <= 1e-3 * h) return true;
        // The widest turn between the exact normals at a corner of each: the two sides of a thin part's ridge turn
        // as far as the triangles on them, one face and the crease beside it no further than the crease.
        double widest = 1;
        for (const std::int32_t x : T[f])
            for (const std::int32_t y : T[g]) widest = std::min(widest, exact_normal(x).dot(exact_normal(y)));
        return std::acos(std::clamp(nu.dot(mu), -1.0, 1.0)) > std::acos(std::clamp(widest, -1.0, 1.0)) + kFoldSlack;
    };
    std::vector<std::int32_t> corners = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, look.size(), 1024), std::vector<std::int32_t>(),
        [&](const auto& r, std::vector<std::int32_t> found) {
            for (std::size_t i = r.begin(); i != r.end(); ++i)
                for (int k = 0; k < 3; ++k) {
                    const std::size_t f = look[i];
                    const std::int64_t g = across(std::uint32_t(f), k);
                    if (g < 0 || !fold(std::uint32_t(f), std::uint32_t(g), k)) continue;
                    found.insert(found.end(), T[f].begin(), T[f].end());
                    found.insert(found.end(), T[std::size_t(g)].begin(), T[std::size_t(g)].end());
                }
            return found;
        },
        concat<std::int32_t>);
    if (corners.empty()) return {};
    std::sort(corners.begin(), corners.end());
    corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
    const double tiny = 1e-4 * h * h;
    // The folds among the triangles around v and their neighbours.
    auto folds_around = [&](std::int32_t v) {
        std::size_t count = 0;
        const auto [begin, end] = index.ring(std::size_t(v));
        for (const std::uint32_t* f = begin; f != end; ++f)
            for (int k = 0; k < 3; ++k) {
                const std::int64_t g = across(*f, k);
                count += g >= 0 && fold(*f, std::uint32_t(g), k);
            }
        return count;
    };
    std::vector<std::uint32_t> moved;
    ChangedCells moved_in(h);
    std::vector<std::uint32_t> near;
    // Whether the triangles `faces` (those around the corners that moved) all have area, look along the exact
    // normal at a corner each, and cross none of the triangles near them.
    auto faces_fine = [&](const std::vector<std::uint32_t>& faces) {
        for (const std::uint32_t f : faces) {
            const Eigen::Vector3d n = normal_of(T[f]);
            bool along = false;
            for (const std::int32_t c : T[f]) along |= n.dot(exact_normal(c)) > 0;
            if (n.norm() <= tiny || !along) return false;
        }
        return !moved_faces_cross(output, index, moved_in, faces.data(), faces.data() + faces.size(), near);
    };
    // The middle of the vertices around v (each twice on a closed ring), and where v may go toward it: a vertex on
    // its exact image only in the exact tangent plane there (onto which the middle is projected), so that one on a
    // flat face stays on it; one left off it to its image, the projected middle, or the middle itself.
    struct Place {
        Eigen::Vector3d middle, image, normal = Eigen::Vector3d::Zero();
        bool reachable = false, on_image = false;
        Eigen::Vector3d toward(const Eigen::Vector3d& x) const { return reachable ? Eigen::Vector3d(x - (x - image).dot(normal) * normal) : x; }
    };
    auto middle_of = [&](std::int32_t v) {
        Eigen::Vector3d middle = Eigen::Vector3d::Zero();
        const auto [begin, end] = index.ring(std::size_t(v));
        std::size_t others = 0;
        for (const std::uint32_t* f = begin; f != end; ++f)
            for (const std::int32_t c : T[*f])
                if (c != v) middle += P[std::size_t(c)], ++others;
        return Eigen::Vector3d(middle / double(std::max<std::size_t>(others, 1)));
    };
    auto place_of = [&](std::int32_t v) {
        Place w;
        w.middle = middle_of(v);
        const SourcePoint& source = sources[std::size_t(v)];
        w.image = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
        if (source.face >= 0) w.image = push_forward(steps, surface.position(source)), w.normal = exact_normal(v);
        const Eigen::Vector3d& from = P[std::size_t(v)];
        w.reachable = w.image.allFinite() && w.normal.allFinite() && (w.image - from).norm() <= max_move;
        w.on_image = w.reachable && (w.image - from).norm() <= 1e-6 * h;
        return w;
    };
    std::vector<std::int32_t> stuck; // corners no move of their own mends
    std::vector<std::uint32_t> faces;
    for (const std::int32_t v : corners) {
        const std::size_t was = folds_around(v);
        if (was == 0) continue;
        const auto [begin, end] = index.ring(std::size_t(v));
        if (begin == end) continue;
        faces.assign(begin, end);
        std::sort(faces.begin(), faces.end());
        const Eigen::Vector3d from = P[std::size_t(v)];
        const Place w = place_of(v);
        std::vector<Eigen::Vector3d> tries;
        if (w.reachable && !w.on_image) tries.push_back(w.image);
        if (w.reachable) tries.push_back(w.toward(w.middle));
        if (!w.on_image) tries.push_back(w.middle);
        bool fine = false;
        for (const Eigen::Vector3d& p : tries) {
            P[std::size_t(v)] = p;
            fine = folds_around(v) < was && faces_fine(faces);
            if (fine) break;
        }
        if (!fine) {
            P[std::size_t(v)] = from;
            stuck.push_back(v);
            continue;
        }
        moved.insert(moved.end(), begin, end);
        for (const std::uint32_t f : faces) moved_in.file(f, box_of(P, T[f]));
    }
    // A tangle of several corners (the feature mesher's fans meeting on a flat face) no one move mends: each group
    // of stuck corners joined by triangles relaxes together, kRelaxSteps steps each to the middle of its own ring
    // (as above: in its tangent plane when on its image), and keeps that where the group's folds drop, under the
    // same tests.
    std::unordered_map<std::int32_t, std::size_t> slot;
    for (std::size_t i = 0; i < stuck.size(); ++i) slot[stuck[i]] = i;
    std::vector<std::size_t> parent(stuck.size());
    std::iota(parent.begin(), parent.end(), std::size_t(0));
    auto root = [&](std::size_t i) {
        while (parent[i] != i) i = parent[i] = parent[parent[i]];
        return i;
    };
    for (std::size_t i = 0; i < stuck.size(); ++i) {
        const auto [begin, end] = index.ring(std::size_t(stuck[i]));
        for (const std::uint32_t* f = begin; f != end; ++f)
            for (const std::int32_t c : T[*f])
                if (const auto it = slot.find(c); it != slot.end()) parent[root(it->second)] = root(i);
    }
    std::map<std::size_t, std::vector<std::int32_t>> groups; // by root, for an order that does not hash
    for (std::size_t i = 0; i < stuck.size(); ++i) groups[root(i)].push_back(stuck[i]);
    for (const auto& [r, group] : groups) {
        if (group.size() < 2) continue;
        std::size_t was = 0;
        faces.clear();
        for (const std::int32_t v : group) {
            was += folds_around(v);
            const auto [begin, end] = index.ring(std::size_t(v));
            faces.insert(faces.end(), begin, end);
        }
        std::sort(faces.begin(), faces.end());
        faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
        std::vector<Eigen::Vector3d> from(group.size()), to(group.size());
        std::vector<Place> places(group.size());
        for (std::size_t i = 0; i < group.size(); ++i) from[i] = P[std::size_t(group[i])], places[i] = place_of(group[i]);
        for (int step = 0; step < kRelaxSteps; ++step) {
            for (std::size_t i = 0; i < group.size(); ++i) to[i] = places[i].toward(middle_of(group[i]));
            for (std::size_t i = 0; i < group.size(); ++i) P[std::size_t(group[i])] = to[i];
        }
        std::size_t now = 0;
        for (const std::int32_t v : group) now += folds_around(v);
        if (now < was && faces_fine(faces)) {
            moved.insert(moved.end(), faces.begin(), faces.end());
            for (const std::uint32_t f : faces) moved_in.file(f, box_of(P, T[f]));
        } else {
            for (std::size_t i = 0; i < group.size(); ++i) P[std::size_t(group[i])] = from[i];
        }
    }
    std::sort(moved.begin(), moved.end());
    moved.erase(std::unique(moved.begin(), moved.end()), moved.end());
    if (!moved.empty()) index.update(output, moved);
    return moved;
}

/// refine_to_sources, its first round with `first` (computed when empty).
std::size_t refine_with(TriangleMesh& output, std::vector<SourcePoint>& sources, const SourceSurface& input, const std::vector<WarpStep>& steps,
                 const SnapOptions& options, const RefineOptions& refine, Sheets first, std::vector<Eigen::Vector3d>* home = nullptr,
                 std::size_t* snapped_again = nullptr) {
    check_options(options);
    if (sources.size() != output.vertices.size())
        throw InvalidInput("refine: " + std::to_string(sources.size()) + " source points for " + std::to_string(output.vertices.size()) + " vertices");
    if (!output.quads.empty()) return 0;
    const SourceSurface::Impl& surface = input.impl();
    const double h = options.voxel_size, reach = options.reach_voxels * h, near = 4 * h;
    const double chord = refine.chord_voxels * h, max_move = options.max_move_voxels * h, tiny = 1e-4 * h * h;
    using Key = std::uint64_t; // an edge: its ends, lower first
    auto key = [](std::int32_t a, std::int32_t b) { return Key(std::uint32_t(std::min(a, b))) << 32 | std::uint32_t(std::max(a, b)); };
    std::size_t added = 0;
    for (int round = 0; round < refine.rounds; ++round) {
        std::vector<Eigen::Vector3d>& P = output.vertices;
        const auto& T = output.triangles;
        const std::size_t n = P.size(), F = T.size();
        if (round > 0 || first.normal.size() != n || first.partner.size() != n) {
            first.normal = snap_internal::vertex_normals(output);
            first.partner = snap_internal::other_sheet(P, first.normal, 1.5 * h);
        }
        const std::vector<Eigen::Vector3d>& normal = first.normal;
        const std::vector<std::int32_t>& partner = first.partner;
        // An edge whose ends' sources lie on faces at an angle may leave the surface at its middle; where the
        // middle of the two sources lies within half the tolerance of either face's plane, it does not. In thin
        // parts (another sheet within 1.5 voxels) a new vertex has no partner to keep it apart from the other sheet:
        // its pieces are tested for crossings instead (below).
        auto creased = [&](std::int32_t a, std::int32_t b) {
            const SourcePoint &sa = sources[std::size_t(a)], &sb = sources[std::size_t(b)];
            if (sa.face < 0 || sb.face < 0 || sa.face == sb.face) return false;
            const Eigen::Vector3d pa = surface.position(sa), pb = surface.position(sb), m = 0.5 * (pa + pb);
            return std::min(std::abs((m - pa).dot(surface.normal[std::size_t(sa.face)])), std::abs((m - pb).dot(surface.normal[std::size_t(sb.face)]))) > 0.5 * chord;
        };
        // Each such edge (named by its side running from the lower vertex to the higher, in a closed mesh one per
        // edge) gets a source: on the crease, where its ends' faces share an edge (crease_point); otherwise the
        // nearest point to the middle of its ends' sources, found as a vertex's source is but without a pullback
        // (that middle is where the edge's middle comes from, to the map's second order). Fixed blocks, so that
        // the tree's hint gives the same answers for any thread count.
        struct Split {
            Key edge;
            Eigen::Vector3d at; ///< the exact image of the source point
            std::array<Eigen::Vector3d, 2> normal; ///< the exact surface's normal there, on either side of a crease
            SourcePoint source;
            /// In a thin part, or on the crease farther than max_move: judged by the exact normals and tested for
            /// crossings (below).
            bool rim = false;
        };
        constexpr std::size_t kBlock = 1536;
        const std::size_t blocks = (3 * F + kBlock - 1) / kBlock;
        std::vector<std::vector<Split>> found(blocks);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks), [&](const auto& r) {
            for (std::size_t block = r.begin(); block != r.end(); ++block) {
                std::optional<snap_internal::Hint> hint;
                for (std::size_t e = block * kBlock; e != std::min(3 * F, (block + 1) * kBlock); ++e) {
                    const std::int32_t a = T[e / 3][e % 3], b = T[e / 3][(e % 3 + 1) % 3];
                    if (a > b || !creased(a, b)) continue;
                    const SourcePoint &sa = sources[std::size_t(a)], &sb = sources[std::size_t(b)];
                    const Eigen::Vector3d pa = surface.position(sa), pb = surface.position(sb);
                    SourcePoint s;
                    std::int32_t other = -1; // the face across the crease
                    const bool thin = partner[std::size_t(a)] >= 0 || partner[std::size_t(b)] >= 0;
                    if (const auto on_crease = crease_point(surface, sa.face, sb.face, pa, pb)) {
                        s = *on_crease, other = sb.face;
                    } else {
                        s = surface.nearest(0.5 * (pa + pb), surface.normal[std::size_t(sa.face)] + surface.normal[std::size_t(sb.face)], reach, hint, near);
                        if (s.face < 0) continue;
                    }
                    const Eigen::Vector3d from = surface.position(s), x = push_forward(steps, from);
                    const double d = (x - 0.5 * (P[std::size_t(a)] + P[std::size_t(b)])).norm();
                    // A thin part's rim (the bunny's ear, stretched by its edit: a ridge of 60 degrees) is cut up to
                    // a voxel and more under its crease, whose point is then the only sound place for the vertex. Off
                    // the crease, a thin part's faces (the ear's tip, the scan's shell) are judged as a rim's: the
                    // extracted normals at their corners, from two sheets a voxel apart, say little (the fold rules of
                    // the thick parts gave the scan at 128 p99 0.226 voxel against the exact warp, these 0.194).
                    const bool rim = thin || (other >= 0 && d > max_move);
                    if (!(d > chord && d <= (other >= 0 && rim ? kCornerReach * h : max_move))) continue;
                    const Eigen::Vector3d& n = surface.normal[std::size_t(s.face)];
                    found[block].push_back({key(a, b), x, push_normals<2>(steps, from, {n, other < 0 ? n : surface.normal[std::size_t(other)]}), s, rim});
                }
            }
        });
        std::vector<Split> splits;
        for (auto& f : found) splits.insert(splits.end(), f.begin(), f.end());
        if (splits.empty()) break;
        std::sort(splits.begin(), splits.end(), [](const Split& x, const Split& y) { return x.edge < y.edge; });
        std::vector<char> touched(n, 0); // an end of a split edge
        for (const auto& s : splits) touched[s.edge >> 32] = touched[s.edge & 0xffffffffu] = 1;
        std::vector<char> split(splits.size(), 1);
        auto split_of = [&](std::int32_t a, std::int32_t b) -> std::int32_t { // index into splits, or -1
            if (!touched[std::size_t(a)] || !touched[std::size_t(b)]) return -1;
            const Key k = key(a, b);
            const auto it = std::lower_bound(splits.begin(), splits.end(), k, [](const Split& x, Key y) { return x.edge < y; });
            return it != splits.end() && it->edge == k ? std::int32_t(it - splits.begin()) : -1;
        };
        // The triangles with a split side, and their sides' splits.
        using Cut = std::pair<std::int32_t, std::array<std::int32_t, 3>>;
        const std::vector<Cut> cut = gather_in_order<Cut>(F, kBlock, [&](std::size_t f, std::vector<Cut>& out) {
            const auto& t = T[f];
            if (!touched[std::size_t(t[0])] + !touched[std::size_t(t[1])] + !touched[std::size_t(t[2])] > 1) return;
            const std::array<std::int32_t, 3> s{split_of(t[0], t[1]), split_of(t[1], t[2]), split_of(t[2], t[0])};
            if (s[0] >= 0 || s[1] >= 0 || s[2] >= 0) out.push_back({std::int32_t(f), s});
        });
        auto position = [&](Corner c) -> const Eigen::Vector3d& { return c >= 0 ? P[std::size_t(c)] : splits[std::size_t(-c - 1)].at; };
        auto on = [&](std::int32_t i) { return i >= 0 && split[std::size_t(i)]; }; // a side's split, not undone
        // Per cut triangle with two sides split: whether its four-sided piece is cut along the longer diagonal.
        std::vector<char> other_diagonal(cut.size(), 0);
        auto pieces_of = [&](std::size_t c, std::vector<std::array<Corner, 3>>& out) {
            const auto& s = cut[c].second;
            pieces(
                T[std::size_t(cut[c].first)], {on(s[0]), on(s[1]), on(s[2])}, [&](int k) { return Corner(-s[std::size_t(k)] - 1); },
                [&](Corner a, Corner b) { return (position(a) - position(b)).squaredNorm(); }, out, other_diagonal[c]);
        };
        auto on_rim = [&](std::size_t c) {
            return std::any_of(cut[c].second.begin(), cut[c].second.end(), [&](std::int32_t i) { return on(i) && splits[std::size_t(i)].rim; });
        };
        // Whether cut triangle c's pieces fold: turned over against it (or the extracted normal at its corners), or
        // a split corner's piece against its exact normal on both sides of its crease, or turned from either side
        // further than the crease turns (off_crease). A rim's pieces stand on the
        // crease's two faces, which may turn from the rounded triangle they replace by more than a right angle (the
        // ear's ridge: 90-100 degrees): up to 120 degrees, the exact normals judging them.
        auto folds_in = [&](std::size_t c, const std::vector<std::array<Corner, 3>>& parts) {
            const auto& t = T[std::size_t(cut[c].first)];
            const Eigen::Vector3d before = (P[std::size_t(t[1])] - P[std::size_t(t[0])]).cross(P[std::size_t(t[2])] - P[std::size_t(t[0])]);
            const bool rim = on_rim(c);
            return std::any_of(parts.begin(), parts.end(), [&](const auto& p) {
                const Eigen::Vector3d after = (position(p[1]) - position(p[0])).cross(position(p[2]) - position(p[0]));
                if (after.norm() < tiny) return true;
                if (rim ? after.dot(before) <= -0.5 * after.norm() * before.norm() : after.dot(before) <= 0 || turns_from_corners(before, after, t, normal))
                    return true;
                for (auto k : p) { // and a split corner's exact normal, on one side of its crease at least
                    if (k >= 0) continue;
                    const auto& e = splits[std::size_t(-k - 1)].normal;
                    if ((after.dot(e[0]) <= 0 && after.dot(e[1]) <= 0) || off_crease(after, e)) return true;
                }
                return false;
            });
        };
        // Whether cut triangle c has a piece turned more than 45 degrees from the extracted normal at one of its
        // corners: where the feature mesher's sharp edges and slivers are, a piece can pass through a triangle two
        // or three away, and such a triangle is tested for crossings as a rim's is.
        auto steep = [&](std::size_t c, std::vector<std::array<Corner, 3>>& parts) {
            const auto& t = T[std::size_t(cut[c].first)];
            parts.clear();
            pieces_of(c, parts);
            return std::any_of(parts.begin(), parts.end(), [&](const auto& p) {
                const Eigen::Vector3d after = (position(p[1]) - position(p[0])).cross(position(p[2]) - position(p[0]));
                return steep_at_corners(after, t, normal);
            });
        };
        auto tested = [&](std::size_t c, std::vector<std::array<Corner, 3>>& parts) { return on_rim(c) || (refine.steep_crossings && steep(c, parts)); };
        std::vector<std::int32_t> cut_of; // per triangle: its index in cut, or -1 (made when a rim is split)
        struct Box3 {
            Eigen::Vector3d lo, hi;
            bool meets(const Box3& o) const { return (lo.array() <= o.hi.array()).all() && (o.lo.array() <= hi.array()).all(); }
        };
        // A cut triangle's reach: its corners and every split point of its sides, put in or not.
        auto box_of = [&](const std::array<Corner, 3>& p) {
            Box3 b{position(p[0]), position(p[0])};
            for (const Corner k : p) b.lo = b.lo.cwiseMin(position(k)), b.hi = b.hi.cwiseMax(position(k));
            return b;
        };
        auto reach_of = [&](std::size_t c) {
            Box3 b = box_of(T[std::size_t(cut[c].first)]);
            for (const auto i : cut[c].second)
                if (i >= 0) b.lo = b.lo.cwiseMin(splits[std::size_t(i)].at), b.hi = b.hi.cwiseMax(splits[std::size_t(i)].at);
            return b;
        };
        std::vector<char> tested_split; // the splits as the last crossing test found them (empty: none yet)
        // Whether a cut triangle's pieces fold depends on its own sides' splits only: after the first pass, the
        // fold test looks again only at the cut triangles beside a split just given up (at 256, a few hundred of
        // 41,000 a pass, where each pass over all took 3-4 ms).
        const Adjacency cuts_beside(splits.size(), [&](auto visit) { // per split: the cut triangles with it as a side
            for (std::size_t c = 0; c < cut.size(); ++c)
                for (const auto i : cut[c].second)
                    if (i >= 0) visit(std::size_t(i), std::uint32_t(c));
        });
        std::vector<std::uint32_t> fold_test(cut.size()); // the cut triangles the next fold pass looks at
        std::iota(fold_test.begin(), fold_test.end(), std::uint32_t(0));
        auto beside = [&](const std::vector<std::int32_t>& given_up) {
            std::vector<std::uint32_t> next;
            for (const auto i : given_up) next.insert(next.end(), cuts_beside.begin(std::size_t(i)), cuts_beside.end(std::size_t(i)));
            std::sort(next.begin(), next.end());
            next.erase(std::unique(next.begin(), next.end()), next.end());
            return next;
        };
        for (;;) {
            // A triangle whose pieces would fold keeps its sides whole; that changes only its neighbours' pieces,
            // so repeat until every cut triangle passes. A rim's triangle split on two sides tries the longer
            // diagonal too: the shorter can leave a piece edge-on across the ridge.
            for (;;) {
                const std::vector<std::int32_t> whole = tbb::parallel_reduce(
                    tbb::blocked_range<std::size_t>(0, fold_test.size(), 1024), std::vector<std::int32_t>(),
                    [&](const auto& r, std::vector<std::int32_t> keep) {
                        std::vector<std::array<Corner, 3>> parts;
                        for (std::size_t k = r.begin(); k != r.end(); ++k) {
                            const std::size_t c = fold_test[k];
                            const auto& s = cut[c].second;
                            if (!on(s[0]) && !on(s[1]) && !on(s[2])) continue;
                            bool folds = true;
                            for (const char other : {0, 1}) {
                                if (other && (int(on(s[0])) + int(on(s[1])) + int(on(s[2])) != 2 || !on_rim(c))) break;
                                other_diagonal[c] = other;
                                parts.clear();
                                pieces_of(c, parts);
                                if (!(folds = folds_in(c, parts))) break;
                            }
                            if (folds)
                                for (auto i : s)
                                    if (on(i)) keep.push_back(i);
                        }
                        return keep;
                    },
                    concat<std::int32_t>);
                if (whole.empty()) break;
                for (auto i : whole) split[std::size_t(i)] = 0;
                fold_test = beside(whole);
            }
            // A rim's pieces reach up to 1.5 voxels off the output, where they may pass through its far sheet or a
            // neighbour's pieces, and a steep triangle's (above) through one a few triangles away: each such
            // triangle's pieces against every triangle (cut ones by their pieces) whose box meets theirs, and one
            // with a crossing gives up its rim splits (a steep one, all its splits); until none crosses. The
            // rims tested: all of them the first time, then those near a cut triangle whose splits changed since
            // (given up for a crossing, or undone by the folds that followed), the only places where pieces moved.
            std::vector<std::size_t> rims;
            if (tested_split.empty()) {
                rims = tbb::parallel_reduce(
                    tbb::blocked_range<std::size_t>(0, cut.size(), 1024), std::vector<std::size_t>(),
                    [&](const auto& r, std::vector<std::size_t> found) {
                        std::vector<std::array<Corner, 3>> parts;
                        for (std::size_t c = r.begin(); c != r.end(); ++c)
                            if (tested(c, parts)) found.push_back(c);
                        return found;
                    },
                    concat<std::size_t>);
            } else {
                std::vector<Box3> dirty;
                for (std::size_t c = 0; c < cut.size(); ++c)
                    if (std::any_of(cut[c].second.begin(), cut[c].second.end(), [&](std::int32_t i) { return i >= 0 && split[std::size_t(i)] != tested_split[std::size_t(i)]; })) {
                        Box3 b = reach_of(c);
                        b.lo.array() -= 2 * h, b.hi.array() += 2 * h;
                        dirty.push_back(b);
                    }
                std::vector<std::array<Corner, 3>> parts;
                for (std::size_t c = 0; c < cut.size(); ++c) {
                    const Box3 b = reach_of(c);
                    if (std::any_of(dirty.begin(), dirty.end(), [&](const Box3& d) { return d.meets(b); }) && tested(c, parts)) rims.push_back(c);
                }
            }
            if (rims.empty()) break;
            tested_split = split;
            if (cut_of.empty()) {
                cut_of.assign(F, -1);
                for (std::size_t c = 0; c < cut.size(); ++c) cut_of[std::size_t(cut[c].first)] = std::int32_t(c);
            }
            // Cells a voxel wide over the rims' reach (grown by two voxels), numbered from its low corner: a box
            // beyond the region meets none, one reaching out of it is clamped to its border cells.
            Box3 region{Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), Eigen::Vector3d::Constant(-std::numeric_limits<double>::infinity())};
            for (const std::size_t c : rims) {
                const Box3 b = reach_of(c);
                region.lo = region.lo.cwiseMin(b.lo), region.hi = region.hi.cwiseMax(b.hi);
            }
            region.lo.array() -= 2 * h, region.hi.array() += 2 * h;
            std::array<std::int64_t, 3> cells{};
            for (int a = 0; a < 3; ++a) cells[std::size_t(a)] = std::int64_t(std::ceil((region.hi[a] - region.lo[a]) / h)) + 1;
            auto cell = [&](const Eigen::Vector3d& x) {
                std::array<std::int64_t, 3> c{};
                for (int a = 0; a < 3; ++a)
                    c[std::size_t(a)] = std::int64_t(std::clamp(std::floor((x[a] - region.lo[a]) / h), 0.0, double(cells[std::size_t(a)] - 1)));
                return c;
            };
            auto cell_key = [&](std::int64_t x, std::int64_t y, std::int64_t z) { return std::uint64_t(x + cells[0] * (y + cells[1] * z)); };
            // Calls visit(key) for each cell of a box that meets the region, until it returns true.
            auto each_cell = [&](const Box3& b, const auto& visit) {
                if (!b.meets(region)) return false;
                const auto lo = cell(b.lo), hi = cell(b.hi);
                for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
                    for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
                        for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
                            if (visit(cell_key(x, y, z))) return true;
                return false;
            };
            // The rims' pieces, filed under every cell their boxes reach; `reached`: those cells.
            std::vector<std::array<Corner, 3>> rim_pieces;
            std::vector<std::uint32_t> rim_of; // per rim piece: its rim (index into rims)
            std::vector<std::pair<std::uint64_t, std::uint32_t>> filed; // (cell, rim piece)
            std::vector<std::array<Corner, 3>> parts;
            for (std::size_t q = 0; q < rims.size(); ++q) {
                parts.clear();
                pieces_of(rims[q], parts);
                for (const auto& p : parts) {
                    each_cell(box_of(p), [&](std::uint64_t k) { return filed.push_back({k, std::uint32_t(rim_pieces.size())}), false; });
                    rim_pieces.push_back(p), rim_of.push_back(std::uint32_t(q));
                }
            }
            tbb::parallel_sort(filed.begin(), filed.end());
            std::vector<std::uint64_t> reached;
            for (std::size_t e = 0; e < filed.size(); ++e)
                if (e == 0 || filed[e].first != filed[e - 1].first) reached.push_back(filed[e].first);
            // Most triangles lie far from every rim: a bitmap of the blocks of 4 x 4 x 4 cells the rims reach passes
            // those over before their cells are looked up (at most 2^27 bits: beyond, every block counts).
            const std::array<std::int64_t, 3> blocks{(cells[0] + 3) / 4, (cells[1] + 3) / 4, (cells[2] + 3) / 4};
            const bool bitmap = double(blocks[0]) * double(blocks[1]) * double(blocks[2]) <= double(1 << 27);
            std::vector<std::uint64_t> blocked(bitmap ? std::size_t(blocks[0] * blocks[1] * blocks[2] + 63) / 64 : 0, 0);
            auto block_of = [&](std::int64_t x, std::int64_t y, std::int64_t z) { return std::size_t(x / 4 + blocks[0] * (y / 4 + blocks[1] * (z / 4))); };
            if (bitmap)
                for (const std::uint64_t k : reached) {
                    const std::int64_t key = std::int64_t(k);
                    const std::size_t b = block_of(key % cells[0], key / cells[0] % cells[1], key / (cells[0] * cells[1]));
                    blocked[b / 64] |= std::uint64_t(1) << (b % 64);
                }
            auto in_blocks = [&](const Box3& b) {
                if (!b.meets(region)) return false;
                if (!bitmap) return true;
                const auto lo = cell(b.lo), hi = cell(b.hi);
                for (std::int64_t z = lo[2] / 4; z <= hi[2] / 4; ++z)
                    for (std::int64_t y = lo[1] / 4; y <= hi[1] / 4; ++y)
                        for (std::int64_t x = lo[0] / 4; x <= hi[0] / 4; ++x) {
                            const std::size_t q = std::size_t(x + blocks[0] * (y + blocks[1] * z));
                            if (blocked[q / 64] >> (q % 64) & 1) return true;
                        }
                return false;
            };
            const std::vector<std::uint32_t> near = tbb::parallel_reduce(
                tbb::blocked_range<std::size_t>(0, F, 4096), std::vector<std::uint32_t>(),
                [&](const auto& r, std::vector<std::uint32_t> found) {
                    for (std::size_t f = r.begin(); f != r.end(); ++f) {
                        const Box3 b = cut_of[f] >= 0 ? reach_of(std::size_t(cut_of[f])) : box_of(T[f]);
                        if (in_blocks(b) && each_cell(b, [&](std::uint64_t k) { return std::binary_search(reached.begin(), reached.end(), k); }))
                            found.push_back(std::uint32_t(f));
                    }
                    return found;
                },
                concat<std::uint32_t>);
            // Each near triangle's pieces (or itself) against the rims' pieces in the cells its box reaches.
            std::vector<std::uint32_t> found_rims = tbb::parallel_reduce(
                tbb::blocked_range<std::size_t>(0, near.size(), 64), std::vector<std::uint32_t>(),
                [&](const auto& r, std::vector<std::uint32_t> found) {
                    std::vector<std::array<Corner, 3>> mine;
                    for (std::size_t q = r.begin(); q != r.end(); ++q) {
                        const std::uint32_t f = near[q];
                        mine.clear();
                        if (cut_of[f] >= 0) pieces_of(std::size_t(cut_of[f]), mine);
                        else mine.push_back(T[f]);
                        for (const auto& o : mine) {
                            const Box3 b = box_of(o);
                            each_cell(b, [&](std::uint64_t k) {
                                auto it = std::lower_bound(filed.begin(), filed.end(), std::pair<std::uint64_t, std::uint32_t>(k, 0));
                                for (; it != filed.end() && it->first == k; ++it) {
                                    const auto& p = rim_pieces[it->second];
                                    const std::uint32_t rim = rim_of[it->second];
                                    if (std::uint32_t(cut[rims[rim]].first) != f && b.meets(box_of(p)) && triangles_cross(position, p, o)) found.push_back(rim);
                                }
                                return false;
                            });
                        }
                    }
                    return found;
                },
                concat<std::uint32_t>);
            std::sort(found_rims.begin(), found_rims.end());
            found_rims.erase(std::unique(found_rims.begin(), found_rims.end()), found_rims.end());
            std::vector<std::size_t> crossing;
            for (const std::uint32_t q : found_rims) crossing.push_back(rims[q]);
            if (crossing.empty()) break;
            std::vector<std::int32_t> given_up;
            for (const std::size_t c : crossing) {
                const bool rim = on_rim(c);
                for (const auto i : cut[c].second)
                    if (on(i) && (splits[std::size_t(i)].rim || !rim)) split[std::size_t(i)] = 0, given_up.push_back(i);
            }
            fold_test = beside(given_up);
        }
        // New vertices in edge order; each cut triangle's first piece in its place, the others at the end.
        std::vector<std::int32_t> id(splits.size(), -1);
        for (std::size_t i = 0; i < splits.size(); ++i)
            if (split[i]) {
                id[i] = std::int32_t(P.size()), P.push_back(splits[i].at), sources.push_back(splits[i].source);
                if (home) home->push_back(0.5 * ((*home)[splits[i].edge >> 32] + (*home)[splits[i].edge & 0xffffffffu]));
            }
        if (P.size() == n) break;
        added += P.size() - n;
        output.triangles.reserve(F + 3 * (P.size() - n)); // a split edge adds a piece to each of its two triangles
        std::vector<std::array<Corner, 3>> parts;
        for (std::size_t c = 0; c < cut.size(); ++c) {
            parts.clear();
            pieces_of(c, parts);
            auto vertex = [&](Corner x) { return x >= 0 ? x : id[std::size_t(-x - 1)]; };
            for (std::size_t p = 0; p < parts.size(); ++p) {
                const std::array<std::int32_t, 3> t{vertex(parts[p][0]), vertex(parts[p][1]), vertex(parts[p][2])};
                if (p == 0) output.triangles[std::size_t(cut[c].first)] = t;
                else output.triangles.push_back(t);
            }
        }
    }
    const std::vector<std::int32_t> left = std::move(first.left);
    first = Sheets{}; // step 6 needs neither (6 MB at 256 off the peak)
    if (refine.rounds > 0) {
        const std::vector<FeaturePoint> points = feature_points(surface, steps, h);
        std::vector<char> settled(points.size(), 0);
        OutputIndex index(output, h);
        for (int round = 0; round < kInsertRounds; ++round) {
            const std::size_t more = insert_points(output, sources, surface, steps, points, settled, chord, kCornerReach * h, index, home);
            added += more;
            if (more == 0) break;
            if (round + 1 >= kInsertRoundsAlways && std::count(settled.begin(), settled.end(), 0) > kLatePassPoints) break;
        }
        join_creases(output, sources, surface, steps, index, home, h, chord);
        // Steps 7b and 8 in turn: the flips around a vertex that could not move may let it move next time.
        const std::vector<Eigen::Vector3d> target = targets_again(output, sources, surface, steps, left, max_move);
        std::size_t again = 0;
        std::vector<std::uint32_t> watch; // where step 9 looks: steep_sides as step 8 first saw them, and those moved since
        for (int round = 0; round < kAgainRounds; ++round) {
            const std::size_t was = again;
            const std::vector<std::uint32_t> moved = snap_again(output, sources, surface, steps, left, target, index, h, again);
            if (round > 0 && again == was) break;
            // The first round looks at the whole output; later ones around the vertices the last one moved.
            if (round == 0) watch = steep_sides(output, index);
            else watch.insert(watch.end(), moved.begin(), moved.end());
            flip_to_normals(output, sources, surface, steps, index, home, h, round == 0 ? &watch : &moved);
            if (again == was) break;
        }
        std::sort(watch.begin(), watch.end());
        watch.erase(std::unique(watch.begin(), watch.end()), watch.end());
        // Step 9, the first pass over `watch`, later ones over the triangles around those the last moved.
        std::vector<std::uint32_t> unfolded;
        for (int pass = 0; pass < kUnfoldPasses; ++pass) {
            std::vector<std::uint32_t> around;
            for (const std::uint32_t f : unfolded)
                for (const std::int32_t c : output.triangles[f]) {
                    const auto [begin, end] = index.ring(std::size_t(c));
                    around.insert(around.end(), begin, end);
                }
            std::sort(around.begin(), around.end());
            around.erase(std::unique(around.begin(), around.end()), around.end());
            unfolded = unfold(output, sources, surface, steps, index, h, max_move, pass == 0 ? watch : around);
            if (unfolded.empty()) break;
        }
        if (snapped_again) *snapped_again = again;
    }
    return added;
}

/// The output's triangles filed for finding the pairs that cross (put_back_crossings): each under every row of
/// cells a voxel square, running along x, that the box of its corners meets, where they are and at home, sorted
/// in each row by where that box begins along x. Corners put back stay in those boxes, so one filing serves every
/// pass.
class CrossingIndex {
public:
    using Pair = std::pair<std::uint32_t, std::uint32_t>;
    /// Only the triangles `searched` lists are filed, all when it is empty.
    CrossingIndex(const TriangleMesh& output, const std::vector<Eigen::Vector3d>& home, const std::vector<std::uint8_t>& searched, double h)
        : T_(output.triangles), P_(output.vertices), home_(home) {
        const auto& P = output.vertices;
        const std::size_t F = T_.size();
        Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
        for (std::size_t v = 0; v < P.size(); ++v) lo = lo.cwiseMin(P[v]).cwiseMin(home[v]), hi = hi.cwiseMax(P[v]).cwiseMax(home[v]);
        // Cells a voxel wide, unless there would be more than 60,000 a side or 4 million rows (a mesh far larger
        // than its voxmap: the cells then grow).
        const Eigen::Vector3d extent = (hi - lo).cwiseMax(0.0);
        const double cell = std::max({h, extent.y() / 60000, extent.z() / 60000, std::sqrt(extent.y() * extent.z() / 4e6)}) * (1 + 1e-9);
        ny_ = std::size_t(extent.y() / cell) + 1;
        const std::size_t nz = std::size_t(extent.z() / cell) + 1;
        low_ = lo, cell_ = cell;
        // Counted into rows, filed by atomic slots, each row then sorted: no sort of the whole, and no array per
        // triangle (the ranges are worked out again: at 256, fresh pages for one cost more than the arithmetic).
        std::vector<std::atomic<std::uint32_t>> count(ny_ * nz + 1);
        lo_ = std::make_unique_for_overwrite<std::array<std::uint16_t, 2>[]>(F);
        widest_ = tbb::parallel_reduce(
            tbb::blocked_range<std::size_t>(0, F, 4096), 0.0f,
            [&](const auto& r, float widest) {
                for (std::size_t f = r.begin(); f != r.end(); ++f) {
                    if (!searched.empty() && !searched[f]) continue;
                    const Range g = range(std::uint32_t(f));
                    lo_[f] = g.lo;
                    widest = std::max(widest, g.x1 - g.x0);
                    each_row(g, [&](std::size_t row) { count[row + 1].fetch_add(1, std::memory_order_relaxed); });
                }
                return widest;
            },
            [](float a, float b) { return std::max(a, b); });
        start_.resize(count.size());
        start_[0] = 0;
        for (std::size_t k = 1; k < count.size(); ++k) start_[k] = start_[k - 1] + count[k].load(std::memory_order_relaxed);
        for (std::size_t k = 0; k + 1 < count.size(); ++k) count[k].store(start_[k], std::memory_order_relaxed);
        entries_ = std::make_unique_for_overwrite<Entry[]>(start_.back());
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, F, 4096), [&](const auto& r) {
            for (std::size_t f = r.begin(); f != r.end(); ++f) {
                if (!searched.empty() && !searched[f]) continue;
                const Range g = range(std::uint32_t(f));
                each_row(g, [&](std::size_t row) { entries_[count[row].fetch_add(1, std::memory_order_relaxed)] = {std::uint32_t(f), g.x0}; });
            }
        });
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, start_.size() - 1, 256), [&](const auto& r) {
            for (std::size_t row = r.begin(); row != r.end(); ++row)
                std::sort(entries_.get() + start_[row], entries_.get() + start_[row + 1], [](const Entry& a, const Entry& b) { return a.x0 < b.x0 || (a.x0 == b.x0 && a.f < b.f); });
        });
    }

    /// The pairs that cross by snapping's test (each passes through the other's plane by more than `depth`, and a
    /// side of one through the other), each once, lower triangle first, sorted; with `marked`, only the pairs with
    /// a triangle it lists.
    std::vector<Pair> crossing(const std::vector<Eigen::Vector3d>& P, double depth, const std::vector<std::uint32_t>* marked) const {
        auto pos = [&](std::int32_t i) -> const Eigen::Vector3d& { return P[std::size_t(i)]; };
        // A pair is tested in the one row both are filed under whose (y, z) is the least corner of their boxes'
        // meeting.
        auto canonical = [&](std::size_t row, const std::array<std::uint16_t, 2>& a, const std::array<std::uint16_t, 2>& b) {
            return row == std::size_t(std::max(a[0], b[0])) + ny_ * std::max(a[1], b[1]);
        };
        std::vector<Pair> pairs;
        if (!marked) {
            // Row by row, each triangle's corners, box and unit normal worked out once into a small buffer: most
            // pairs are then settled by their boxes or planes without a look at the mesh.
            struct Near {
                std::array<Eigen::Vector3d, 3> v;
                Eigen::Vector3d lo, hi, n; ///< n: zero where the triangle has no area
                std::array<std::uint16_t, 2> cell; ///< Range::lo
            };
            auto through = [](const Near& a, const Near& b) { return internal::straddle_depth(a.v[0], a.v[1], a.v[2], b.v[0], b.n, 1.0); };
            tbb::enumerable_thread_specific<std::vector<Near>> buffers;
            pairs = tbb::parallel_reduce(
                tbb::blocked_range<std::size_t>(0, start_.size() - 1, 256), std::vector<Pair>(),
                [&](const auto& r, std::vector<Pair> found) {
                    std::vector<Near>& near = buffers.local();
                    for (std::size_t row = r.begin(); row != r.end(); ++row) {
                        const Entry* e = entries_.get() + start_[row];
                        const std::size_t count = start_[row + 1] - start_[row];
                        if (count < 2) continue;
                        near.resize(count);
                        for (std::size_t i = 0; i < count; ++i) {
                            Near& q = near[i];
                            for (int k = 0; k < 3; ++k) q.v[std::size_t(k)] = P[std::size_t(T_[e[i].f][std::size_t(k)])];
                            q.lo = q.v[0].cwiseMin(q.v[1]).cwiseMin(q.v[2]), q.hi = q.v[0].cwiseMax(q.v[1]).cwiseMax(q.v[2]);
                            q.n = (q.v[1] - q.v[0]).cross(q.v[2] - q.v[0]);
                            const double length = q.n.norm();
                            q.n = length > 0 ? Eigen::Vector3d(q.n / length) : Eigen::Vector3d::Zero();
                            q.cell = lo_[e[i].f];
                        }
                        // A box as filed begins no later than its corners' box now: past the end of this one's, no
                        // box met later in the row meets it.
                        for (std::size_t i = 0; i < count; ++i)
                            for (std::size_t j = i + 1; j < count && double(e[j].x0) <= near[i].hi.x() - low_.x(); ++j) {
                                const Near &a = near[i], &b = near[j];
                                if (!canonical(row, a.cell, b.cell)) continue;
                                if ((a.lo.array() > b.hi.array()).any() || (b.lo.array() > a.hi.array()).any()) continue;
                                if (through(a, b) > depth && through(b, a) > depth && triangles_cross(pos, T_[e[i].f], T_[e[j].f]))
                                    found.push_back({std::min(e[i].f, e[j].f), std::max(e[i].f, e[j].f)});
                            }
                    }
                    return found;
                },
                concat<Pair>);
        } else {
            auto straddles = [&](const std::array<std::int32_t, 3>& a, const std::array<std::int32_t, 3>& plane) {
                return internal::straddle_depth(pos(a[0]), pos(a[1]), pos(a[2]), pos(plane[0]), pos(plane[1]), pos(plane[2])) > depth;
            };
            for (const std::uint32_t f : *marked) {
                const Range a = range(f);
                each_row(a, [&](std::size_t row) {
                    const Entry* first = entries_.get() + start_[row];
                    const Entry* last = entries_.get() + start_[row + 1];
                    const float from = a.x0 - widest_;
                    for (const Entry* e = std::lower_bound(first, last, from, [](const Entry& x, float y) { return x.x0 < y; }); e != last && e->x0 <= a.x1; ++e) {
                        if (e->f == f || !canonical(row, a.lo, lo_[e->f])) continue;
                        const auto &s = T_[f], &t = T_[e->f];
                        if (straddles(s, t) && straddles(t, s) && triangles_cross(pos, s, t)) pairs.push_back({std::min(f, e->f), std::max(f, e->f)});
                    }
                });
            }
        }
        std::sort(pairs.begin(), pairs.end());
        pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
        return pairs;
    }

private:
    struct Range {
        float x0, x1;                        ///< along x, from low_, rounded outward
        std::array<std::uint16_t, 2> lo, hi; ///< cells along y and z
    };
    struct Entry {
        std::uint32_t f;
        float x0; ///< Range::x0
    };
    /// Triangle f's box over its corners where they are and at home.
    Range range(std::uint32_t f) const {
        Eigen::Vector3d l = P_[std::size_t(T_[f][0])], u = l;
        for (const auto v : T_[f]) l = l.cwiseMin(P_[std::size_t(v)]).cwiseMin(home_[std::size_t(v)]), u = u.cwiseMax(P_[std::size_t(v)]).cwiseMax(home_[std::size_t(v)]);
        auto at = [&](double x, int a) { return std::uint16_t(std::clamp(std::floor((x - low_[a]) / cell_), 0.0, 65535.0)); };
        return {outward(l.x() - low_.x(), -1), outward(u.x() - low_.x(), 1), {at(l.y(), 1), at(l.z(), 2)}, {at(u.y(), 1), at(u.z(), 2)}};
    }
    /// x as a float on the side `sign` of it.
    static float outward(double x, int sign) {
        float f = float(x);
        if (sign < 0 ? double(f) > x : double(f) < x) f = std::nextafter(f, sign < 0 ? -std::numeric_limits<float>::infinity() : std::numeric_limits<float>::infinity());
        return f;
    }
    template <class Visit>
    void each_row(const Range& g, const Visit& visit) const {
        for (std::size_t z = g.lo[1]; z <= g.hi[1]; ++z)
            for (std::size_t y = g.lo[0]; y <= g.hi[0]; ++y) visit(y + ny_ * z);
    }
    const std::vector<std::array<std::int32_t, 3>>& T_;
    const std::vector<Eigen::Vector3d>& P_; ///< where the corners are as filed, and ...
    const std::vector<Eigen::Vector3d>& home_; ///< ... where they are put back to
    Eigen::Vector3d low_ = Eigen::Vector3d::Zero();
    double cell_ = 1;
    std::size_t ny_ = 1;
    float widest_ = 0; ///< the widest box along x
    std::vector<std::uint32_t> start_;
    std::unique_ptr<Entry[]> entries_;
    std::unique_ptr<std::array<std::uint16_t, 2>[]> lo_; ///< per triangle, Range::lo
};

/// Per triangle, whether a corner of it at `home` lies within 3 voxels of one of the points `near` (a flag each;
/// empty when `near` is): cells 3 voxels wide, a bit each, those around a point's cell marked.
std::vector<std::uint8_t> triangles_near(const std::vector<std::array<std::int32_t, 3>>& T, const std::vector<Eigen::Vector3d>& home,
                                         const std::vector<Eigen::Vector3d>& near, double h) {
    if (near.empty() || home.empty()) return {};
    Eigen::Vector3d lo = home[0], hi = home[0];
    for (const auto& p : home) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
    // A mesh far larger than its voxels (which the cap of 2^27 cells keeps to 16 MiB of bits) gets wider cells.
    const Eigen::Vector3d extent = (hi - lo).cwiseMax(0.0);
    const double side = std::max(3 * h, std::cbrt(extent.prod() / double(std::uint64_t(1) << 27))) * (1 + 1e-9);
    const std::array<std::int64_t, 3> n{std::int64_t(extent.x() / side) + 1, std::int64_t(extent.y() / side) + 1, std::int64_t(extent.z() / side) + 1};
    auto cell = [&](const Eigen::Vector3d& p, int a) { return std::int64_t(std::floor((p[a] - lo[a]) / side)); };
    std::vector<std::uint64_t> bits(std::size_t((n[0] * n[1] * n[2] + 63) / 64), 0);
    for (const auto& p : near) {
        const std::array<std::int64_t, 3> c{cell(p, 0), cell(p, 1), cell(p, 2)};
        for (std::int64_t z = std::max<std::int64_t>(0, c[2] - 1); z <= std::min(n[2] - 1, c[2] + 1); ++z)
            for (std::int64_t y = std::max<std::int64_t>(0, c[1] - 1); y <= std::min(n[1] - 1, c[1] + 1); ++y)
                for (std::int64_t x = std::max<std::int64_t>(0, c[0] - 1); x <= std::min(n[0] - 1, c[0] + 1); ++x) {
                    const std::uint64_t b = std::uint64_t(x + n[0] * (y + n[1] * z));
                    bits[b / 64] |= std::uint64_t(1) << (b % 64);
                }
    }
    std::vector<std::uint8_t> close(home.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, home.size(), 4096), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) {
            const std::uint64_t b = std::uint64_t(cell(home[v], 0) + n[0] * (cell(home[v], 1) + n[1] * cell(home[v], 2)));
            close[v] = std::uint8_t(bits[b / 64] >> (b % 64) & 1);
        }
    });
    std::vector<std::uint8_t> searched(T.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, T.size(), 4096), [&](const auto& r) {
        for (std::size_t f = r.begin(); f != r.end(); ++f) searched[f] = close[std::size_t(T[f][0])] | close[std::size_t(T[f][1])] | close[std::size_t(T[f][2])];
    });
    return searched;
}

/// Passes of put_back_crossings that put back one corner of each crossing pair.
constexpr int kFarthestPasses = 16;

/// Puts back `home` (where extraction made it; a refined vertex on the triangle it split there) the corner that
/// moved farthest of each pair of triangles that cross, pass by pass until none crosses: at home the output is the
/// extracted surface, subdivided, which crosses nowhere. Putting back all six corners of a pair at once took about
/// twice as many vertices off the exact surface (bunny ear edit at 128: 23 against 12; the snowden scan: 277
/// against 199). After kFarthestPasses passes (the bundled edits need at most 8) every corner of a pair still
/// crossing goes back, so that no output needs many more. Returns the vertices put back.
std::size_t put_back_crossings(TriangleMesh& output, const std::vector<Eigen::Vector3d>& home, const std::vector<Eigen::Vector3d>& near, double h) {
    auto& P = output.vertices;
    const auto& T = output.triangles;
    if (T.size() < 2) return 0;
    const CrossingIndex index(output, home, triangles_near(T, home, near, h), h);
    std::size_t back = 0;
    std::vector<char> moved(P.size(), 0);
    std::vector<std::uint32_t> marked; // after the first pass, the triangles around a vertex put back
    for (int pass = 0;; ++pass) {
        const auto pairs = index.crossing(P, kCrossDepth * h, pass == 0 ? nullptr : &marked);
        bool any = false;
        auto put_back = [&](std::int32_t v) { P[std::size_t(v)] = home[std::size_t(v)], moved[std::size_t(v)] = 1, any = true, ++back; };
        for (const auto& [f, g] : pairs) {
            std::int32_t far = -1; // the corner moved farthest, still away from home
            double most = 0;
            for (const std::uint32_t t : {f, g})
                for (const std::int32_t v : T[t])
                    if (const double d = (P[std::size_t(v)] - home[std::size_t(v)]).squaredNorm(); d > most) {
                        if (pass >= kFarthestPasses) put_back(v);
                        else most = d, far = v;
                    }
            if (far >= 0) put_back(far);
        }
        if (!any) break;
        marked.clear();
        for (std::size_t f = 0; f < T.size(); ++f)
            if (moved[std::size_t(T[f][0])] || moved[std::size_t(T[f][1])] || moved[std::size_t(T[f][2])]) marked.push_back(std::uint32_t(f));
        std::fill(moved.begin(), moved.end(), 0);
    }
    return back;
}

} // namespace

std::size_t refine_to_sources(TriangleMesh& output, std::vector<SourcePoint>& sources, const SourceSurface& input, const std::vector<WarpStep>& steps,
                              const SnapOptions& options, const RefineOptions& refine_options) {
    return refine_with(output, sources, input, steps, options, refine_options, {});
}

SnapReport snap_and_refine(TriangleMesh& output, const SourceSurface& input, const std::vector<WarpStep>& steps, std::vector<SourcePoint>& sources,
                           const SnapOptions& options, const RefineOptions& refine_options) {
    Sheets sheets;
    std::vector<Eigen::Vector3d> normal;
    if (sources.empty() && !output.vertices.empty()) {
        normal = vertex_normals(output);
        sources = find_sources(output, input, steps, options, normal);
    }
    std::vector<Eigen::Vector3d> home;
    if (refine_options.put_back_crossings && output.quads.empty()) home = output.vertices;
    SnapReport report = snap(output, input.mesh(), steps, sources, options, &sheets, std::move(normal));
    std::size_t again = 0;
    report.refined = refine_with(output, sources, input, steps, options, refine_options, std::move(sheets), home.empty() ? nullptr : &home, &again);
    report.snapped += report.refined + again;
    report.unsnapped -= std::min(report.unsnapped, again);
    if (!home.empty()) {
        report.put_back = put_back_crossings(output, home, refine_options.crossings_near, options.voxel_size);
        report.snapped -= std::min(report.snapped, report.put_back);
        report.unsnapped += report.put_back;
    }
    return report;
}

} // namespace voxwarp
