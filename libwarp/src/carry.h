// The carried voxels of a voxmap (resolve.h: thin on their side, or a face neighbour of a thin voxel on the same
// side), found block by block with bit masks: the fast path's equivalent of is_carried at every voxel.
#pragma once

#include <voxwarp/sparse_voxmap.h>

#include <cstdint>
#include <vector>

namespace voxwarp::warp_internal {

/// The voxmap's carried voxels as indices i + nx (j + ny k), sorted. Only voxels of the voxmap itself (outside it
/// the density is 0 and never carried). Parallel.
std::vector<std::uint64_t> carried_voxels(const SparseVoxmap& voxmap);

} // namespace voxwarp::warp_internal
