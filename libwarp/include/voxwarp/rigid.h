/// @file rigid.h
/// @brief The rotation-aware lattice solve: point constraints met while the map stays as rigid as possible where
///        the model's material is (as-rigid-as-possible, Sorkine & Alexa 2007, measured on the map's own Jacobian),
///        optionally keeping the material's volume; the same volume term also serves the min-norm objective.
///
/// Frames: control points in world units; the energy is dimensionless. The lattice's parameter domain is split
/// into 2 x 2 x 2 cells per region; cell c holds material of mean density rho_c (lattice_material). With F_c the
/// map's world Jacobian at the cell's centre (identity for the undeformed lattice), the energy is
///   sum_c a_c [ |F_c - R_c|^2 + v |F_c - D_c|^2 ]        a_c = rho_c V_c / sum rho V (the material's mass share)
///   + eps/N sum_{i~j} |(P_j - P_i) - R_i (P0_j - P0_i)|^2 / |P0_j - P0_i|^2     (control-point edges, rigid)
///   + mu/N sum_i m_i |P_i - P0_i|^2 / h^2                                      (zero velocity, or min-norm motion)
///   + k sum_soft w_c |B_c P - t_c|^2 / h^2                                     (weighted point constraints)
/// with R_c the rotation nearest F_c, D_c the unit-determinant matrix nearest F_c (preserve_volume: v > 0),
/// N the unknowns, h the mean control-point spacing; pins, control-point offsets and unweighted independent moves
/// hold exactly. Only the material's cells count, so empty space around a model does not stiffen it (its
/// control points follow on their own afterwards, rigidly along the lattice's edges).
///
/// Solved by local/global iterations (Sorkine & Alexa's, and with the volume term Bouaziz et al.'s Projective
/// Dynamics, 2014): the global step's matrix is fixed, so it is factored once and every iteration is a local
/// polar decomposition per cell plus two triangular solves; the material's total volume is held by a linearised
/// constraint in every global step, and the iterations are accelerated after Anderson (Peng et al. 2018).
/// BM_SolveRigid against BM_SolveRigidGraphCeres (solve_rigid_graph_ceres, below) says why that is the default.
#pragma once

#include <voxwarp/constraints.h>
#include <voxwarp/progress.h>

#include <array>
#include <vector>

namespace voxwarp {

struct WarpDomain;

/// How much material each cell of a lattice holds: the domain split into q x q x q cells per region. Cell (x, y, z)
/// covers parameters [x/q, (x+1)/q) x ... . Frame: parameter space of the domain's lattice.
struct LatticeMaterial {
    int per_region = 2;                ///< q
    std::array<int, 3> cells{};        ///< cells per axis: q * (n - 3)
    std::vector<float> density;        ///< mean density of each cell in [0, 1], x fastest
    float at(int x, int y, int z) const { return density[std::size_t(x) + std::size_t(cells[0]) * (std::size_t(y) + std::size_t(cells[1]) * std::size_t(z))]; }
};

/// Mean density of every cell of the domain (uniform placement: the zero padding counts as empty). Parallel.
LatticeMaterial lattice_material(const WarpDomain& domain, int per_region = 2);

/// Per control point (flat index): the basis-weighted mean density of its support, in [0, 1].
std::vector<double> control_point_material(const Lattice& lattice, const LatticeMaterial& material);

struct RigidSolveOptions {
    bool rigid = true;              ///< false: the min-norm objective (least control-point motion) instead of rigidity
    bool preserve_volume = false;   ///< add the volume term v over the material cells
    double empty_weight = 1e-3;     ///< eps: the control-point edges' weight, against the material's 1
    double volume_weight = 10;      ///< v
    double motion_weight = 1e-3;    ///< mu of the min-norm objective (rigid: 1e-6, zero velocity only)
    int max_iterations = 400;       ///< local/global iterations at most
    double tolerance = 1e-4;        ///< stop when no control point moves farther than this fraction of the spacing in an iteration
    ProgressCallback progress;      ///< optional progress / cancel
};

/// Most control points a rigid solve takes (those that shape the material): about a 17^3 lattice full of it.
constexpr int kMaxRigidUnknowns = 5000;

struct RigidSolution : ConstraintSolution {
    int iterations = 0;             ///< iterations taken
};

/// Solve `constraints` on `rest` (an undeformed lattice) with the rigidity and/or volume energy over `material`
/// (lattice_material of the domain the lattice came from). Point constraints without weights are met exactly
/// when their rows are independent, pins and control-point offsets always; residuals as in solve_constraints.
/// Deterministic: the same answer for any thread count.
/// @throw InvalidInput as solve_constraints, or more than kMaxRigidUnknowns unknowns; SolverFailure; Cancelled.
RigidSolution solve_rigid(const Lattice& rest, const std::vector<Constraint>& constraints, const LatticeMaterial& material,
                          const RigidSolveOptions& options = {});

/// The baseline the solve above is measured against (BM_SolveRigidGraphCeres, Rigid.BeatsTheControlPointGraphBaseline): the
/// design card's first sketch, embedded-deformation style. ARAP between axis-neighbouring control points (each
/// star weighted by the material in the point's support, 1e-3 where there is none), a rotation per control point
/// on Ceres' quaternion manifold, every constraint a stiff penalty, Levenberg-Marquardt with sparse Cholesky from
/// the undeformed lattice. Not used by the pipeline.
RigidSolution solve_rigid_graph_ceres(const Lattice& rest, const std::vector<Constraint>& constraints, const LatticeMaterial& material);

/// Volume of the material after the map: sum over cells of rho_c V_c det J(x_c) sampled at 2^3 points per cell,
/// world units^3 (the undeformed lattice gives the material's own volume).
double mapped_material_volume(const Lattice& lattice, const LatticeMaterial& material);

} // namespace voxwarp
