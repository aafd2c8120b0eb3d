// Internal: point constraints as rows of basis weights over the lattice's distinct control points, shared by
// the min-norm solve (constraints.cpp) and the rigid one (rigid.cpp).
#pragma once

#include <voxwarp/constraints.h>

#include <Eigen/Core>

#include <utility>
#include <vector>

namespace voxwarp::constraints_internal {

struct ConstraintRows {
    std::vector<int> group;          ///< flat control point index -> distinct unknown
    int groups = 0;
    Eigen::VectorXd multiplicity;    ///< control points per unknown
    /// Per constraint: (unknown, basis weight) in the order they are summed (an unknown may recur: tripled points).
    std::vector<std::vector<std::pair<int, double>>> terms;
    Eigen::MatrixXd D;               ///< m x 3: the displacement each row asks for, world units
    std::vector<bool> hard;          ///< pins and control-point offsets
    bool weighted = false;           ///< some constraint carries an explicit weight
};

/// Validate the constraints against `rest` and build their rows. @throw InvalidInput (see solve_constraints).
ConstraintRows constraint_rows(const Lattice& rest, const std::vector<Constraint>& constraints);

/// The rows' terms with each unknown once (recurring unknowns summed).
std::vector<std::pair<int, double>> merged(const std::vector<std::pair<int, double>>& terms);

} // namespace voxwarp::constraints_internal
