/// @file constraints.h
/// @brief Direct manipulation of the lattice (Hsu, Hughes & Kaufman 1992; least squares after Welch, Gleicher
///        & Witkin 1991): "move this point there, keep that one here" solved for the least control-point motion.
///
/// Each point constraint is a row of the basis matrix B (the 64 basis weights of the point's parameter);
/// unknowns are the *distinct* control points: tripled points of the clamped placement share one unknown
/// through the multiplicity selection matrix S, and the motion minimised is that of every control point,
/// sum_i |dP_i|^2 = sum_g mult_g |dQ_g|^2. All positions in world units.
///
/// - Without explicit weights and with independent rows the answer is the minimum-norm exact solution
///   dQ = M^-1/2 (B S M^-1/2)^+ d (the pseudoinverse of DMFFD).
/// - With weights, or rows that are dependent (over-determined or conflicting), it is the weighted least-squares
///   solution found by Ceres, with a small zero-velocity term lambda * sum mult_g |dQ_g|^2 that keeps it minimal;
///   pins and control-point offsets stay hard (exact) there too, by solving in the null space of their rows.
#pragma once

#include <voxwarp/lattice.h>

#include <optional>
#include <string>
#include <vector>

namespace voxwarp {

enum class ConstraintKind {
    move,          ///< world point `point` goes to `to`
    pin,           ///< world point `point` stays where it is (hard)
    control_point, ///< control point `control_point` moves by `offset` (hard)
};

struct Constraint {
    ConstraintKind kind = ConstraintKind::move;
    Eigen::Vector3d point = Eigen::Vector3d::Zero();  ///< move / pin: world point on the current shape
    Eigen::Vector3d to = Eigen::Vector3d::Zero();     ///< move: target world point
    std::array<int, 3> control_point{0, 0, 0};        ///< control_point: lattice index (i, j, k)
    Eigen::Vector3d offset = Eigen::Vector3d::Zero(); ///< control_point: world displacement
    std::optional<double> weight;                     ///< explicit weight (> 0): the set is solved as weighted least squares
    std::string name;                                 ///< where it came from, for messages (e.g. "edits[0].constraints[2]")
};

struct SolveOptions {
    double damping = 1e-6; ///< zero-velocity weight lambda, relative to the mean squared basis-row norm
};

struct ConstraintSolution {
    Lattice lattice;                  ///< the moved lattice
    std::vector<double> residuals;    ///< per constraint, world units: |B_c dP - d_c| (0 for satisfied constraints)
    bool least_squares = false;       ///< true when solved as weighted least squares (Ceres)
    int rank = 0;                     ///< rank of the constraint rows
    int unknowns = 0;                 ///< distinct control points (columns of B S)
};

/// Solve for the control-point motion of `rest` (an undeformed lattice) that satisfies `constraints`.
/// @throw InvalidInput for a point outside the lattice's domain, a control-point index outside the lattice,
///        a non-positive or non-finite weight, or no constraints; SolverFailure if Ceres fails.
ConstraintSolution solve_constraints(const Lattice& rest, const std::vector<Constraint>& constraints, const SolveOptions& options = {});

/// Distinct control points of a lattice: group[p] is the unknown that control point p (flat index) belongs to;
/// points at the same rest position (the clamped placement's tripled ends) share one. Returns the group count.
int control_point_groups(const Lattice& lattice, std::vector<int>& group);

} // namespace voxwarp
