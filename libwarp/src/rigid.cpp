// The rotation-aware solve (rigid.h): material per lattice cell, Anderson-accelerated ARAP local/global iterations;
// the Ceres graph baseline it is measured against.
#include "constraint_rows.h"

#include <voxwarp/basis.h>
#include <voxwarp/errors.h>
#include <voxwarp/rigid.h>
#include <voxwarp/warp.h>

#include <ceres/ceres.h>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <Eigen/SparseCholesky>

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <map>
#include <set>

namespace voxwarp {

namespace rigid_internal {

using namespace constraints_internal;

/// Gauss-Legendre rule on [0, 1] with three points: exact for polynomials of degree 5 (|F|^2 over a cell is of
/// degree 4 in each parameter).
constexpr std::array<double, 3> kGaussWeight{5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0};
inline std::array<double, 3> gauss_points() {
    const double d = 0.5 * std::sqrt(0.6);
    return {0.5 - d, 0.5, 0.5 + d};
}

/// Cells (1/q of a region per axis) in the support of control point i along one axis, with the integral of its
/// basis piece over each.
std::vector<std::pair<int, double>> support_cells(int i, int regions, int q) {
    std::vector<std::pair<int, double>> out;
    const auto gp = gauss_points();
    for (int a = std::max(0, i - 3); a <= std::min(regions - 1, i); ++a)
        for (int h = 0; h < q; ++h) {
            double integral = 0;
            for (int p = 0; p < 3; ++p) integral += kGaussWeight[std::size_t(p)] * cubic_basis((h + gp[std::size_t(p)]) / q)[std::size_t(i - a)] / q;
            out.emplace_back(q * a + h, integral);
        }
    return out;
}

/// Parameter of the centre of cell (x, y, z) when a region holds q^3 cells.
Eigen::Vector3d cell_centre(int x, int y, int z, int q) { return (Eigen::Vector3d(x, y, z) + Eigen::Vector3d::Constant(0.5)) / q; }

/// One cell's integrals, per lattice point of its region (slot i + 4 (j + 4 k)), as means over the cell: the
/// world gradient of the point's basis function g (J0^-T dN/d(s,t,u), J0 the undeformed map's derivative, so that
/// F = sum P g^T is the map's world Jacobian, identity undeformed) and the Gram matrix of those gradients.
struct CellIntegrals {
    Eigen::Matrix<double, 64, 3> gradient;
    Eigen::Matrix<double, 64, 64> gram;
    double volume = 0; ///< the cell's undeformed world volume
};

CellIntegrals integrate_cell(const Lattice& rest, int x, int y, int z, int q) {
    const std::array<int, 3> cell{x, y, z};
    const auto regions = rest.regions();
    std::array<int, 3> region{}, sub{};
    for (std::size_t a = 0; a < 3; ++a) region[a] = std::min(cell[a] / q, regions[a] - 1), sub[a] = cell[a] - q * region[a];
    const auto gp = gauss_points();
    CellIntegrals out;
    out.gradient.setZero();
    out.gram.setZero();
    Eigen::Matrix<double, 64, 3> G;
    for (int pz = 0; pz < 3; ++pz)
        for (int py = 0; py < 3; ++py)
            for (int px = 0; px < 3; ++px) {
                const std::array<int, 3> p{px, py, pz};
                std::array<std::array<double, 4>, 3> b, d;
                Eigen::Vector3d stu;
                for (std::size_t a = 0; a < 3; ++a) {
                    const double t = (sub[a] + gp[std::size_t(p[a])]) / q;
                    b[a] = cubic_basis(t), d[a] = cubic_basis_derivative(t);
                    stu[Eigen::Index(a)] = region[a] + t;
                }
                const Eigen::Matrix3d J0 = rest.jacobian(stu);
                const Eigen::Matrix3d inverse_transpose = J0.inverse().transpose();
                for (int k = 0; k < 4; ++k)
                    for (int j = 0; j < 4; ++j)
                        for (int i = 0; i < 4; ++i)
                            G.row(i + 4 * (j + 4 * k)) = (inverse_transpose * Eigen::Vector3d(d[0][std::size_t(i)] * b[1][std::size_t(j)] * b[2][std::size_t(k)],
                                                                                               b[0][std::size_t(i)] * d[1][std::size_t(j)] * b[2][std::size_t(k)],
                                                                                               b[0][std::size_t(i)] * b[1][std::size_t(j)] * d[2][std::size_t(k)]))
                                                              .transpose();
                const double w = kGaussWeight[std::size_t(px)] * kGaussWeight[std::size_t(py)] * kGaussWeight[std::size_t(pz)];
                out.gradient += w * G;
                out.gram.noalias() += w * G * G.transpose();
                out.volume += w * J0.determinant() / (double(q) * q * q);
            }
    return out;
}

/// The rotation nearest to A (its polar factor), by Mueller, Bender, Chentanez & Macklin's iteration (2016),
/// started from `q` (the previous answer): one or two steps when A changes a little.
Eigen::Quaterniond extract_rotation(const Eigen::Matrix3d& A, Eigen::Quaterniond q) {
    for (int it = 0; it < 10; ++it) {
        const Eigen::Matrix3d R = q.toRotationMatrix();
        const Eigen::Vector3d omega = (R.col(0).cross(A.col(0)) + R.col(1).cross(A.col(1)) + R.col(2).cross(A.col(2))) /
                                      (std::abs(R.col(0).dot(A.col(0)) + R.col(1).dot(A.col(1)) + R.col(2).dot(A.col(2))) + 1e-12);
        const double w = omega.squaredNorm();
        if (!(w > 1e-14)) break; // 1e-7 radians: the outer iterations refine the rest
        // q <- exp(omega / 2) q, the exponential taken to second order (exact enough for a step of an iteration).
        const Eigen::Vector3d half = 0.5 * (w > 1.0 ? omega / std::sqrt(w) : omega);
        const Eigen::Quaterniond dq(1.0 - 0.5 * half.squaredNorm(), half.x(), half.y(), half.z());
        q = dq * q;
        q.normalize();
    }
    return q;
}

/// A matrix near F with determinant 1: F's singular values moved onto s1 s2 s3 = 1 (Gauss-Newton steps along the
/// constraint's gradient, as in Projective Dynamics' volume projection), its rotations kept proper (an inverted F
/// is mapped to its unfolded neighbour).
Eigen::Matrix3d unit_determinant(const Eigen::Matrix3d& F) {
    Eigen::JacobiSVD<Eigen::Matrix3d> svd;
    svd.compute(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
    if (U.determinant() < 0) U.col(2) *= -1.0;
    if (V.determinant() < 0) V.col(2) *= -1.0;
    Eigen::Vector3d d = (U.transpose() * F * V).diagonal().cwiseAbs().cwiseMax(1e-3);
    for (int it = 0; it < 20; ++it) {
        const double C = d.prod() - 1.0;
        if (std::abs(C) < 1e-12) break;
        const Eigen::Vector3d grad(d[1] * d[2], d[0] * d[2], d[0] * d[1]);
        d -= C / grad.squaredNorm() * grad;
    }
    return U * d.asDiagonal() * V.transpose();
}

/// Axis-neighbour pairs of distinct unknowns on the lattice, each once (a < b).
std::vector<std::pair<int, int>> neighbour_pairs(const Lattice& lattice, const std::vector<int>& group) {
    std::set<std::pair<int, int>> pairs;
    const auto n = lattice.size();
    for (int k = 0; k < n[2]; ++k)
        for (int j = 0; j < n[1]; ++j)
            for (int i = 0; i < n[0]; ++i)
                for (int axis = 0; axis < 3; ++axis) {
                    std::array<int, 3> q{i, j, k};
                    if (++q[std::size_t(axis)] >= n[std::size_t(axis)]) continue;
                    const int a = group[lattice.flat_index(i, j, k)], b = group[lattice.flat_index(q[0], q[1], q[2])];
                    if (a != b) pairs.insert(std::minmax(a, b));
                }
    return {pairs.begin(), pairs.end()};
}

using Rows = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>; // one 3D point per row

/// The symmetric positive definite system of a global step, dense for the usual lattice, sparse beyond.
class SpdSystem {
public:
    explicit SpdSystem(int n) : n_(n), dense_(n <= kDenseLimit) {
        if (dense_) A_ = Eigen::MatrixXd::Zero(n, n);
    }
    void add(int i, int j, double v) {
        if (dense_) A_(i, j) += v;
        else entries_.emplace_back(i, j, v);
    }
    /// Factor; then solve() answers A x = b. @throw SolverFailure when A is not positive definite.
    void factor() {
        if (dense_) {
            llt_.compute(A_);
            if (llt_.info() != Eigen::Success) throw SolverFailure("rigid solve: the global step's matrix is not positive definite");
        } else {
            Eigen::SparseMatrix<double> S(n_, n_);
            S.setFromTriplets(entries_.begin(), entries_.end());
            entries_ = {};
            ldlt_.compute(S);
            if (ldlt_.info() != Eigen::Success) throw SolverFailure("rigid solve: the global step's matrix could not be factored");
        }
    }
    Eigen::MatrixXd solve(const Eigen::MatrixXd& b) const { return dense_ ? Eigen::MatrixXd(llt_.solve(b)) : Eigen::MatrixXd(ldlt_.solve(b)); }
    static constexpr int kDenseLimit = 2500;

private:
    int n_;
    bool dense_;
    Eigen::MatrixXd A_;
    Eigen::LLT<Eigen::MatrixXd> llt_;
    std::vector<Eigen::Triplet<double>> entries_;
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt_;
};

/// Control points that shape no material (the lattice's outer shell) follow the solved ones as rigidly as the
/// lattice edges let them: ARAP on the control-point graph with the solved points held, a few local/global steps.
void extend_rigidly(const Lattice& rest, const std::vector<int>& group, const std::vector<int>& solved_index,
                    const std::vector<Eigen::Quaterniond>& solved_rotation, std::vector<Eigen::Vector3d>& P) {
    const int g = int(P.size());
    std::vector<int> free_index(static_cast<std::size_t>(g), -1), free;
    for (int q = 0; q < g; ++q)
        if (solved_index[std::size_t(q)] < 0) free_index[std::size_t(q)] = int(free.size()), free.push_back(q);
    std::vector<Eigen::Vector3d> P0(static_cast<std::size_t>(g));
    for (std::size_t p = 0; p < group.size(); ++p) P0[std::size_t(group[p])] = rest.rest_points()[p];
    const auto pairs = neighbour_pairs(rest, group);
    // Start every free point with the motion of a solved neighbour's rotation about it, spreading outwards.
    std::vector<Eigen::Quaterniond> rotation(static_cast<std::size_t>(g), Eigen::Quaterniond::Identity());
    std::vector<bool> known(static_cast<std::size_t>(g), false);
    for (int q = 0; q < g; ++q)
        if (solved_index[std::size_t(q)] >= 0) rotation[std::size_t(q)] = solved_rotation[std::size_t(solved_index[std::size_t(q)])], known[std::size_t(q)] = true;
    for (bool grew = true; grew;) {
        grew = false;
        for (const auto& [a, b] : pairs)
            for (const auto& [from, to] : {std::pair{a, b}, std::pair{b, a}})
                if (known[std::size_t(from)] && !known[std::size_t(to)]) {
                    P[std::size_t(to)] = P[std::size_t(from)] + rotation[std::size_t(from)] * (P0[std::size_t(to)] - P0[std::size_t(from)]);
                    rotation[std::size_t(to)] = rotation[std::size_t(from)];
                    known[std::size_t(to)] = true;
                    grew = true;
                }
    }
    // Then ARAP on the graph, solved points fixed.
    const int f = int(free.size());
    std::vector<Eigen::Triplet<double>> entries;
    for (const auto& [a, b] : pairs) {
        const double w = 1.0 / (P0[std::size_t(b)] - P0[std::size_t(a)]).squaredNorm();
        const int fa = free_index[std::size_t(a)], fb = free_index[std::size_t(b)];
        if (fa >= 0) entries.emplace_back(fa, fa, 2 * w);
        if (fb >= 0) entries.emplace_back(fb, fb, 2 * w);
        if (fa >= 0 && fb >= 0) entries.emplace_back(fa, fb, -2 * w), entries.emplace_back(fb, fa, -2 * w);
    }
    Eigen::SparseMatrix<double> A(f, f);
    A.setFromTriplets(entries.begin(), entries.end());
    const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(A);
    if (ldlt.info() != Eigen::Success) return; // every free point already follows a solved neighbour rigidly
    for (int it = 0; it < 5; ++it) {
        std::vector<Eigen::Matrix3d> star(static_cast<std::size_t>(g), Eigen::Matrix3d::Zero());
        for (const auto& [a, b] : pairs) {
            const Eigen::Vector3d e = P0[std::size_t(b)] - P0[std::size_t(a)];
            const Eigen::Matrix3d outer = (P[std::size_t(b)] - P[std::size_t(a)]) * e.transpose() / e.squaredNorm();
            star[std::size_t(a)] += outer, star[std::size_t(b)] += outer;
        }
        for (int q : free) rotation[std::size_t(q)] = extract_rotation(star[std::size_t(q)], rotation[std::size_t(q)]);
        Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(f, 3);
        for (const auto& [a, b] : pairs) {
            const Eigen::Vector3d e = P0[std::size_t(b)] - P0[std::size_t(a)];
            const double w = 1.0 / e.squaredNorm();
            const Eigen::Vector3d re = w * (rotation[std::size_t(a)] * e + rotation[std::size_t(b)] * e);
            const int fa = free_index[std::size_t(a)], fb = free_index[std::size_t(b)];
            if (fb >= 0) rhs.row(fb) += re.transpose() + (fa < 0 ? Eigen::Vector3d(2 * w * P[std::size_t(a)]) : Eigen::Vector3d::Zero()).transpose();
            if (fa >= 0) rhs.row(fa) -= re.transpose() - (fb < 0 ? Eigen::Vector3d(2 * w * P[std::size_t(b)]) : Eigen::Vector3d::Zero()).transpose();
        }
        const Eigen::MatrixXd x = ldlt.solve(rhs);
        for (int k = 0; k < f; ++k) P[std::size_t(free[std::size_t(k)])] = x.row(k).transpose();
    }
}

/// The baseline's edge residual: r = s (P_h - P_g - R_g e), R_g a unit quaternion (Eigen's x, y, z, w order).
struct EdgeResidual {
    Eigen::Vector3d e;
    double s;
    template <class T>
    bool operator()(const T* pg, const T* ph, const T* q, T* r) const {
        const Eigen::Map<const Eigen::Quaternion<T>> rotation(q);
        const Eigen::Matrix<T, 3, 1> re = rotation * e.cast<T>();
        for (int a = 0; a < 3; ++a) r[a] = T(s) * (ph[a] - pg[a] - re[a]);
        return true;
    }
};

/// r = s (sum_k w_k P_k - t): a point constraint as three residuals.
class RowResidual final : public ceres::CostFunction {
public:
    RowResidual(std::vector<double> w, const Eigen::Vector3d& t, double s) : w_(std::move(w)), t_(t), s_(s) {
        set_num_residuals(3);
        for (std::size_t k = 0; k < w_.size(); ++k) mutable_parameter_block_sizes()->push_back(3);
    }
    bool Evaluate(double const* const* p, double* r, double** jac) const override {
        Eigen::Vector3d sum = -t_;
        for (std::size_t k = 0; k < w_.size(); ++k) sum += w_[k] * Eigen::Map<const Eigen::Vector3d>(p[k]);
        Eigen::Map<Eigen::Vector3d> residual(r);
        residual = s_ * sum;
        if (jac)
            for (std::size_t k = 0; k < w_.size(); ++k)
                if (jac[k]) Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jac[k]} = s_ * w_[k] * Eigen::Matrix3d::Identity();
        return true;
    }

private:
    std::vector<double> w_;
    Eigen::Vector3d t_;
    double s_;
};

} // namespace rigid_internal

using namespace rigid_internal;

LatticeMaterial lattice_material(const WarpDomain& domain, int per_region) {
    if (per_region < 1 || per_region > 8) throw InvalidInput("lattice material: " + std::to_string(per_region) + " cells per region is outside [1, 8]");
    LatticeMaterial out;
    out.per_region = per_region;
    const auto r = domain.lattice.regions();
    std::array<std::vector<int>, 3> cell_of;
    std::array<std::vector<std::int64_t>, 3> count;
    for (std::size_t a = 0; a < 3; ++a) {
        out.cells[a] = per_region * r[a];
        cell_of[a].resize(std::size_t(domain.dims[a]));
        count[a].assign(std::size_t(out.cells[a]), 0);
        for (std::int64_t e = 0; e < domain.dims[a]; ++e) {
            const int c = std::clamp(int(per_region * e / domain.granularity[a]), 0, out.cells[a] - 1);
            cell_of[a][std::size_t(e)] = c;
            ++count[a][std::size_t(c)];
        }
    }
    const std::size_t cells = std::size_t(out.cells[0]) * std::size_t(out.cells[1]) * std::size_t(out.cells[2]);
    // Densities summed in fixed point (2^-24), so the sums, and every solve built on them, do not depend on
    // how the blocks were shared among threads.
    constexpr double kScale = double(1 << 24);
    tbb::combinable<std::vector<std::int64_t>> sums([cells] { return std::vector<std::int64_t>(cells, 0); });
    const SparseVoxmap& v = domain.voxmap;
    const auto& n = v.dims();
    const auto& bd = v.block_dims();
    constexpr std::int64_t S = SparseVoxmap::kSide;
    auto cell_index = [&](std::int64_t e, std::int64_t f, std::int64_t g) -> std::int64_t {
        e += domain.offset[0], f += domain.offset[1], g += domain.offset[2];
        if (e < 0 || f < 0 || g < 0 || e >= domain.dims[0] || f >= domain.dims[1] || g >= domain.dims[2]) return -1;
        return cell_of[0][std::size_t(e)] + std::int64_t(out.cells[0]) * (cell_of[1][std::size_t(f)] + std::int64_t(out.cells[1]) * cell_of[2][std::size_t(g)]);
    };
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, v.block_count()), [&](const auto& range) {
        auto& local = sums.local();
        for (std::int64_t b = range.begin(); b != range.end(); ++b) {
            const std::int64_t i0 = S * (b % bd[0]), j0 = S * ((b / bd[0]) % bd[1]), k0 = S * (b / (bd[0] * bd[1]));
            const std::int64_t i1 = std::min(i0 + S, n[0]), j1 = std::min(j0 + S, n[1]), k1 = std::min(k0 + S, n[2]);
            const float* values = v.block_values(b);
            const std::int64_t uniform = values ? 0 : std::llround(double(v.block_uniform(b)) * kScale);
            if (!values && uniform == 0) continue;
            for (std::int64_t k = k0; k < k1; ++k)
                for (std::int64_t j = j0; j < j1; ++j)
                    for (std::int64_t i = i0; i < i1; ++i) {
                        const std::int64_t value = values ? std::llround(double(values[(i - i0) + S * ((j - j0) + S * (k - k0))]) * kScale) : uniform;
                        if (value == 0) continue;
                        const std::int64_t c = cell_index(i, j, k);
                        if (c >= 0) local[std::size_t(c)] += value;
                    }
        }
    });
    std::vector<std::int64_t> total(cells, 0);
    sums.combine_each([&](const std::vector<std::int64_t>& part) {
        for (std::size_t c = 0; c < cells; ++c) total[c] += part[c];
    });
    out.density.resize(cells);
    for (int z = 0; z < out.cells[2]; ++z)
        for (int y = 0; y < out.cells[1]; ++y)
            for (int x = 0; x < out.cells[0]; ++x) {
                const std::size_t c = std::size_t(x) + std::size_t(out.cells[0]) * (std::size_t(y) + std::size_t(out.cells[1]) * std::size_t(z));
                const double voxels = double(count[0][std::size_t(x)]) * double(count[1][std::size_t(y)]) * double(count[2][std::size_t(z)]);
                out.density[c] = voxels > 0 ? float(std::min(1.0, double(total[c]) / kScale / voxels)) : 0.0f;
            }
    return out;
}

namespace rigid_internal {

void check_material(const Lattice& lattice, const LatticeMaterial& material) {
    const auto r = lattice.regions();
    for (std::size_t a = 0; a < 3; ++a)
        if (material.per_region < 1 || material.cells[a] != material.per_region * r[a] ||
            material.density.size() != std::size_t(material.cells[0]) * std::size_t(material.cells[1]) * std::size_t(material.cells[2]))
            throw InvalidInput("lattice material: " + std::to_string(material.cells[a]) + " cells along axis " + std::to_string(a) + " do not match a lattice of " +
                               std::to_string(lattice.size()[a]) + " control points");
}

} // namespace rigid_internal

std::vector<double> control_point_material(const Lattice& lattice, const LatticeMaterial& material) {
    check_material(lattice, material);
    const auto n = lattice.size();
    const auto r = lattice.regions();
    std::array<std::vector<std::vector<std::pair<int, double>>>, 3> support;
    for (std::size_t a = 0; a < 3; ++a)
        for (int i = 0; i < n[a]; ++i) support[a].push_back(support_cells(i, r[a], material.per_region));
    std::vector<double> out(lattice.control_point_count(), 0.0);
    tbb::parallel_for(0, n[2], [&](int k) {
        for (int j = 0; j < n[1]; ++j)
            for (int i = 0; i < n[0]; ++i) {
                double sum = 0, weight = 0;
                for (const auto& [cz, bz] : support[2][std::size_t(k)])
                    for (const auto& [cy, by] : support[1][std::size_t(j)])
                        for (const auto& [cx, bx] : support[0][std::size_t(i)]) {
                            const double beta = bx * by * bz;
                            sum += beta * material.at(cx, cy, cz);
                            weight += beta;
                        }
                out[lattice.flat_index(i, j, k)] = weight > 0 ? sum / weight : 0.0;
            }
    });
    return out;
}

double mapped_material_volume(const Lattice& lattice, const LatticeMaterial& material) {
    check_material(lattice, material);
    const int q = material.per_region;
    const auto gp = gauss_points();
    double volume = 0;
    for (int z = 0; z < material.cells[2]; ++z)
        for (int y = 0; y < material.cells[1]; ++y)
            for (int x = 0; x < material.cells[0]; ++x) {
                const double rho = material.at(x, y, z);
                if (rho <= 0) continue;
                // det J is world volume per parameter volume; 3^3 Gauss points over the cell's (1/q)^3 of it.
                for (int p = 0; p < 27; ++p) {
                    const Eigen::Vector3d stu =
                        (Eigen::Vector3d(x, y, z) + Eigen::Vector3d(gp[std::size_t(p % 3)], gp[std::size_t(p / 3 % 3)], gp[std::size_t(p / 9)])) / q;
                    volume += rho * kGaussWeight[std::size_t(p % 3)] * kGaussWeight[std::size_t(p / 3 % 3)] * kGaussWeight[std::size_t(p / 9)] *
                              lattice.jacobian(stu).determinant() / (double(q) * q * q);
                }
            }
    return volume;
}

RigidSolution solve_rigid(const Lattice& rest, const std::vector<Constraint>& constraints, const LatticeMaterial& material, const RigidSolveOptions& options) {
    Progress progress(options.progress, options.rigid ? "rigid solve" : "volume solve");
    if (!(options.empty_weight > 0 && options.empty_weight <= 1)) throw InvalidInput("rigid solve: empty_weight must be in (0, 1]");
    if (!options.rigid && !options.preserve_volume) throw InvalidInput("rigid solve: neither rigidity nor volume asked for");
    const ConstraintRows rows = constraint_rows(rest, constraints);
    check_material(rest, material);
    const int g = rows.groups, m = int(constraints.size());
    const auto& group = rows.group;
    std::vector<Eigen::Vector3d> P0(static_cast<std::size_t>(g));
    for (std::size_t p = 0; p < group.size(); ++p) P0[std::size_t(group[p])] = rest.rest_points()[p];
    const double L = rest.spacing().mean();

    // Material cells and the unknowns they (or a constraint) involve: the only control points that shape the
    // material. The others follow afterwards (rigid) or stay put (min-norm). A uniform lattice's cells all share
    // the integrals of their place in the region; a clamped one's are integrated cell by cell.
    struct Cell {
        std::array<int, 3> region;
        int slot_cache;                       // index into `integrals`
        std::vector<int> unknowns;            // distinct unknowns of its region's 64 control points
        std::vector<Eigen::Vector3d> gradient; // mean world gradient per unknown
        std::vector<int> slot_unknown;        // per slot: index into `unknowns`
        double a;                             // share of the material's mass
    };
    const int q = material.per_region;
    const bool shared_integrals = rest.placement() == Placement::uniform;
    std::vector<CellIntegrals> integrals;
    std::map<std::array<int, 3>, int> cached;
    std::vector<Cell> cells;
    double mass = 0;
    for (int z = 0; z < material.cells[2]; ++z)
        for (int y = 0; y < material.cells[1]; ++y)
            for (int x = 0; x < material.cells[0]; ++x) {
                const double rho = material.at(x, y, z);
                if (rho <= 0) continue;
                Cell cell;
                const std::array<int, 3> at{x, y, z};
                std::array<int, 3> sub{};
                for (std::size_t a = 0; a < 3; ++a) cell.region[a] = std::min(at[a] / q, rest.regions()[a] - 1), sub[a] = at[a] - q * cell.region[a];
                auto it = shared_integrals ? cached.find(sub) : cached.end();
                if (it == cached.end()) {
                    integrals.push_back(integrate_cell(rest, x, y, z, q));
                    it = cached.emplace(shared_integrals ? sub : at, int(integrals.size() - 1)).first;
                }
                cell.slot_cache = it->second;
                const CellIntegrals& ci = integrals[std::size_t(cell.slot_cache)];
                if (!(ci.volume > 0)) continue;
                std::map<int, Eigen::Vector3d> per_unknown;
                std::array<int, 64> slot_group{};
                for (int k = 0; k < 4; ++k)
                    for (int j = 0; j < 4; ++j)
                        for (int i = 0; i < 4; ++i) {
                            const int slot = i + 4 * (j + 4 * k);
                            slot_group[std::size_t(slot)] = group[rest.flat_index(cell.region[0] + i, cell.region[1] + j, cell.region[2] + k)];
                            auto [pu, inserted] = per_unknown.try_emplace(slot_group[std::size_t(slot)], ci.gradient.row(slot).transpose());
                            if (!inserted) pu->second += ci.gradient.row(slot).transpose();
                        }
                for (const auto& [qq, grad] : per_unknown) cell.unknowns.push_back(qq), cell.gradient.push_back(grad);
                cell.slot_unknown.resize(64);
                for (int slot = 0; slot < 64; ++slot)
                    cell.slot_unknown[std::size_t(slot)] =
                        int(std::lower_bound(cell.unknowns.begin(), cell.unknowns.end(), slot_group[std::size_t(slot)]) - cell.unknowns.begin());
                cell.a = rho * ci.volume;
                mass += cell.a;
                cells.push_back(std::move(cell));
            }
    std::vector<int> local(static_cast<std::size_t>(g), -1), unknowns;
    auto involve = [&](int q) {
        if (local[std::size_t(q)] < 0) local[std::size_t(q)] = int(unknowns.size()), unknowns.push_back(q);
    };
    std::vector<std::vector<std::pair<int, double>>> terms(static_cast<std::size_t>(m));
    std::vector<Eigen::Vector3d> target(static_cast<std::size_t>(m));
    for (int c = 0; c < m; ++c) {
        terms[std::size_t(c)] = merged(rows.terms[std::size_t(c)]);
        Eigen::Vector3d at_rest = Eigen::Vector3d::Zero();
        for (const auto& [q, w] : terms[std::size_t(c)]) at_rest += w * P0[std::size_t(q)], involve(q);
        target[std::size_t(c)] = at_rest + rows.D.row(c).transpose();
    }
    for (auto& cell : cells) {
        cell.a /= mass;
        for (int& qq : cell.unknowns) involve(qq), qq = local[std::size_t(qq)];
    }
    const int u = int(unknowns.size());
    if (u > kMaxRigidUnknowns)
        throw InvalidInput("rigid solve: " + std::to_string(u) + " control points shape the model, more than the " + std::to_string(kMaxRigidUnknowns) +
                           " this solve takes; use a smaller lattice.size");

    // Exact or least squares, by the same test as the min-norm solve: independent rows without weights are met exactly.
    const Eigen::VectorXd inv_sqrt_mult = rows.multiplicity.cwiseSqrt().cwiseInverse();
    Eigen::MatrixXd Ay = Eigen::MatrixXd::Zero(m, u);
    for (int c = 0; c < m; ++c)
        for (const auto& [q, w] : terms[std::size_t(c)]) Ay(c, local[std::size_t(q)]) += w * inv_sqrt_mult[q];
    RigidSolution out;
    out.rank = int(Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd>(Ay).rank());
    out.unknowns = g;
    const bool exact = !rows.weighted && out.rank == m;
    out.least_squares = !exact;
    std::vector<int> hard_rows, soft_rows;
    for (int c = 0; c < m; ++c) (exact || rows.hard[std::size_t(c)] ? hard_rows : soft_rows).push_back(c);

    // Weights (see rigid.h): material terms sum to one; the rest is scaled to them.
    const double w_rigid = options.rigid ? 1.0 : 0.0, w_volume = options.preserve_volume ? options.volume_weight : 0.0;
    const double w_cell = w_rigid + w_volume;
    const double motion = (options.rigid ? 1e-6 : options.motion_weight) / (u * L * L);
    const double soft = 1e3 / (L * L);
    std::vector<std::pair<int, int>> edges; // empty-space regularisation between unknowns (rigid)
    std::vector<Eigen::Vector3d> edge_rest;
    const double w_edge = options.empty_weight / std::max(1, u);
    if (options.rigid)
        for (const auto& [a, b] : neighbour_pairs(rest, group))
            if (local[std::size_t(a)] >= 0 && local[std::size_t(b)] >= 0) {
                edges.emplace_back(local[std::size_t(a)], local[std::size_t(b)]);
                edge_rest.push_back(P0[std::size_t(b)] - P0[std::size_t(a)]);
            }

    // The global step's matrix: fixed for the whole solve (rotations and volume targets only move its right side).
    SpdSystem H(u);
    Rows b_fixed = Rows::Zero(u, 3);
    for (const auto& cell : cells) {
        const auto& gram = integrals[std::size_t(cell.slot_cache)].gram;
        const double w = w_cell * cell.a;
        for (int s1 = 0; s1 < 64; ++s1)
            for (int s2 = 0; s2 < 64; ++s2)
                H.add(cell.unknowns[std::size_t(cell.slot_unknown[std::size_t(s1)])], cell.unknowns[std::size_t(cell.slot_unknown[std::size_t(s2)])], w * gram(s1, s2));
    }
    for (std::size_t e = 0; e < edges.size(); ++e) {
        const auto [i, j] = edges[e];
        const double w = 2 * w_edge / edge_rest[e].squaredNorm(); // both stars
        H.add(i, i, w), H.add(j, j, w), H.add(i, j, -w), H.add(j, i, -w);
    }
    for (int k = 0; k < u; ++k) {
        const double w = motion * rows.multiplicity[unknowns[std::size_t(k)]];
        H.add(k, k, w);
        b_fixed.row(k) += w * P0[std::size_t(unknowns[std::size_t(k)])].transpose();
    }
    for (int c : soft_rows) {
        const double w = soft * constraints[std::size_t(c)].weight.value_or(1.0);
        for (const auto& [q1, w1] : terms[std::size_t(c)]) {
            for (const auto& [q2, w2] : terms[std::size_t(c)]) H.add(local[std::size_t(q1)], local[std::size_t(q2)], w * w1 * w2);
            b_fixed.row(local[std::size_t(q1)]) += w * w1 * target[std::size_t(c)].transpose();
        }
    }
    H.factor();
    // Hard rows C x = d exactly, through their Schur complement: x = x0 - Y lambda, Y = H^-1 C^T, (C Y) lambda = C x0 - d.
    const int h = int(hard_rows.size());
    Eigen::MatrixXd C = Eigen::MatrixXd::Zero(h, u), d(h, 3);
    for (int r = 0; r < h; ++r) {
        const int c = hard_rows[std::size_t(r)];
        for (const auto& [q, w] : terms[std::size_t(c)]) C(r, local[std::size_t(q)]) += w;
        d.row(r) = target[std::size_t(c)].transpose();
    }
    const Eigen::MatrixXd Y = h > 0 ? H.solve(C.transpose()) : Eigen::MatrixXd(u, 0);
    // Eigen's decompositions fault on an empty matrix: without hard rows (least squares without pins) there is none.
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> schur;
    if (h > 0) schur.compute(C * Y);
    // The material's volume relative to its own, V = sum a_c det F_c (a_c summing to one), is held at 1 (rigid, or
    // preserve_volume): its linearisation at the current point, <v, x> = 1 - V + <v, P>, v = dV/dP, joins the hard
    // rows of the global step. One more solve per step (w = H^-1 v), and the volume settles with the shape.
    const bool hold_volume = !cells.empty() && (options.rigid || options.preserve_volume);
    auto global_step = [&](const Rows& b, const Rows& v, double c) -> Rows {
        Eigen::MatrixXd rhs(u, hold_volume ? 6 : 3);
        rhs.leftCols(3) = b;
        if (hold_volume) rhs.rightCols(3) = v;
        const Eigen::MatrixXd X = H.solve(rhs);
        Eigen::MatrixXd x_hat = X.leftCols(3); // projected onto the hard rows (H metric)
        if (h > 0) x_hat -= Y * schur.solve(C * x_hat - d);
        if (!hold_volume) return x_hat;
        Eigen::MatrixXd w_hat = X.rightCols(3);
        if (h > 0) w_hat -= Y * schur.solve(C * w_hat);
        const double denominator = (v.array() * w_hat.array()).sum();
        if (!(std::abs(denominator) > 1e-300)) return x_hat; // the hard rows leave the volume no freedom
        const double mu = ((v.array() * x_hat.array()).sum() - c) / denominator;
        return x_hat - mu * w_hat;
    };

    // Local/global iterations (Sorkine & Alexa 2007; with the volume term, Bouaziz et al.'s Projective Dynamics).
    std::vector<Eigen::Quaterniond> cell_rotation(cells.size(), Eigen::Quaterniond::Identity()), node_rotation(std::size_t(u), Eigen::Quaterniond::Identity());
    std::vector<Eigen::Matrix3d> cell_target(cells.size(), Eigen::Matrix3d::Identity());
    Rows P(u, 3);
    for (int k = 0; k < u; ++k) P.row(k) = P0[std::size_t(unknowns[std::size_t(k)])].transpose();
    auto jacobian = [&](const Cell& cell) { // the cell's mean Jacobian
        Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
        for (std::size_t k = 0; k < cell.unknowns.size(); ++k) F += P.row(cell.unknowns[k]).transpose() * cell.gradient[k].transpose();
        return F;
    };
    double volume = 1;
    Rows volume_gradient = Rows::Zero(u, 3);
    // Cells are handled in fixed chunks, each summing into a buffer of its own, the buffers then added in order:
    // parallel, yet the same sums for any thread count.
    constexpr std::size_t kChunk = 64;
    const std::size_t chunks = (cells.size() + kChunk - 1) / kChunk;
    std::vector<Rows> chunk_b(chunks, Rows::Zero(u, 3)), chunk_v(chunks, Rows::Zero(u, 3));
    std::vector<double> chunk_volume(chunks, 0.0);
    Rows b_cells = Rows::Zero(u, 3);
    // Local step: the nearest rotation (and unit-determinant matrix) to every cell's mean Jacobian, and to every
    // unknown's star of lattice edges; with them, the cells' part of the global step's right side, and the volume
    // and its gradient (d det F / d P_k = cof(F) g_k).
    auto local_step = [&] {
        tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t chunk) {
            Rows& bc = chunk_b[chunk];
            Rows& vc = chunk_v[chunk];
            bc.setZero(), vc.setZero();
            double vol = 0;
            for (std::size_t c = chunk * kChunk; c < std::min(cells.size(), (chunk + 1) * kChunk); ++c) {
                const Cell& cell = cells[c];
                const Eigen::Matrix3d F = jacobian(cell);
                Eigen::Matrix3d T = Eigen::Matrix3d::Zero();
                if (options.rigid) T += w_rigid * (cell_rotation[c] = extract_rotation(F, cell_rotation[c])).toRotationMatrix();
                if (options.preserve_volume) T += w_volume * unit_determinant(F);
                cell_target[c] = T / w_cell;
                Eigen::Matrix3d cofactor;
                cofactor.col(0) = F.col(1).cross(F.col(2)), cofactor.col(1) = F.col(2).cross(F.col(0)), cofactor.col(2) = F.col(0).cross(F.col(1));
                vol += cell.a * F.col(0).dot(cofactor.col(0));
                const Eigen::Matrix3d Tw = (w_cell * cell.a) * cell_target[c], Cw = cell.a * cofactor;
                for (std::size_t k = 0; k < cell.unknowns.size(); ++k) {
                    bc.row(cell.unknowns[k]) += (Tw * cell.gradient[k]).transpose();
                    vc.row(cell.unknowns[k]) += (Cw * cell.gradient[k]).transpose();
                }
            }
            chunk_volume[chunk] = vol;
        });
        volume = 0;
        b_cells.setZero(), volume_gradient.setZero();
        for (std::size_t chunk = 0; chunk < chunks; ++chunk) volume += chunk_volume[chunk], b_cells += chunk_b[chunk], volume_gradient += chunk_v[chunk];
        if (!options.rigid) return;
        std::vector<Eigen::Matrix3d> star(std::size_t(u), Eigen::Matrix3d::Zero());
        for (std::size_t e = 0; e < edges.size(); ++e) {
            const auto [i, j] = edges[e];
            const Eigen::Matrix3d outer = (P.row(j) - P.row(i)).transpose() * edge_rest[e].transpose() / edge_rest[e].squaredNorm();
            star[std::size_t(i)] += outer, star[std::size_t(j)] += outer;
        }
        for (int k = 0; k < u; ++k) node_rotation[std::size_t(k)] = extract_rotation(star[std::size_t(k)], node_rotation[std::size_t(k)]);
    };
    // The fixed point P = G(P) of a local and a global step, accelerated after Anderson (Peng, Deng, Zhang & Liu,
    // "Anderson acceleration for geometry optimization and physics simulation", 2018): the next point combines the
    // last few G(P) so that their residuals G(P) - P cancel best. Safeguard: when an accelerated point's residual
    // grows, it is dropped for the plain step it replaced and the history restarts.
    constexpr std::size_t kHistory = 6;
    constexpr double kReject = 2.0; // the volume snaps back in the next step: let a residual grow a little
    std::vector<Eigen::VectorXd> dG, dF;
    Eigen::VectorXd g_prev, f_prev;
    Rows plain;
    bool accelerated = false;
    double last_residual = std::numeric_limits<double>::infinity();
    int iteration = 0;
    for (; iteration < options.max_iterations; ++iteration) {
        local_step();
        Rows b = b_fixed + b_cells;
        for (std::size_t e = 0; e < edges.size(); ++e) {
            const auto [i, j] = edges[e];
            const double w = w_edge / edge_rest[e].squaredNorm();
            const Eigen::Vector3d re = w * (node_rotation[std::size_t(i)] * edge_rest[e] + node_rotation[std::size_t(j)] * edge_rest[e]);
            b.row(j) += re.transpose(), b.row(i) -= re.transpose();
        }
        const Rows G = global_step(b, volume_gradient, 1 - volume + (volume_gradient.array() * P.array()).sum());
        const double residual = (G - P).rowwise().norm().maxCoeff();
        progress.report(double(iteration + 1) / options.max_iterations);
        if (accelerated && residual > kReject * last_residual) {
            P = plain;
            dG.clear(), dF.clear();
            accelerated = false;
            last_residual = std::numeric_limits<double>::infinity();
            continue;
        }
        // The first step brings the hard rows in; the volume must have settled too.
        if (iteration > 0 && residual <= options.tolerance * L && (!hold_volume || std::abs(1 - volume) <= 1e-4)) {
            P = G;
            break;
        }
        const Eigen::VectorXd g = G.reshaped(), f = g - P.reshaped();
        if (g_prev.size() == g.size()) {
            dG.push_back(g - g_prev), dF.push_back(f - f_prev);
            if (dG.size() > kHistory) dG.erase(dG.begin()), dF.erase(dF.begin());
        }
        g_prev = g, f_prev = f;
        last_residual = residual;
        if (dF.size() < 2) { // one difference extrapolates too boldly on the volume's curvature
            P = G;
            accelerated = false;
            continue;
        }
        Eigen::MatrixXd DF(f.size(), Eigen::Index(dF.size())), DG(g.size(), Eigen::Index(dG.size()));
        for (std::size_t k = 0; k < dF.size(); ++k) DF.col(Eigen::Index(k)) = dF[k], DG.col(Eigen::Index(k)) = dG[k];
        Eigen::MatrixXd normal = DF.transpose() * DF;
        normal.diagonal().array() += 1e-10 * normal.diagonal().maxCoeff() + 1e-300;
        const Eigen::VectorXd gamma = normal.ldlt().solve(DF.transpose() * f);
        plain = G;
        P = (g - DG * gamma).reshaped(u, 3);
        accelerated = true;
    }
    out.iterations = std::min(iteration + 1, options.max_iterations);

    // Write back: the solved unknowns; the rest follow as rigidly as they can (rigid) or stay put (min-norm).
    std::vector<Eigen::Vector3d> solved = P0;
    for (int k = 0; k < u; ++k) solved[std::size_t(unknowns[std::size_t(k)])] = P.row(k).transpose();
    if (options.rigid && u < g) extend_rigidly(rest, group, local, node_rotation, solved);
    out.lattice = rest;
    auto& points = out.lattice.points();
    for (std::size_t p = 0; p < points.size(); ++p) points[p] = solved[std::size_t(group[p])];
    out.residuals.resize(std::size_t(m));
    for (int c = 0; c < m; ++c) {
        Eigen::Vector3d achieved = Eigen::Vector3d::Zero();
        for (const auto& [q, w] : terms[std::size_t(c)]) achieved += w * solved[std::size_t(q)];
        out.residuals[std::size_t(c)] = (achieved - target[std::size_t(c)]).norm();
    }
    progress.report(1.0);
    return out;
}

} // namespace voxwarp

namespace voxwarp {

RigidSolution solve_rigid_graph_ceres(const Lattice& rest, const std::vector<Constraint>& constraints, const LatticeMaterial& material) {
    const ConstraintRows rows = constraint_rows(rest, constraints);
    const std::vector<double> point_material = control_point_material(rest, material);
    const int g = rows.groups, m = int(constraints.size());
    const auto& group = rows.group;
    std::vector<Eigen::Vector3d> P0(static_cast<std::size_t>(g));
    std::vector<double> w(static_cast<std::size_t>(g), 1e-3);
    for (std::size_t p = 0; p < group.size(); ++p) {
        P0[std::size_t(group[p])] = rest.rest_points()[p];
        w[std::size_t(group[p])] = std::max(w[std::size_t(group[p])], point_material[p]);
    }
    const double L = rest.spacing().mean();
    std::vector<double> X(3 * static_cast<std::size_t>(g)), Q(4 * static_cast<std::size_t>(g), 0.0);
    for (int q = 0; q < g; ++q) {
        for (int a = 0; a < 3; ++a) X[3 * std::size_t(q) + std::size_t(a)] = P0[std::size_t(q)][a];
        Q[4 * std::size_t(q) + 3] = 1.0;
    }
    ceres::Problem problem;
    for (int q = 0; q < g; ++q) problem.AddParameterBlock(&X[3 * std::size_t(q)], 3), problem.AddParameterBlock(&Q[4 * std::size_t(q)], 4, new ceres::EigenQuaternionManifold);
    for (const auto& [a, b] : neighbour_pairs(rest, group))
        for (const auto& [from, to] : {std::pair{a, b}, std::pair{b, a}}) {
            const Eigen::Vector3d e = P0[std::size_t(to)] - P0[std::size_t(from)];
            problem.AddResidualBlock(new ceres::AutoDiffCostFunction<EdgeResidual, 3, 3, 3, 4>(new EdgeResidual{e, std::sqrt(w[std::size_t(from)]) / e.norm()}), nullptr,
                                     &X[3 * std::size_t(from)], &X[3 * std::size_t(to)], &Q[4 * std::size_t(from)]);
        }
    std::vector<std::vector<std::pair<int, double>>> terms(static_cast<std::size_t>(m));
    std::vector<Eigen::Vector3d> target(static_cast<std::size_t>(m));
    double scale = 0;
    for (double x : w) scale += x;
    for (int c = 0; c < m; ++c) {
        terms[std::size_t(c)] = merged(rows.terms[std::size_t(c)]);
        Eigen::Vector3d at_rest = Eigen::Vector3d::Zero();
        std::vector<double> weights;
        std::vector<double*> blocks;
        for (const auto& [q, wq] : terms[std::size_t(c)]) at_rest += wq * P0[std::size_t(q)], weights.push_back(wq), blocks.push_back(&X[3 * std::size_t(q)]);
        target[std::size_t(c)] = at_rest + rows.D.row(c).transpose();
        // Every constraint as a stiff penalty (the baseline makes no exact/weighted distinction).
        problem.AddResidualBlock(new RowResidual(std::move(weights), target[std::size_t(c)], std::sqrt(1e6 * scale) / L), nullptr, blocks);
    }
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    so.max_num_iterations = 100;
    so.function_tolerance = 1e-10;
    so.num_threads = 1;
    so.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    if (!summary.IsSolutionUsable()) throw SolverFailure("graph ARAP baseline: Ceres failed: " + summary.message);
    RigidSolution out;
    out.iterations = int(summary.iterations.size()) - 1;
    out.unknowns = g;
    out.least_squares = true;
    out.lattice = rest;
    for (std::size_t p = 0; p < group.size(); ++p) out.lattice.points()[p] = Eigen::Map<const Eigen::Vector3d>(&X[3 * std::size_t(group[p])]);
    for (int c = 0; c < m; ++c) {
        Eigen::Vector3d achieved = Eigen::Vector3d::Zero();
        for (const auto& [q, wq] : terms[std::size_t(c)]) achieved += wq * Eigen::Map<const Eigen::Vector3d>(&X[3 * std::size_t(q)]);
        out.residuals.push_back((achieved - target[std::size_t(c)]).norm());
    }
    return out;
}

} // namespace voxwarp
