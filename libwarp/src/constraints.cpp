#include "constraint_rows.h"

#include <voxwarp/constraints.h>
#include <voxwarp/errors.h>

#include <ceres/ceres.h>

#include <Eigen/QR>

#include <cmath>
#include <map>

namespace voxwarp {

int control_point_groups(const Lattice& lattice, std::vector<int>& group) {
    const auto& points = lattice.points();
    group.assign(points.size(), -1);
    std::map<std::array<double, 3>, int> seen;
    int count = 0;
    for (std::size_t p = 0; p < points.size(); ++p) {
        const std::array<double, 3> key{points[p].x(), points[p].y(), points[p].z()};
        auto [it, inserted] = seen.try_emplace(key, count);
        if (inserted) ++count;
        group[p] = it->second;
    }
    return count;
}

namespace constraints_internal {

/// r = J x - t: one linear residual block for Ceres.
class LinearResidual final : public ceres::CostFunction {
public:
    LinearResidual(Eigen::MatrixXd J, Eigen::VectorXd t) : J_(std::move(J)), t_(std::move(t)) {
        set_num_residuals(int(J_.rows()));
        mutable_parameter_block_sizes()->push_back(int(J_.cols()));
    }
    bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
        const Eigen::Map<const Eigen::VectorXd> x(parameters[0], J_.cols());
        Eigen::Map<Eigen::VectorXd>(residuals, J_.rows()) = J_ * x - t_;
        if (jacobians && jacobians[0])
            Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(jacobians[0], J_.rows(), J_.cols()) = J_;
        return true;
    }

private:
    Eigen::MatrixXd J_;
    Eigen::VectorXd t_;
};

/// Minimise |J x - t|^2 (J already holds sqrt of the weights) with Ceres; x starts at zero. Linear, so one
/// Gauss-Newton step with a dense QR is the exact answer.
Eigen::VectorXd solve_least_squares(const Eigen::MatrixXd& J, const Eigen::VectorXd& t) {
    Eigen::VectorXd x = Eigen::VectorXd::Zero(J.cols());
    if (J.cols() == 0) return x;
    ceres::Problem problem;
    problem.AddResidualBlock(new LinearResidual(J, t), nullptr, x.data());
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::DENSE_QR;
    options.max_num_iterations = 10;
    options.function_tolerance = 1e-16;
    options.gradient_tolerance = 1e-16;
    options.parameter_tolerance = 1e-16;
    options.logging_type = ceres::SILENT;
    options.minimizer_progress_to_stdout = false;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    if (!summary.IsSolutionUsable()) throw SolverFailure("constraint solve: Ceres failed: " + summary.message);
    return x;
}

ConstraintRows constraint_rows(const Lattice& rest, const std::vector<Constraint>& constraints) {
    if (constraints.empty()) throw InvalidInput("constraint solve: no constraints");
    ConstraintRows out;
    out.groups = control_point_groups(rest, out.group);
    const auto& group = out.group;
    out.multiplicity = Eigen::VectorXd::Zero(out.groups);
    for (int p : group) out.multiplicity[p] += 1;

    const int m = int(constraints.size());
    out.terms.resize(std::size_t(m));
    out.D.resize(m, 3);
    out.hard.assign(std::size_t(m), false);
    const auto n = rest.size();
    for (int c = 0; c < m; ++c) {
        const Constraint& k = constraints[std::size_t(c)];
        const std::string who = k.name.empty() ? "constraint " + std::to_string(c) : k.name;
        auto& terms = out.terms[std::size_t(c)];
        if (k.weight) {
            if (!(std::isfinite(*k.weight) && *k.weight > 0)) throw InvalidInput(who + ".weight: " + std::to_string(*k.weight) + ", expected a finite number > 0");
            out.weighted = true;
        }
        if (k.kind == ConstraintKind::control_point) {
            const auto& idx = k.control_point;
            for (int a = 0; a < 3; ++a)
                if (idx[std::size_t(a)] < 0 || idx[std::size_t(a)] >= n[std::size_t(a)])
                    throw InvalidInput(who + ".control_point: index (" + std::to_string(idx[0]) + ", " + std::to_string(idx[1]) + ", " +
                                       std::to_string(idx[2]) + ") is outside the " + std::to_string(n[0]) + "x" + std::to_string(n[1]) + "x" +
                                       std::to_string(n[2]) + " lattice");
            if (!k.offset.allFinite()) throw InvalidInput(who + ".offset: not finite");
            terms.emplace_back(group[rest.flat_index(idx[0], idx[1], idx[2])], 1.0);
            out.D.row(c) = k.offset.transpose();
            out.hard[std::size_t(c)] = true;
            continue;
        }
        if (k.kind == ConstraintKind::region || k.kind == ConstraintKind::normal || k.kind == ConstraintKind::slide || k.kind == ConstraintKind::plate)
            throw InvalidInput(who + ": a region, normal, slide or frame's plate needs the model's surface: the deform turns it into rows, the solver takes none");
        if (!k.point.allFinite() || !k.to.allFinite()) throw InvalidInput(who + ": point or target is not finite");
        // The parameter of a world point in the rest lattice, inside its closed domain.
        auto parameter = [&](const Eigen::Vector3d& point) {
            Eigen::Vector3d stu;
            try {
                stu = rest.parameter_of(point);
            } catch (const SolverFailure&) {
                throw InvalidInput(who + ": point (" + std::to_string(point.x()) + ", " + std::to_string(point.y()) + ", " +
                                   std::to_string(point.z()) + ") cannot be located in the lattice");
            }
            if (!rest.contains_parameter(stu, 1e-9))
                throw InvalidInput(who + ": point (" + std::to_string(point.x()) + ", " + std::to_string(point.y()) + ", " + std::to_string(point.z()) +
                                   ") lies outside the lattice (parameter " + std::to_string(stu.x()) + ", " + std::to_string(stu.y()) + ", " +
                                   std::to_string(stu.z()) + ")");
            // The parameter domain is closed: a point exactly on a face belongs to the last region, whose basis
            // still gives it full weight (PyGeM#272: such points must move too).
            const auto r = rest.regions();
            for (int a = 0; a < 3; ++a) stu[a] = std::clamp(stu[a], 0.0, double(r[std::size_t(a)]));
            return stu;
        };
        auto add_terms = [&](const std::array<int, 3>& region, const std::array<double, 64>& w, double scale) {
            for (int kk = 0; kk < 4; ++kk)
                for (int j = 0; j < 4; ++j)
                    for (int i = 0; i < 4; ++i)
                        terms.emplace_back(group[rest.flat_index(region[0] + i, region[1] + j, region[2] + kk)], scale * w[std::size_t(i + 4 * (j + 4 * kk))]);
        };
        std::array<int, 3> region;
        std::array<double, 64> w;
        const Eigen::Vector3d stu = parameter(k.point);
        if (k.kind == ConstraintKind::turn) {
            // The derivative along the world direction d: the parameter direction the rest map takes to d. The row
            // is scaled by one lattice spacing, so that it weighs like a point row across one cell.
            if (!k.direction.allFinite() || std::abs(k.direction.norm() - 1) > 1e-9 || !k.rotation.allFinite())
                throw InvalidInput(who + ": a turn needs a unit direction and a finite rotation");
            const double length = rest.spacing().mean();
            rest.derivative_weights(stu, rest.jacobian(stu).inverse() * k.direction, region, w);
            add_terms(region, w, length);
            out.D.row(c) = (length * (k.rotation * k.direction - k.direction)).transpose();
            continue;
        }
        if (k.kind == ConstraintKind::bend) {
            // Scaled by a spacing squared, so that it weighs like a point row across one cell. The rest map's own
            // second derivative (zero but for a clamped lattice's ends) is turned with the rest.
            if (!k.direction.allFinite() || std::abs(k.direction.norm() - 1) > 1e-9 || !k.across.allFinite() || std::abs(k.across.norm() - 1) > 1e-9 ||
                !k.rotation.allFinite())
                throw InvalidInput(who + ": a bend needs two unit directions and a finite rotation");
            const double length = rest.spacing().mean();
            const Eigen::Matrix3d inverse = rest.jacobian(stu).inverse();
            rest.second_derivative_weights(stu, inverse * k.direction, inverse * k.across, region, w);
            add_terms(region, w, length * length);
            out.D.row(c) = (length * length * (k.rotation - Eigen::Matrix3d::Identity()) * rest.combine(region, w)).transpose();
            continue;
        }
        rest.weights(stu, region, w);
        add_terms(region, w, 1.0);
        if (k.kind == ConstraintKind::join) { // x(point) - x(to) = 0: both points' rows, the second subtracted
            rest.weights(parameter(k.to), region, w);
            add_terms(region, w, -1.0);
            out.D.row(c) = (k.to - k.point).transpose();
            continue;
        }
        out.D.row(c) = (k.kind == ConstraintKind::pin ? Eigen::Vector3d::Zero() : Eigen::Vector3d(k.to - k.point)).transpose();
        out.hard[std::size_t(c)] = k.kind == ConstraintKind::pin;
    }
    return out;
}

std::vector<std::pair<int, double>> merged(const std::vector<std::pair<int, double>>& terms) {
    std::map<int, double> sum;
    for (const auto& [q, w] : terms) sum[q] += w;
    return {sum.begin(), sum.end()};
}

} // namespace constraints_internal

using namespace constraints_internal;

ConstraintSolution solve_constraints(const Lattice& rest, const std::vector<Constraint>& constraints, const SolveOptions& options) {
    const ConstraintRows rows = constraint_rows(rest, constraints);
    const std::vector<int>& group = rows.group;
    const int g = rows.groups;
    const Eigen::VectorXd inv_sqrt_mult = rows.multiplicity.cwiseSqrt().cwiseInverse();
    const int m = int(constraints.size());
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(m, g); // rows of B S
    for (int c = 0; c < m; ++c)
        for (const auto& [q, w] : rows.terms[std::size_t(c)]) A(c, q) += w;
    const Eigen::MatrixXd& D = rows.D;
    const std::vector<bool>& hard = rows.hard;
    const bool weighted = rows.weighted;

    // Unknowns no constraint touches stay put in the minimum-norm and in the damped answer alike: drop them,
    // so the dense solves grow with the constraints (at most 64 columns each), not with the lattice.
    std::vector<int> active;
    for (int q = 0; q < g; ++q)
        if (A.col(q).cwiseAbs().maxCoeff() > 0) active.push_back(q);
    const int ga = int(active.size());
    // Work in y = M^1/2 dQ, where the motion of every control point is plain |y|^2.
    Eigen::MatrixXd Ay(m, ga);
    for (int q = 0; q < ga; ++q) Ay.col(q) = A.col(active[std::size_t(q)]) * inv_sqrt_mult[active[std::size_t(q)]];
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(Ay);
    ConstraintSolution out;
    Eigen::MatrixXd dQ_active;
    out.rank = int(cod.rank());
    out.unknowns = g;
    const int g_all = g;
    {
    const int g = ga;
    Eigen::MatrixXd Y(g, 3);
    if (!weighted && out.rank == m) {
        Y = cod.solve(D); // minimum-norm exact solution
    } else {
        out.least_squares = true;
        std::vector<int> hard_rows, soft_rows;
        for (int c = 0; c < m; ++c) (hard[std::size_t(c)] ? hard_rows : soft_rows).push_back(c);
        // Hard rows: y = y0 + N z, y0 their minimum-norm (least-squares if they conflict) solution, N their null space.
        Eigen::MatrixXd Y0 = Eigen::MatrixXd::Zero(g, 3);
        Eigen::MatrixXd N = Eigen::MatrixXd::Identity(g, g);
        if (!hard_rows.empty()) {
            Eigen::MatrixXd H(hard_rows.size(), g), DH(hard_rows.size(), 3);
            for (std::size_t q = 0; q < hard_rows.size(); ++q) H.row(Eigen::Index(q)) = Ay.row(hard_rows[q]), DH.row(Eigen::Index(q)) = D.row(hard_rows[q]);
            Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> hcod(H);
            Y0 = hcod.solve(DH);
            // Null space of H: the last g - rank columns of the orthogonal factor of H^T's QR.
            Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(H.transpose());
            const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(g, g);
            N = Q.rightCols(g - Eigen::Index(qr.rank()));
        }
        const double mean_row = Ay.rowwise().squaredNorm().mean();
        const double lambda = options.damping * (mean_row > 0 ? mean_row : 1.0);
        // Residual rows: sqrt(w_c) (A_c (y0 + N z) - d_c) for soft rows, sqrt(lambda) (y0 + N z) for zero velocity.
        const Eigen::Index residual_rows = Eigen::Index(soft_rows.size()) + g;
        Eigen::MatrixXd J(residual_rows, N.cols());
        Eigen::MatrixXd T(residual_rows, 3);
        for (std::size_t q = 0; q < soft_rows.size(); ++q) {
            const int c = soft_rows[q];
            const double sw = std::sqrt(constraints[std::size_t(c)].weight.value_or(1.0));
            J.row(Eigen::Index(q)) = sw * (Ay.row(c) * N);
            T.row(Eigen::Index(q)) = sw * (D.row(c) - Ay.row(c) * Y0);
        }
        const double sl = std::sqrt(lambda);
        J.bottomRows(g) = sl * N;
        T.bottomRows(g) = -sl * Y0;
        Y = Y0;
        for (int axis = 0; axis < 3; ++axis) Y.col(axis) += N * solve_least_squares(J, T.col(axis));
    }
    dQ_active = Y;
    }
    Eigen::MatrixXd dQ = Eigen::MatrixXd::Zero(g_all, 3);
    for (int q = 0; q < ga; ++q) dQ.row(active[std::size_t(q)]) = dQ_active.row(q) * inv_sqrt_mult[active[std::size_t(q)]];
    out.lattice = rest;
    auto& points = out.lattice.points();
    for (std::size_t p = 0; p < points.size(); ++p) points[p] += dQ.row(group[p]).transpose();
    const Eigen::MatrixXd achieved = A * dQ;
    out.residuals.resize(std::size_t(m));
    for (int c = 0; c < m; ++c) out.residuals[std::size_t(c)] = (achieved.row(c) - D.row(c)).norm();
    return out;
}

} // namespace voxwarp
