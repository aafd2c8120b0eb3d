/// @file foldover.h
/// @brief Where a deformed lattice map stops being injective: the paper's admitted limitation, detected.
#pragma once

#include <voxwarp/lattice.h>

#include <array>
#include <vector>

namespace voxwarp {

/// A region in which the map folds over (Jacobian determinant <= 0 at some sample).
struct Fold {
    std::array<int, 3> region{};          ///< region (a, b, c); its control points are (a..a+3, b..b+3, c..c+3)
    double min_determinant = 0;           ///< smallest det(dB/d(s,t,u)) seen, world units^3 per parameter unit^3
    Eigen::Vector3d parameter;            ///< where it was seen (s, t, u)
};

/// Sample det J on a (samples+1)^3 grid in every region (including its faces) and report the regions where
/// it is <= `threshold` times the undeformed determinant scale (default 0: folded or degenerate). Parallel.
/// The clamped placement's tripled end points give det = 0 on the domain's faces by construction; those face
/// samples are not reported.
std::vector<Fold> find_folds(const Lattice& lattice, int samples = 4, double threshold = 0.0);

} // namespace voxwarp
