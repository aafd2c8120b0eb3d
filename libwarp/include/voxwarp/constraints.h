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
    turn,          ///< the map's derivative at `point` along the world unit vector `direction` becomes `rotation * direction`
                   ///< (a frame handle's orientation is three of these; `to` is its point's target, for split edits)
    join,          ///< world points `point` and `to` end at the same place (wherever the least motion puts it)
    region,        ///< the material inside `region` follows the rigid motion x -> rotation (x - pivot) + pivot + offset:
                   ///< expanded by the deform into moves of points of the material there
    normal,        ///< the surface normal at `point` ends along `direction` (unit): expanded by the deform into two
                   ///< turns of the surface's tangents by the least rotation from its normal there to `direction`
    slide,         ///< the surface passes through `to` (= `point`): expanded by the deform into a move of the surface
                   ///< point nearest to it
    plate,         ///< a frame's grip on the surface: the surface around `point` turns with `rotation` as a rigid plate
                   ///< (stays flat and unstretched). Expanded by the deform into three bends along the surface's
                   ///< tangent plane there; into none when no surface lies within a voxel and a half of the point
    bend,          ///< the map's second derivative at `point` along the world unit vectors `direction` and `across`
                   ///< becomes `rotation` times the undeformed one (`to`: its point's target, for split edits)
};

/// The shape of a region constraint: a sphere (centre, radius) or an axis-aligned box (lo, hi), world units.
struct RegionShape {
    bool sphere = true;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero(), lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
    double radius = 0;
    bool contains(const Eigen::Vector3d& p) const {
        return sphere ? (p - centre).squaredNorm() <= radius * radius : (p.array() >= lo.array()).all() && (p.array() <= hi.array()).all();
    }
};

struct Constraint {
    ConstraintKind kind = ConstraintKind::move;
    Eigen::Vector3d point = Eigen::Vector3d::Zero();  ///< move / pin: world point on the current shape
    Eigen::Vector3d to = Eigen::Vector3d::Zero();     ///< move: target world point
    std::array<int, 3> control_point{0, 0, 0};        ///< control_point: lattice index (i, j, k)
    Eigen::Vector3d offset = Eigen::Vector3d::Zero(); ///< control_point: world displacement
    Eigen::Vector3d direction = Eigen::Vector3d::UnitX();     ///< turn, bend: world unit vector
    Eigen::Vector3d across = Eigen::Vector3d::UnitY();        ///< bend: the second world unit vector
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();   ///< turn, region, plate, bend: the rotation
    Eigen::Vector3d pivot = Eigen::Vector3d::Zero();          ///< region: the rotation's fixed point (offset: the translation)
    RegionShape region;                                       ///< region: where
    std::optional<double> weight;                     ///< explicit weight (> 0): the set is solved as weighted least squares
    std::string name;                                 ///< where it came from, for messages (e.g. "edits[0].constraints[2]")
    /// The edit file's entry when it became several rows ("frame": a move, three turns and a plate; "region": moves;
    /// "connect" with "at": two moves); empty otherwise. Rows of one entry share its name.
    std::string entry;
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
