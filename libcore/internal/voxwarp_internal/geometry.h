// Internal to voxwarp's libraries: small geometric and combinatorial pieces several of them need (no OpenVDB).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <numeric>
#include <vector>

namespace voxwarp::internal {

/// World units two points must keep apart to stay apart, and not turn about each other, once written as 32-bit floats
/// (PLY, STL, glTF) anywhere up to `largest` from the origin: eight float steps there (a float keeps 24 bits).
inline double float_gap(double largest) { return 8 * std::ldexp(largest, -24); }

/// The point of triangle abc nearest p, by the Voronoi region of p's projection (Ericson, Real-Time Collision
/// Detection 5.1.5). Also the tests' measure of which input faces lie near an output triangle.
inline Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return a;
    const Eigen::Vector3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return b;
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
    const Eigen::Vector3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return c;
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    const double denom = 1.0 / (va + vb + vc);
    return a + ab * (vb * denom) + ac * (vc * denom);
}

/// straddle_depth for the plane through p with normal n, `length` long (a unit normal: 1; a zero normal gives 0):
/// for callers that test one triangle's plane against many.
inline double straddle_depth(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& p,
                             const Eigen::Vector3d& n, double length) {
    double above = 0, below = 0;
    for (const Eigen::Vector3d* x : {&a, &b, &c}) {
        const double d = n.dot(*x - p) / length;
        above = std::max(above, d), below = std::min(below, d);
    }
    return std::min(above, -below);
}

/// How far triangle (a, b, c) passes through the plane of triangle (p, q, r) on its shallower side: the least of
/// its deepest corner above the plane and its deepest below (world units); 0 when it keeps to one side, or the
/// plane's triangle has no area. Two triangles cross deeper than `tiny` only where each passes through the other's
/// plane by more than that.
inline double straddle_depth(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& p,
                             const Eigen::Vector3d& q, const Eigen::Vector3d& r) {
    const Eigen::Vector3d n = (q - p).cross(r - p);
    const double length = n.norm();
    if (!(length > 0)) return 0;
    return straddle_depth(a, b, c, p, n, length);
}

/// Where the line o + t d meets triangle (a, b, c) (Moller & Trumbore): its parameter t, of either sign, or NaN
/// when it passes beside the triangle (barycentric coordinates outside [-slack, 1 + slack]) or runs parallel to
/// its plane, or the triangle is degenerate.
inline double line_meets_triangle(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                  const Eigen::Vector3d& c, double slack = 0) {
    const double miss = std::numeric_limits<double>::quiet_NaN();
    const Eigen::Vector3d e1 = b - a, e2 = c - a, p = d.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-300) return miss;
    const Eigen::Vector3d s = o - a;
    const double u = s.dot(p) / det;
    if (u < -slack || u > 1 + slack) return miss;
    const Eigen::Vector3d q = s.cross(e1);
    const double v = d.dot(q) / det;
    if (v < -slack || u + v > 1 + slack) return miss;
    return e2.dot(q) / det;
}

/// Disjoint sets over 0 .. n-1 (union-find with path halving). join(a, b) puts a's root under b's, so the roots,
/// and any order derived from them, follow from the order of the joins alone.
class DisjointSets {
public:
    explicit DisjointSets(std::size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), std::size_t(0)); }
    std::size_t find(std::size_t x) {
        while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];
        return x;
    }
    void join(std::size_t a, std::size_t b) { parent_[find(a)] = find(b); }

private:
    std::vector<std::size_t> parent_;
};

} // namespace voxwarp::internal
