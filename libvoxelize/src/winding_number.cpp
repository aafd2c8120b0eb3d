#include <voxwarp/winding_number.h>
#include <voxwarp_internal/geometry.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>

namespace voxwarp {

struct WindingNumber::Tree {
    /// What a query's descent reads at every node, in one 48-byte record; the far field's moments and the box
    /// (segment queries) are kept apart, read only where used (a query visits hundreds of nodes, so the records'
    /// cache lines were a third of its time).
    struct Node {
        Eigen::Vector3d centre = Eigen::Vector3d::Zero(); // area-weighted centroid of the cluster
        double radius = 0;                                // farthest triangle vertex from centre
        std::int32_t first = 0, count = 0;                // leaf: range in `order`
        std::int32_t left = -1, right = -1;
    };
    /// The far field of a cluster: sum of area * unit normal (= half cross products), and of the second-order
    /// moment M = sum area_normal_t (centroid_t - centre)^T, its trace and the symmetric part that d^T M d reads
    /// (xx, yy, zz, then xy + yx, xz + zx, yz + zy).
    struct Far {
        Eigen::Vector3d area_normal = Eigen::Vector3d::Zero();
        double trace = 0;
        double m[6] = {0, 0, 0, 0, 0, 0};
    };
    struct Bounds {
        Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero(); // the triangles' bounding box
    };
    static constexpr std::int32_t kLeafSize = 8;
    std::size_t triangles = 0;
    std::vector<double> corners; // the triangles' corners, in `order`, as nine arrays: the first corners' x, y, z, then the second's, the third's
    std::vector<Node> nodes;
    std::vector<Far> far;       // per node
    std::vector<Bounds> boxes;  // per node
    double beta = 3.0;

    /// Corner k (0, 1, 2) of triangle i.
    Eigen::Vector3d corner(std::size_t i, int k) const {
        const double* x = corners.data() + 3 * std::size_t(k) * triangles + i;
        return {x[0], x[triangles], x[2 * triangles]};
    }

    static double solid_angle(const Eigen::Vector3d& A, const Eigen::Vector3d& B, const Eigen::Vector3d& C) {
        // Van Oosterom & Strackee (1983): tan(Omega / 2) = det[A B C] / (|A||B||C| + (A.B)|C| + (B.C)|A| + (C.A)|B|)
        const double la = A.norm(), lb = B.norm(), lc = C.norm();
        const double det = A.dot(B.cross(C));
        const double den = la * lb * lc + A.dot(B) * lc + B.dot(C) * la + C.dot(A) * lb;
        return 2.0 * std::atan2(det, den);
    }

    /// A sum of solid_angle terms with one atan2 in all instead of one per triangle (that atan2 took a fifth of
    /// voxelizing a scan): each term is twice the argument of the complex number den + i det, so their sum is
    /// twice the argument of the product, plus the whole turns the product made about the origin. A factor with
    /// den > 0 turns the product by less than a quarter turn, so it can only pass the negative real axis from
    /// the second quadrant to the third (a turn more) or back (a turn less); those are counted. A triangle with
    /// den <= 0 (seen from nearer than its own size, or degenerate) is summed by its own atan2.
    struct AngleSum {
        double re = 1, im = 0, separate = 0;
        int turns = 0;
        void add(double det, double den) {
            if (!(den > 0)) {
                separate += 2.0 * std::atan2(det, den);
                return;
            }
            const double r = re * den - im * det, i = re * det + im * den;
            if (r < 0 && re < 0 && (i < 0) != (im < 0)) turns += im < 0 ? -1 : 1;
            re = r, im = i;
            // Keep the product's magnitude (a product of lengths cubed) inside the doubles' range; its argument
            // is all that counts.
            const double size = std::abs(re) + std::abs(im);
            if (size < 1e-100 || size > 1e100) re /= size, im /= size;
        }
        /// The sum; im + 0.0 makes a negative zero positive, the side `turns` counted it on.
        double total() const { return separate + 2.0 * (std::atan2(im + 0.0, re) + 2.0 * std::numbers::pi * turns); }
    };
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
    t.nodes.reserve(2 * n / Tree::kLeafSize + 2);
    // Median split on the longest axis of the centroids' bounds; iterative to keep the stack flat.
    struct Job {
        std::int32_t node, first, count;
    };
    std::vector<Job> jobs;
    t.far.reserve(t.nodes.capacity());
    t.boxes.reserve(t.nodes.capacity());
    t.nodes.push_back({});
    t.far.push_back({});
    t.boxes.push_back({});
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
        node.radius = radius;
        auto& f = t.far[std::size_t(job.node)];
        f.area_normal = area_normal;
        f.trace = second.trace();
        f.m[0] = second(0, 0), f.m[1] = second(1, 1), f.m[2] = second(2, 2);
        f.m[3] = second(0, 1) + second(1, 0), f.m[4] = second(0, 2) + second(2, 0), f.m[5] = second(1, 2) + second(2, 1);
        t.boxes[std::size_t(job.node)] = {box_lo, box_hi};
        node.first = job.first;
        node.count = job.count;
        if (job.count <= Tree::kLeafSize) continue;
        int axis;
        (hi - lo).maxCoeff(&axis);
        const std::int32_t half = job.count / 2;
        std::nth_element(order.begin() + job.first, order.begin() + job.first + half, order.begin() + job.first + job.count,
                         [&](std::int32_t x, std::int32_t y) { return centroid[x][axis] < centroid[y][axis]; });
        const auto left = std::int32_t(t.nodes.size());
        t.nodes.resize(t.nodes.size() + 2);
        t.far.resize(t.nodes.size());
        t.boxes.resize(t.nodes.size());
        t.nodes[std::size_t(job.node)].left = left;
        t.nodes[std::size_t(job.node)].right = left + 1;
        jobs.push_back({left, job.first, half});
        jobs.push_back({left + 1, job.first + half, job.count - half});
    }
    t.triangles = n;
    t.corners.resize(9 * n);
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t k = 0; k < 3; ++k)
            for (std::size_t axis = 0; axis < 3; ++axis) t.corners[(3 * k + axis) * n + i] = mesh.vertices[std::size_t(mesh.triangles[std::size_t(order[i])][k])][int(axis)];
}

WindingNumber::~WindingNumber() = default;
WindingNumber::WindingNumber(WindingNumber&&) noexcept = default;
WindingNumber& WindingNumber::operator=(WindingNumber&&) noexcept = default;

double WindingNumber::operator()(const Eigen::Vector3d& q) const {
    const auto& t = *tree_;
    if (t.nodes.empty() || t.triangles == 0) return 0.0;
    double omega = 0;
    Tree::AngleSum near;
    std::int32_t stack[128];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
        const std::int32_t id = stack[--top];
        const auto& node = t.nodes[std::size_t(id)];
        const Eigen::Vector3d d = node.centre - q;
        const double dist2 = d.squaredNorm(), reach = t.beta * node.radius;
        if (dist2 > reach * reach) {
            // Far field: the solid angle of a patch at x is A . f(x) with f(x) = (x - q) / |x - q|^3. Expanding f
            // to first order about the centre gives the dipole term plus trace(J M), J = I/|d|^3 - 3 d d^T/|d|^5.
            const auto& f = t.far[std::size_t(id)];
            const double inv3 = 1.0 / (dist2 * std::sqrt(dist2)), inv5 = inv3 / dist2;
            const double dMd = f.m[0] * d[0] * d[0] + f.m[1] * d[1] * d[1] + f.m[2] * d[2] * d[2] + f.m[3] * d[0] * d[1] + f.m[4] * d[0] * d[2] +
                               f.m[5] * d[1] * d[2];
            omega += (f.area_normal.dot(d) - f.trace) * inv3 + 3.0 * dMd * inv5;
        } else if (node.left < 0 || top + 2 > 128) {
            // solid_angle's two terms for the leaf's triangles (a node bigger than a leaf where the stack ran out: a
            // leaf's worth at a time), from their corners kept coordinate by coordinate (a loop the compiler runs two
            // triangles at a time), then multiplied in.
            const double* x = t.corners.data();
            const std::size_t m = t.triangles;
            for (std::int32_t first = node.first; first < node.first + node.count; first += Tree::kLeafSize) {
                double det[Tree::kLeafSize], den[Tree::kLeafSize];
                const std::int32_t n = std::min(node.first + node.count - first, Tree::kLeafSize);
                for (std::int32_t k = 0; k < n; ++k) {
                    const std::size_t i = std::size_t(first + k);
                    const double ax = x[i] - q[0], ay = x[m + i] - q[1], az = x[2 * m + i] - q[2];
                    const double bx = x[3 * m + i] - q[0], by = x[4 * m + i] - q[1], bz = x[5 * m + i] - q[2];
                    const double cx = x[6 * m + i] - q[0], cy = x[7 * m + i] - q[1], cz = x[8 * m + i] - q[2];
                    const double la = std::sqrt(ax * ax + ay * ay + az * az), lb = std::sqrt(bx * bx + by * by + bz * bz), lc = std::sqrt(cx * cx + cy * cy + cz * cz);
                    det[k] = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx);
                    den[k] = la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (bx * cx + by * cy + bz * cz) * la + (cx * ax + cy * ay + cz * az) * lb;
                }
                for (std::int32_t k = 0; k < n; ++k) near.add(det[k], den[k]);
            }
        } else {
            stack[top++] = node.left;
            stack[top++] = node.right;
        }
    }
    return (omega + near.total()) / (4.0 * std::numbers::pi);
}

double WindingNumber::exact(const Eigen::Vector3d& q) const {
    const auto& t = *tree_;
    double omega = 0;
    for (std::size_t i = 0; i < t.triangles; ++i) omega += Tree::solid_angle(t.corner(i, 0) - q, t.corner(i, 1) - q, t.corner(i, 2) - q);
    return omega / (4.0 * std::numbers::pi);
}

WindingNumber::Crossings WindingNumber::crossings(const Eigen::Vector3d& p, const Eigen::Vector3d& q) const {
    const auto& tree = *tree_;
    Crossings result;
    if (tree.nodes.empty() || tree.triangles == 0) return result;
    const Eigen::Vector3d d = q - p;
    result.first = 2.0;
    std::int32_t stack[128];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
        const std::int32_t id = stack[--top];
        const auto& node = tree.nodes[std::size_t(id)];
        const auto& box = tree.boxes[std::size_t(id)];
        // The segment against the cluster's bounding box (slabs), padded by a hair for rounding.
        double enter = 0, leave = 1;
        for (int a = 0; a < 3 && enter <= leave; ++a) {
            const double pad = 1e-9 * (std::abs(box.lo[a]) + std::abs(box.hi[a]) + 1);
            const double lo = box.lo[a] - pad - p[a], hi = box.hi[a] + pad - p[a];
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
                const double u = internal::line_meets_triangle(p, d, tree.corner(std::size_t(i), 0), tree.corner(std::size_t(i), 1), tree.corner(std::size_t(i), 2)); // p + u d
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
