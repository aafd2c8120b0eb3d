#include <voxwarp/basis.h>
#include <voxwarp/errors.h>
#include <voxwarp/lattice.h>

#include <Eigen/LU>

#include <cmath>

namespace voxwarp {

std::string to_string(Placement placement) { return placement == Placement::uniform ? "uniform" : "clamped"; }

Placement placement_from_string(const std::string& name) {
    if (name == "uniform") return Placement::uniform;
    if (name == "clamped") return Placement::clamped;
    throw InvalidInput("placement '" + name + "': expected \"uniform\" or \"clamped\"");
}

namespace {

void check_size(const std::array<int, 3>& size, int minimum) {
    for (int a = 0; a < 3; ++a)
        if (size[std::size_t(a)] < minimum || size[std::size_t(a)] > 1024)
            throw InvalidInput("lattice size " + std::to_string(size[std::size_t(a)]) + " along axis " + std::to_string(a) + " is outside [" +
                               std::to_string(minimum) + ", 1024]");
    const double count = double(size[0]) * size[1] * size[2];
    if (count > 16.0 * 1024 * 1024) throw InvalidInput("lattice of " + std::to_string(std::int64_t(count)) + " control points is more than 16 M");
}

/// Region index and local parameter for one axis; the closed far end belongs to the last region.
inline int region_of(double s, int regions, double& t) {
    int a = int(std::floor(s));
    if (a < 0) a = 0;
    if (a > regions - 1) a = regions - 1;
    t = s - a;
    return a;
}

using AxisBasis = std::array<std::array<double, 4>, 3>; // per axis, the four basis functions' values (or slopes)

/// Per axis: the region holding stu, the basis values at its local parameter and, when `slopes` is given, their
/// derivatives.
inline void basis_at(const std::array<int, 3>& size, const Eigen::Vector3d& stu, std::array<int, 3>& region, AxisBasis& values,
                     AxisBasis* slopes = nullptr, AxisBasis* curvatures = nullptr) {
    for (int a = 0; a < 3; ++a) {
        double t;
        region[std::size_t(a)] = region_of(stu[a], size[std::size_t(a)] - 3, t);
        values[std::size_t(a)] = cubic_basis(t);
        if (slopes) (*slopes)[std::size_t(a)] = cubic_basis_derivative(t);
        if (curvatures) (*curvatures)[std::size_t(a)] = cubic_basis_second_derivative(t);
    }
}

} // namespace

Lattice Lattice::uniform(const std::array<int, 3>& size, const Eigen::Vector3d& origin, const Eigen::Vector3d& spacing) {
    check_size(size, 4);
    if (!origin.allFinite() || !spacing.allFinite() || (spacing.array() <= 0).any())
        throw InvalidInput("uniform lattice: spacing must be finite and > 0");
    Lattice l;
    l.size_ = size;
    l.placement_ = Placement::uniform;
    l.origin_ = origin;
    l.spacing_ = spacing;
    l.points_.resize(std::size_t(size[0]) * size[1] * size[2]);
    for (int k = 0; k < size[2]; ++k)
        for (int j = 0; j < size[1]; ++j)
            for (int i = 0; i < size[0]; ++i)
                l.points_[l.flat_index(i, j, k)] = origin + Eigen::Vector3d((i - 1) * spacing.x(), (j - 1) * spacing.y(), (k - 1) * spacing.z());
    l.rest_points_ = l.points_;
    return l;
}

Lattice Lattice::clamped(const std::array<int, 3>& size, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
    check_size(size, 6);
    if (!lo.allFinite() || !hi.allFinite() || ((hi - lo).array() <= 0).any()) throw InvalidInput("clamped lattice: the data box is empty");
    Lattice l;
    l.size_ = size;
    l.placement_ = Placement::clamped;
    l.origin_ = lo;
    for (int a = 0; a < 3; ++a) l.spacing_[a] = (hi[a] - lo[a]) / (size[std::size_t(a)] - 3);
    auto coordinate = [&](int a, int i) {
        const int n = size[std::size_t(a)];
        const int m = std::clamp(i - 2, 0, n - 5); // 0 .. n-5 over the n-4 distinct positions
        return lo[a] + (hi[a] - lo[a]) * m / (n - 5);
    };
    l.points_.resize(std::size_t(size[0]) * size[1] * size[2]);
    for (int k = 0; k < size[2]; ++k)
        for (int j = 0; j < size[1]; ++j)
            for (int i = 0; i < size[0]; ++i) l.points_[l.flat_index(i, j, k)] = Eigen::Vector3d(coordinate(0, i), coordinate(1, j), coordinate(2, k));
    l.rest_points_ = l.points_;
    return l;
}

void Lattice::weights(const Eigen::Vector3d& stu, std::array<int, 3>& region, std::array<double, 64>& w) const {
    AxisBasis b;
    basis_at(size_, stu, region, b);
    for (int k = 0; k < 4; ++k)
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i) w[std::size_t(i + 4 * (j + 4 * k))] = b[0][std::size_t(i)] * b[1][std::size_t(j)] * b[2][std::size_t(k)];
}

void Lattice::derivative_weights(const Eigen::Vector3d& stu, const Eigen::Vector3d& dstu, std::array<int, 3>& region, std::array<double, 64>& w) const {
    AxisBasis b, d;
    basis_at(size_, stu, region, b, &d);
    for (int k = 0; k < 4; ++k)
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i) {
                const std::size_t I = std::size_t(i), J = std::size_t(j), K = std::size_t(k);
                w[I + 4 * (J + 4 * K)] = dstu.x() * d[0][I] * b[1][J] * b[2][K] + dstu.y() * b[0][I] * d[1][J] * b[2][K] + dstu.z() * b[0][I] * b[1][J] * d[2][K];
            }
}

void Lattice::second_derivative_weights(const Eigen::Vector3d& stu, const Eigen::Vector3d& a, const Eigen::Vector3d& b, std::array<int, 3>& region,
                                        std::array<double, 64>& w) const {
    AxisBasis value, slope, curvature;
    basis_at(size_, stu, region, value, &slope, &curvature);
    // d^2/dp dq of B_i(s) B_j(t) B_k(u): the factor of each axis is its value, slope (once differentiated) or
    // curvature (twice), by how many of p and q name that axis.
    Eigen::Matrix3d pair = a * b.transpose();
    pair = (pair + pair.transpose()).eval() / 2;
    w.fill(0.0);
    for (int p = 0; p < 3; ++p)
        for (int q = 0; q < 3; ++q) {
            if (pair(p, q) == 0) continue;
            std::array<const std::array<double, 4>*, 3> factor{&value[0], &value[1], &value[2]};
            for (int axis = 0; axis < 3; ++axis) {
                const int order = int(p == axis) + int(q == axis);
                if (order == 1) factor[std::size_t(axis)] = &slope[std::size_t(axis)];
                if (order == 2) factor[std::size_t(axis)] = &curvature[std::size_t(axis)];
            }
            for (int k = 0; k < 4; ++k)
                for (int j = 0; j < 4; ++j)
                    for (int i = 0; i < 4; ++i)
                        w[std::size_t(i + 4 * (j + 4 * k))] += pair(p, q) * (*factor[0])[std::size_t(i)] * (*factor[1])[std::size_t(j)] * (*factor[2])[std::size_t(k)];
        }
}

Eigen::Vector3d Lattice::combine(const std::array<int, 3>& r, const std::array<double, 64>& w) const {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k)
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i) p += w[std::size_t(i + 4 * (j + 4 * k))] * point(r[0] + i, r[1] + j, r[2] + k);
    return p;
}

Eigen::Vector3d Lattice::evaluate(const Eigen::Vector3d& stu) const {
    std::array<int, 3> r;
    AxisBasis b;
    basis_at(size_, stu, r, b);
    // Contracted along s, then t, then u (as the Jacobian's overload): 48 + 12 + 3 products instead of 64 weights
    // and 64 more.
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) {
        Eigen::Vector3d v_k = Eigen::Vector3d::Zero();
        for (int j = 0; j < 4; ++j) {
            const Eigen::Vector3d* row = &point(r[0], r[1] + j, r[2] + k);
            const Eigen::Vector3d v = b[0][0] * row[0] + b[0][1] * row[1] + b[0][2] * row[2] + b[0][3] * row[3];
            v_k += b[1][std::size_t(j)] * v;
        }
        p += b[2][std::size_t(k)] * v_k;
    }
    return p;
}

Eigen::Matrix3d Lattice::jacobian(const Eigen::Vector3d& stu) const {
    Eigen::Matrix3d J;
    evaluate(stu, J);
    return J;
}

Eigen::Vector3d Lattice::evaluate(const Eigen::Vector3d& stu, Eigen::Matrix3d& J) const {
    std::array<int, 3> r;
    AxisBasis b, d;
    basis_at(size_, stu, r, b, &d);
    // Contract along s first (value and s-derivative per row), then t, then u: 3 x 64 + 2 x 16 + 4 products
    // instead of four separate passes over the 64 points.
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    J.setZero();
    for (int k = 0; k < 4; ++k) {
        Eigen::Vector3d v_k = Eigen::Vector3d::Zero(), ds_k = Eigen::Vector3d::Zero(), dt_k = Eigen::Vector3d::Zero();
        for (int j = 0; j < 4; ++j) {
            Eigen::Vector3d v = Eigen::Vector3d::Zero(), ds = Eigen::Vector3d::Zero();
            const Eigen::Vector3d* row = &point(r[0], r[1] + j, r[2] + k);
            for (int i = 0; i < 4; ++i) {
                v += b[0][std::size_t(i)] * row[i];
                ds += d[0][std::size_t(i)] * row[i];
            }
            v_k += b[1][std::size_t(j)] * v;
            ds_k += b[1][std::size_t(j)] * ds;
            dt_k += d[1][std::size_t(j)] * v;
        }
        p += b[2][std::size_t(k)] * v_k;
        J.col(0) += b[2][std::size_t(k)] * ds_k;
        J.col(1) += b[2][std::size_t(k)] * dt_k;
        J.col(2) += d[2][std::size_t(k)] * v_k;
    }
    return p;
}

bool Lattice::contains_parameter(const Eigen::Vector3d& stu, double tolerance) const {
    for (int a = 0; a < 3; ++a)
        if (stu[a] < -tolerance || stu[a] > size_[std::size_t(a)] - 3 + tolerance) return false;
    return true;
}

Eigen::Vector3d Lattice::parameter_of(const Eigen::Vector3d& world) const {
    const bool undeformed = points_ == rest_points_;
    Eigen::Vector3d stu = (world - origin_).cwiseQuotient(spacing_);
    if (undeformed && placement_ == Placement::uniform) return stu;
    const double scale = Eigen::Vector3d(size_[0] - 3, size_[1] - 3, size_[2] - 3).maxCoeff();
    for (int iteration = 0; iteration < 100; ++iteration) {
        Eigen::Matrix3d J;
        const Eigen::Vector3d residual = evaluate(stu, J) - world;
        // Clamped ends have a zero derivative; a tiny diagonal keeps the step finite there.
        Eigen::Vector3d step = (J + 1e-12 * J.norm() * Eigen::Matrix3d::Identity()).fullPivLu().solve(residual);
        if (!step.allFinite()) break;
        const double limit = 0.5; // at most half a region per step keeps Newton inside one polynomial piece
        if (step.cwiseAbs().maxCoeff() > limit) step *= limit / step.cwiseAbs().maxCoeff();
        stu -= step;
        if (step.norm() < 1e-12 * scale) return stu;
    }
    const Eigen::Vector3d residual = evaluate(stu) - world;
    if (residual.norm() <= 1e-9 * (spacing_.norm() * scale)) return stu;
    throw SolverFailure("lattice: cannot find the parameter of world point (" + std::to_string(world.x()) + ", " + std::to_string(world.y()) + ", " +
                        std::to_string(world.z()) + "): Newton did not converge (the map may fold there)");
}

} // namespace voxwarp
