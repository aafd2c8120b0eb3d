// The last step of the splat (paper section 6), shared by the fast path and the naive reference: turn a target
// voxel's accumulated weight and weighted value into a density.
//
// The paper: density = wv if weight < 1, else wv / weight. Its "wv if weight < 1" treats the part of a voxel that
// no splat covered as empty, which is right at the edge of the warped data and wrong inside it: there the
// box-filter approximation leaves small coverage gaps (a few percent under rotation) that the paper's rule
// turns into dips of density inside the solid. So the uncovered part takes the density of the side the voxel
// is on: outside (wv >= weight / 2 fails) it is empty, as in the paper; inside it is full. A voxel no splat
// touched takes the side of the last touched voxel before it along its x row (rows start outside: the target
// covers the warped domain and a margin, and the domain's border is empty).
//
// That rule is what lets the fast path splat only the narrow band around the surface: deep inside and far
// outside, the skipped voxels are pure (density exactly 1 or 0), so they would only confirm the side.
#pragma once

#include <algorithm>
#include <cstdint>

namespace voxwarp::warp_internal {

/// Density of a target voxel with weight `w` and weighted value `v` (any units, `one` = full coverage).
/// `inside` carries the side along a row: read for an untouched voxel, updated by a touched one.
template <class T>
inline float resolve_density(T w, T v, T one, bool& inside) {
    if (w <= 0) return inside ? 1.0f : 0.0f;
    inside = 2.0 * double(v) >= double(w);
    double d;
    if (w >= one) d = double(v) / double(w);
    else d = (double(v) + (inside ? double(one - w) : 0.0)) / double(one);
    return float(std::clamp(d, 0.0, 1.0));
}

} // namespace voxwarp::warp_internal
