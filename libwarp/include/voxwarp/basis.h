/// @file basis.h
/// @brief The uniform cubic B-spline basis of the papers (True & Hughes 1992, eq. 2) and its per-axis tables.
///
/// B0 = (1-t)^3/6, B1 = (3t^3 - 6t^2 + 4)/6, B2 = (-3t^3 + 3t^2 + 3t + 1)/6, B3 = t^3/6, t in [0, 1] the
/// fractional parameter inside a region. They sum to 1 and are non-negative (a partition of unity).
#pragma once

#include <array>
#include <vector>

namespace voxwarp {

/// The four basis values at t.
inline std::array<double, 4> cubic_basis(double t) {
    const double t2 = t * t, t3 = t2 * t, u = 1.0 - t;
    return {u * u * u / 6.0, (3 * t3 - 6 * t2 + 4) / 6.0, (-3 * t3 + 3 * t2 + 3 * t + 1) / 6.0, t3 / 6.0};
}

/// The four basis derivatives d/dt at t.
inline std::array<double, 4> cubic_basis_derivative(double t) {
    const double t2 = t * t, u = 1.0 - t;
    return {-0.5 * u * u, (9 * t2 - 12 * t) / 6.0, (-9 * t2 + 6 * t + 3) / 6.0, 0.5 * t2};
}

/// The four basis second derivatives d^2/dt^2 at t.
inline std::array<double, 4> cubic_basis_second_derivative(double t) { return {1.0 - t, 3 * t - 2, 1.0 - 3 * t, t}; }

/// Basis values tabulated at the G fractional parameters e/G, e = 0..G-1 (the paper's section 4 table,
/// kept per axis: the tensor-product map is separable, so 3 x G x 4 numbers replace G^3 x 64).
/// Entry [e][i] = B_i(e / G). Entry [G][i] = B_i(1) serves the closed end of the parameter interval.
struct BasisTable {
    int granularity = 0;
    std::vector<std::array<double, 4>> values;
    explicit BasisTable(int granularity);
};

} // namespace voxwarp
