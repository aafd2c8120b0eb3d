// Trilinear interpolation shared by the dense and the block-sparse voxmap.
#pragma once

#include <Eigen/Core>

#include <cmath>
#include <cstdint>

namespace voxwarp::core_internal {

/// Trilinear value at continuous index-space position p of the voxels `value(i, j, k)` gives.
template <class F>
float trilinear(const Eigen::Vector3d& p, F&& value) {
    const double fx = std::floor(p.x()), fy = std::floor(p.y()), fz = std::floor(p.z());
    const std::int64_t i0 = std::int64_t(fx), j0 = std::int64_t(fy), k0 = std::int64_t(fz);
    const double tx = p.x() - fx, ty = p.y() - fy, tz = p.z() - fz;
    double result = 0;
    for (int dk = 0; dk < 2; ++dk)
        for (int dj = 0; dj < 2; ++dj)
            for (int di = 0; di < 2; ++di) {
                const double w = (di ? tx : 1 - tx) * (dj ? ty : 1 - ty) * (dk ? tz : 1 - tz);
                if (w != 0) result += w * double(value(i0 + di, j0 + dj, k0 + dk));
            }
    return float(result);
}

} // namespace voxwarp::core_internal
