// The constraint solver against closed forms and independent dense solves.
#include <voxwarp/constraints.h>
#include <voxwarp/errors.h>

#include <Eigen/Geometry>
#include <Eigen/SVD>

#include <gtest/gtest.h>

#include <random>

namespace voxwarp {
namespace {

Constraint move(const Eigen::Vector3d& p, const Eigen::Vector3d& to, std::optional<double> weight = {}) {
    Constraint c;
    c.kind = ConstraintKind::move, c.point = p, c.to = to, c.weight = weight;
    return c;
}

Constraint pin(const Eigen::Vector3d& p) {
    Constraint c;
    c.kind = ConstraintKind::pin, c.point = c.to = p;
    return c;
}

/// Dense basis matrix over all control points (flat index), computed from the basis directly.
Eigen::MatrixXd basis_matrix(const Lattice& l, const std::vector<Eigen::Vector3d>& points) {
    Eigen::MatrixXd B = Eigen::MatrixXd::Zero(Eigen::Index(points.size()), Eigen::Index(l.control_point_count()));
    for (std::size_t r = 0; r < points.size(); ++r) {
        std::array<int, 3> region;
        std::array<double, 64> w;
        l.weights(l.parameter_of(points[r]), region, w);
        for (int k = 0; k < 4; ++k)
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i) B(Eigen::Index(r), Eigen::Index(l.flat_index(region[0] + i, region[1] + j, region[2] + k))) += w[std::size_t(i + 4 * (j + 4 * k))];
    }
    return B;
}

Eigen::MatrixXd displacement(const Lattice& rest, const Lattice& moved) {
    Eigen::MatrixXd d(rest.control_point_count(), 3);
    for (std::size_t p = 0; p < rest.control_point_count(); ++p) d.row(Eigen::Index(p)) = (moved.points()[p] - rest.points()[p]).transpose();
    return d;
}

const Lattice kRest = Lattice::uniform({7, 6, 8}, {-1, -2, -0.5}, {0.5, 0.8, 0.4});

TEST(Constraints, SingleMoveIsTheDMFFDClosedForm) {
    const Eigen::Vector3d p(0.37, 0.11, 0.63), d(0.05, -0.02, 0.08);
    const ConstraintSolution s = solve_constraints(kRest, {move(p, p + d)});
    EXPECT_FALSE(s.least_squares);
    // Hsu et al.: dP_i = B_i d / sum_j B_j^2.
    std::array<int, 3> region;
    std::array<double, 64> w;
    kRest.weights(kRest.parameter_of(p), region, w);
    double sum_sq = 0;
    for (double x : w) sum_sq += x * x;
    for (int k = 0; k < 4; ++k)
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i) {
                const Eigen::Vector3d expected = w[std::size_t(i + 4 * (j + 4 * k))] * d / sum_sq;
                const Eigen::Vector3d got = s.lattice.point(region[0] + i, region[1] + j, region[2] + k) - kRest.point(region[0] + i, region[1] + j, region[2] + k);
                EXPECT_NEAR((got - expected).norm(), 0.0, 1e-12);
            }
    EXPECT_NEAR((s.lattice.evaluate(kRest.parameter_of(p)) - (p + d)).norm(), 0.0, 1e-12);
}

TEST(Constraints, EqualsIndependentPseudoinverseAndHasLeastNorm) {
    std::mt19937 rng(2);
    std::uniform_real_distribution<double> u(0, 1), n(-0.1, 0.1);
    std::vector<Eigen::Vector3d> points;
    std::vector<Constraint> cs;
    for (int c = 0; c < 6; ++c) {
        const Eigen::Vector3d p = kRest.evaluate(Eigen::Vector3d(u(rng) * 4, u(rng) * 3, u(rng) * 5));
        points.push_back(p);
        cs.push_back(move(p, p + Eigen::Vector3d(n(rng), n(rng), n(rng))));
    }
    const ConstraintSolution s = solve_constraints(kRest, cs);
    const Eigen::MatrixXd B = basis_matrix(kRest, points);
    Eigen::MatrixXd D(6, 3);
    for (int c = 0; c < 6; ++c) D.row(c) = (cs[std::size_t(c)].to - cs[std::size_t(c)].point).transpose();
    const Eigen::MatrixXd expected = B.jacobiSvd(Eigen::ComputeThinU | Eigen::ComputeThinV).solve(D);
    const Eigen::MatrixXd got = displacement(kRest, s.lattice);
    EXPECT_LE((got - expected).cwiseAbs().maxCoeff(), 1e-10);
    EXPECT_LE((B * got - D).cwiseAbs().maxCoeff(), 1e-10);
    // Any other feasible answer (plus a null-space direction of B) moves the control points more.
    Eigen::FullPivLU<Eigen::MatrixXd> lu(B);
    const Eigen::MatrixXd null = lu.kernel();
    ASSERT_GT(null.cols(), 0);
    for (int q = 0; q < 5; ++q) {
        const Eigen::MatrixXd other = got + null.col(q * 7 % null.cols()) * Eigen::RowVector3d(0.01, -0.02, 0.03);
        EXPECT_LE((B * other - D).cwiseAbs().maxCoeff(), 1e-10);
        EXPECT_GT(other.squaredNorm(), got.squaredNorm());
    }
}

TEST(Constraints, TripledPointsOfTheClampedLatticeMoveTogether) {
    const Lattice clamped = Lattice::clamped({7, 7, 7}, {0, 0, 0}, {4, 4, 4});
    const Eigen::Vector3d p(0.2, 0.3, 0.25); // near the corner the tripled points shape
    const ConstraintSolution s = solve_constraints(clamped, {move(p, p + Eigen::Vector3d(0.1, 0.1, -0.05))});
    const Eigen::Vector3d corner = s.lattice.point(0, 0, 0) - clamped.point(0, 0, 0);
    EXPECT_GT(corner.norm(), 0.0);
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) EXPECT_NEAR((s.lattice.point(i, j, k) - clamped.point(i, j, k) - corner).norm(), 0.0, 1e-12);
    EXPECT_NEAR((s.lattice.evaluate(clamped.parameter_of(p)) - (p + Eigen::Vector3d(0.1, 0.1, -0.05))).norm(), 0.0, 1e-9);
}

TEST(Constraints, InconsistentSetMatchesDenseWeightedLeastSquares) {
    const Eigen::Vector3d p(0.4, -0.5, 0.7), q(0.9, -1.2, 0.4);
    const std::vector<Constraint> cs{move(p, p + Eigen::Vector3d(0.1, 0, 0), 1.0), move(p, p + Eigen::Vector3d(0, 0.2, 0), 3.0),
                                     move(q, q + Eigen::Vector3d(0, 0, 0.05), 2.0)};
    const ConstraintSolution s = solve_constraints(kRest, cs);
    EXPECT_TRUE(s.least_squares);
    // Independent dense solve: minimise sum w |B_c x - d_c|^2 + lambda |x|^2 over all control points.
    const Eigen::MatrixXd B = basis_matrix(kRest, {p, p, q});
    const Eigen::Vector3d w(1, 3, 2);
    Eigen::MatrixXd D(3, 3);
    for (int c = 0; c < 3; ++c) D.row(c) = (cs[std::size_t(c)].to - cs[std::size_t(c)].point).transpose();
    // The solver's zero-velocity weight: 1e-6 times the mean squared row norm of the touched columns.
    const double lambda = 1e-6 * B.rowwise().squaredNorm().mean();
    const Eigen::MatrixXd lhs = B.transpose() * w.asDiagonal() * B + lambda * Eigen::MatrixXd::Identity(B.cols(), B.cols());
    const Eigen::MatrixXd expected = lhs.ldlt().solve(B.transpose() * w.asDiagonal() * D);
    // The reference's normal equations with lambda ~ 1e-6 lose about six digits: agree to 1e-6 on moves of ~0.1.
    EXPECT_LE((displacement(kRest, s.lattice) - expected).cwiseAbs().maxCoeff(), 1e-6);
    // The conflicting pair meets in the weighted mean of its wishes.
    const Eigen::Vector3d achieved = s.lattice.evaluate(kRest.parameter_of(p)) - p;
    EXPECT_NEAR(achieved.x(), 0.1 * 1 / 4, 1e-4);
    EXPECT_NEAR(achieved.y(), 0.2 * 3 / 4, 1e-4);
    EXPECT_GT(s.residuals[0], 0.01);
}

TEST(Constraints, PinsStayExactInLeastSquares) {
    const Eigen::Vector3d p(0.4, -0.5, 0.7), anchor(0.6, -0.4, 0.6);
    const ConstraintSolution s =
        solve_constraints(kRest, {move(p, p + Eigen::Vector3d(0.2, 0, 0), 1.0), move(p, p + Eigen::Vector3d(0.1, 0, 0), 1.0), pin(anchor)});
    EXPECT_TRUE(s.least_squares);
    EXPECT_LE(s.residuals[2], 1e-12);
    EXPECT_LE((s.lattice.evaluate(kRest.parameter_of(anchor)) - anchor).norm(), 1e-12);
    EXPECT_NEAR((s.lattice.evaluate(kRest.parameter_of(p)) - p).x(), 0.15, 1e-3);
}

TEST(Constraints, PointOnTheDomainBoundaryMoves) {
    const auto r = kRest.regions();
    const Eigen::Vector3d corner = kRest.evaluate(Eigen::Vector3d(r[0], r[1], r[2])); // the far corner, closed domain
    const ConstraintSolution s = solve_constraints(kRest, {move(corner, corner + Eigen::Vector3d(0.1, 0, 0))});
    EXPECT_NEAR((s.lattice.evaluate(Eigen::Vector3d(r[0], r[1], r[2])) - corner - Eigen::Vector3d(0.1, 0, 0)).norm(), 0.0, 1e-12);
}

TEST(Constraints, DerivativeWeightsAreTheJacobian) {
    // On a lattice with every control point moved at random, the derivative weights reproduce the Jacobian the
    // lattice computes, and that matches central differences of the map.
    Lattice l = Lattice::clamped({7, 6, 8}, {-1, -2, -0.5}, {2, 1, 1.5});
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> jitter(-0.05, 0.05);
    for (auto& p : l.points()) p += Eigen::Vector3d(jitter(rng), jitter(rng), jitter(rng));
    for (const Eigen::Vector3d& stu : {Eigen::Vector3d(0.3, 1.7, 2.2), Eigen::Vector3d(3.9, 0.1, 4.5), Eigen::Vector3d(2.0, 3.0, 0.0)}) {
        const Eigen::Matrix3d J = l.jacobian(stu);
        for (int a = 0; a < 3; ++a) {
            const Eigen::Vector3d d = Eigen::Vector3d(0.3, -0.7, 0.5).normalized() + Eigen::Vector3d::Unit(a);
            std::array<int, 3> region;
            std::array<double, 64> w;
            l.derivative_weights(stu, d, region, w);
            const Eigen::Vector3d sum = l.combine(region, w);
            EXPECT_LE((sum - J * d).norm(), 1e-12);
            const double e = 1e-6;
            EXPECT_LE(((l.evaluate(stu + e * d) - l.evaluate(stu - e * d)) / (2 * e) - J * d).norm(), 1e-7);
        }
    }
}

TEST(Constraints, SecondDerivativeWeightsAreTheMapsCurvature) {
    // On the same jittered clamped lattice: the weights of the second derivative along two parameter directions
    // against central differences of the Jacobian the lattice computes.
    Lattice l = Lattice::clamped({7, 6, 8}, {-1, -2, -0.5}, {2, 1, 1.5});
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> jitter(-0.05, 0.05);
    for (auto& p : l.points()) p += Eigen::Vector3d(jitter(rng), jitter(rng), jitter(rng));
    for (const Eigen::Vector3d& stu : {Eigen::Vector3d(0.3, 1.7, 2.2), Eigen::Vector3d(3.6, 0.4, 4.5), Eigen::Vector3d(2.5, 2.5, 0.5)})
        for (const auto& [a, b] : {std::pair{Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(1, 0, 0)}, std::pair{Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, 0, 1)},
                                   std::pair{Eigen::Vector3d(0.3, -0.7, 0.5), Eigen::Vector3d(-0.2, 0.4, 0.9)}}) {
            std::array<int, 3> region;
            std::array<double, 64> w;
            l.second_derivative_weights(stu, a, b, region, w);
            const Eigen::Vector3d sum = l.combine(region, w);
            const double e = 1e-5;
            const Eigen::Vector3d differences = (l.jacobian(stu + e * a) - l.jacobian(stu - e * a)) * b / (2 * e);
            EXPECT_LE((sum - differences).norm(), 1e-6 * (1 + differences.norm())) << stu.transpose() << " | " << a.transpose() << " | " << b.transpose();
        }
}

TEST(Constraints, BendRowsHoldAPlateFlatAsItTurns) {
    // A frame's point, its turn and the three bends of a plate across (x, y): solved exactly, the solved map's
    // second derivatives along the plate are zero (the rest map's, turned), while one across it is left free.
    const Eigen::Vector3d P(0.5, 0.4, 1.1), Q(0.6, 0.2, 1.3);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(0.6, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
    std::vector<Constraint> cs{move(P, Q), move(Eigen::Vector3d(0.5, 0.4, 0.3), Eigen::Vector3d(0.9, 0.4, 0.3))};
    const Eigen::Vector3d t1 = Eigen::Vector3d::UnitX(), t2 = Eigen::Vector3d::UnitY();
    for (const auto& [a, b] : {std::pair{t1, t1}, std::pair{t1, t2}, std::pair{t2, t2}}) {
        Constraint bend = cs[0];
        bend.kind = ConstraintKind::bend, bend.direction = a, bend.across = b, bend.rotation = R;
        cs.push_back(bend);
    }
    const ConstraintSolution s = solve_constraints(kRest, cs);
    EXPECT_FALSE(s.least_squares);
    for (double r : s.residuals) EXPECT_LE(r, 1e-10);
    const Eigen::Vector3d stu = kRest.parameter_of(P);
    const Eigen::Matrix3d to_parameter = kRest.jacobian(stu).inverse();
    auto curvature = [&](const Lattice& l, const Eigen::Vector3d& a, const Eigen::Vector3d& b) { // world units (P sits on a knot)
        std::array<int, 3> region;
        std::array<double, 64> w;
        l.second_derivative_weights(stu, to_parameter * a, to_parameter * b, region, w);
        return l.combine(region, w);
    };
    for (const auto& [a, b] : {std::pair{t1, t1}, std::pair{t1, t2}, std::pair{t2, t2}})
        EXPECT_LE((curvature(s.lattice, a, b) - R * curvature(kRest, a, b)).norm(), 1e-9);
    // The second move, below P, bends the map across the plate: that curvature is not held.
    EXPECT_GT(curvature(s.lattice, Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitZ()).norm(), 0.1);
    // A plate is the deform's to expand (it needs the surface's tangent plane): handed to the solver it is refused.
    Constraint plate = cs[0];
    plate.kind = ConstraintKind::plate;
    EXPECT_THROW(solve_constraints(kRest, {plate}), InvalidInput);
}

TEST(Constraints, FrameRowsTurnTheMapAndJoinRowsJoinPoints) {
    // A frame (a move and three turn rows) and a join, solved exactly: the solved map, evaluated on its own, takes
    // the frame's point to its target with the asked rotation as its Jacobian (in world units), and the two joined
    // points to one place.
    const Eigen::Vector3d P(0.5, 0.4, 1.1), Q(0.6, 0.2, 1.3), A(0.2, -0.6, 0.3), B(0.8, -0.2, 0.5);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(0.6, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
    std::vector<Constraint> cs{move(P, Q)};
    for (int a = 0; a < 3; ++a) {
        Constraint t = cs[0];
        t.kind = ConstraintKind::turn, t.direction = Eigen::Vector3d::Unit(a), t.rotation = R;
        cs.push_back(t);
    }
    Constraint join;
    join.kind = ConstraintKind::join, join.point = A, join.to = B;
    cs.push_back(join);
    const ConstraintSolution s = solve_constraints(kRest, cs);
    EXPECT_FALSE(s.least_squares);
    for (double r : s.residuals) EXPECT_LE(r, 1e-10);
    const Eigen::Vector3d stu = kRest.parameter_of(P);
    EXPECT_LE((s.lattice.evaluate(stu) - Q).norm(), 1e-10);
    const Eigen::Matrix3d world = s.lattice.jacobian(stu) * kRest.jacobian(stu).inverse();
    EXPECT_LE((world - R).norm(), 1e-9);
    EXPECT_LE((s.lattice.evaluate(kRest.parameter_of(A)) - s.lattice.evaluate(kRest.parameter_of(B))).norm(), 1e-10);
    // A region is the deform's to expand: handed to the solver as one row it is refused with its name.
    Constraint region;
    region.kind = ConstraintKind::region, region.name = "edits[0].constraints[4]";
    EXPECT_THROW(solve_constraints(kRest, {region}), InvalidInput);
}

TEST(Constraints, RejectsPointsOutsideAndBadIndices) {
    EXPECT_THROW(solve_constraints(kRest, {move({50, 0, 0}, {51, 0, 0})}), InvalidInput);
    Constraint c;
    c.kind = ConstraintKind::control_point;
    c.control_point = {7, 0, 0};
    EXPECT_THROW(solve_constraints(kRest, {c}), InvalidInput);
    EXPECT_THROW(solve_constraints(kRest, {move({0.1, 0.1, 0.1}, {0.2, 0.1, 0.1}, -1.0)}), InvalidInput);
    EXPECT_THROW(solve_constraints(kRest, {}), InvalidInput);
}

} // namespace
} // namespace voxwarp
