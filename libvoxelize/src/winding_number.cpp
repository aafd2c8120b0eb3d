#include <voxwarp/winding_number.h>
#include <voxwarp_internal/geometry.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>

namespace voxwarp {

struct WindingNumber::Tree {
    struct Node {
        Eigen::Vector3d centre = Eigen::Vector3d::Zero();      // area-weighted centroid of the cluster
        Eigen::Vector3d area_normal = Eigen::Vector3d::Zero(); // sum of area * unit normal (= half cross products)
        Eigen::Matrix3d second = Eigen::Matrix3d::Zero();      // sum of area_normal_t (centroid_t - centre)^T, the second-order moment
        double radius = 0;           // farthest triangle vertex from centre
        Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero(); // the triangles' bounding box, for segment queries
        std::int32_t first = 0, count = 0; // leaf: range in `order`
        std::int32_t left = -1, right = -1;
    };
    std::vector<Eigen::Vector3d> a, b, c; // triangle corners, in `order`
    std::vector<Node> nodes;
    double beta = 3.0;

    static double solid_angle(const Eigen::Vector3d& A, const Eigen::Vector3d& B, const Eigen::Vector3d& C) {
        // Van Oosterom & Strackee (1983): tan(Omega / 2) = det[A B C] / (|A||B||C| + (A.B)|C| + (B.C)|A| + (C.A)|B|)
        const double la = A.norm(), lb = B.norm(), lc = C.norm();
        const double det = A.dot(B.cross(C));
        const double den = la * lb * lc + A.dot(B) * lc + B.dot(C) * la + C.dot(A) * lb;
        return 2.0 * std::atan2(det, den);
    }
};

WindingNumber::WindingNumber(const TriangleMesh& mesh, double beta) : tree_(std::make_unique<Tree>()) {
    auto& t = *tree_;
    t.beta = beta;
    const std::size_t n = mesh.triangles.size();
    std::vector<std::int32_t> order(n);
    std::iota(order.begin(), order.end(), 0);
    std::vector<Eigen::Vector3d> centroid(n);
    for (std::size_t i = 0; i < n; ++i) {
        const auto& tri = mesh.triangles[i];
        centroid[i] = (mesh.vertices[tri[0]] + mesh.vertices[tri[1]] + mesh.vertices[tri[2]]) / 3.0;
    }
    constexpr std::int32_t leaf_size = 8;
    t.nodes.reserve(2 * n / leaf_size + 2);
    // Median split on the longest axis of the centroids' bounds; iterative to keep the stack flat.
    struct Job {
        std::int32_t node, first, count;
    };
    std::vector<Job> jobs;
    t.nodes.push_back({});
    jobs.push_back({0, 0, std::int32_t(n)});
    while (!jobs.empty()) {
        const Job job = jobs.back();
        jobs.pop_back();
        Eigen::Vector3d area_normal = Eigen::Vector3d::Zero(), weighted = Eigen::Vector3d::Zero();
        double area_sum = 0;
        Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
        for (std::int32_t i = job.first; i < job.first + job.count; ++i) {
            const auto& tri = mesh.triangles[order[i]];
            const Eigen::Vector3d cr = (mesh.vertices[tri[1]] - mesh.vertices[tri[0]]).cross(mesh.vertices[tri[2]] - mesh.vertices[tri[0]]);
            const double area = 0.5 * cr.norm();
            area_normal += 0.5 * cr;
            weighted += area * centroid[order[i]];
            area_sum += area;
            lo = lo.cwiseMin(centroid[order[i]]);
            hi = hi.cwiseMax(centroid[order[i]]);
        }
        Eigen::Vector3d centre = area_sum > 0 ? Eigen::Vector3d(weighted / area_sum) : Eigen::Vector3d(0.5 * (lo + hi));
        double radius = 0;
        Eigen::Vector3d box_lo = Eigen::Vector3d::Constant(1e300), box_hi = -box_lo;
        Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
        for (std::int32_t i = job.first; i < job.first + job.count; ++i) {
            const auto& tri = mesh.triangles[order[i]];
            for (int k = 0; k < 3; ++k) {
                radius = std::max(radius, (mesh.vertices[tri[k]] - centre).norm());
                box_lo = box_lo.cwiseMin(mesh.vertices[tri[k]]), box_hi = box_hi.cwiseMax(mesh.vertices[tri[k]]);
            }
            const Eigen::Vector3d half_cross =
                0.5 * (mesh.vertices[tri[1]] - mesh.vertices[tri[0]]).cross(mesh.vertices[tri[2]] - mesh.vertices[tri[0]]);
            second += half_cross * (centroid[order[i]] - centre).transpose();
        }
        auto& node = t.nodes[std::size_t(job.node)];
        node.centre = centre;
        node.area_normal = area_normal;
        node.second = second;
        node.radius = radius;
        node.lo = box_lo, node.hi = box_hi;
        node.first = job.first;
        node.count = job.count;
        if (job.count <= leaf_size) continue;
        int axis;
        (hi - lo).maxCoeff(&axis);
        const std::int32_t half = job.count / 2;
        std::nth_element(order.begin() + job.first, order.begin() + job.first + half, order.begin() + job.first + job.count,
                         [&](std::int32_t x, std::int32_t y) { return centroid[x][axis] < centroid[y][axis]; });
        const auto left = std::int32_t(t.nodes.size());
        t.nodes.push_back({});
        t.nodes.push_back({});
        t.nodes[std::size_t(job.node)].left = left;
        t.nodes[std::size_t(job.node)].right = left + 1;
        jobs.push_back({left, job.first, half});
        jobs.push_back({left + 1, job.first + half, job.count - half});
    }
    t.a.resize(n), t.b.resize(n), t.c.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        const auto& tri = mesh.triangles[order[i]];
        t.a[i] = mesh.vertices[tri[0]], t.b[i] = mesh.vertices[tri[1]], t.c[i] = mesh.vertices[tri[2]];
    }
}

WindingNumber::~WindingNumber() = default;
WindingNumber::WindingNumber(WindingNumber&&) noexcept = default;
WindingNumber& WindingNumber::operator=(WindingNumber&&) noexcept = default;

double WindingNumber::operator()(const Eigen::Vector3d& q) const {
    const auto& t = *tree_;
    if (t.nodes.empty() || t.a.empty()) return 0.0;
    double omega = 0;
    std::int32_t stack[128];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
        const auto& node = t.nodes[std::size_t(stack[--top])];
        const Eigen::Vector3d d = node.centre - q;
        const double dist = d.norm();
        if (dist > t.beta * node.radius) {
            // Far field: the solid angle of a patch at x is A . f(x) with f(x) = (x - q) / |x - q|^3. Expanding f
            // to first order about the centre gives the dipole term plus trace(J M), J = I/|d|^3 - 3 d d^T/|d|^5.
            const double inv3 = 1.0 / (dist * dist * dist), inv5 = inv3 / (dist * dist);
            omega += node.area_normal.dot(d) * inv3 - node.second.trace() * inv3 + 3.0 * d.dot(node.second * d) * inv5;
        } else if (node.left < 0 || top + 2 > 128) {
            for (std::int32_t i = node.first; i < node.first + node.count; ++i)
                omega += Tree::solid_angle(t.a[i] - q, t.b[i] - q, t.c[i] - q);
        } else {
            stack[top++] = node.left;
            stack[top++] = node.right;
        }
    }
    return omega / (4.0 * std::numbers::pi);
}

double WindingNumber::exact(const Eigen::Vector3d& q) const {
    const auto& t = *tree_;
    double omega = 0;
    for (std::size_t i = 0; i < t.a.size(); ++i) omega += Tree::solid_angle(t.a[i] - q, t.b[i] - q, t.c[i] - q);
    return omega / (4.0 * std::numbers::pi);
}

WindingNumber::Crossings WindingNumber::crossings(const Eigen::Vector3d& p, const Eigen::Vector3d& q) const {
    const auto& tree = *tree_;
    Crossings result;
    if (tree.nodes.empty() || tree.a.empty()) return result;
    const Eigen::Vector3d d = q - p;
    result.first = 2.0;
    std::int32_t stack[128];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
        const auto& node = tree.nodes[std::size_t(stack[--top])];
        // The segment against the cluster's bounding box (slabs), padded by a hair for rounding.
        double enter = 0, leave = 1;
        for (int a = 0; a < 3 && enter <= leave; ++a) {
            const double pad = 1e-9 * (std::abs(node.lo[a]) + std::abs(node.hi[a]) + 1);
            const double lo = node.lo[a] - pad - p[a], hi = node.hi[a] + pad - p[a];
            if (d[a] == 0) {
                if (lo > 0 || hi < 0) leave = -1;
                continue;
            }
            const double t0 = lo / d[a], t1 = hi / d[a];
            enter = std::max(enter, std::min(t0, t1)), leave = std::min(leave, std::max(t0, t1));
        }
        if (enter > leave) continue;
        if (node.left < 0 || top + 2 > 128) {
            for (std::int32_t i = node.first; i < node.first + node.count; ++i) {
                const double u = internal::line_meets_triangle(p, d, tree.a[i], tree.b[i], tree.c[i]); // p + u d
                if (!(u >= 0 && u <= 1)) continue;
                ++result.count;
                result.first = std::min(result.first, u);
                result.last = std::max(result.last, u);
            }
        } else {
            stack[top++] = node.left;
            stack[top++] = node.right;
        }
    }
    if (result.count == 0) result.first = 0;
    return result;
}

} // namespace voxwarp
