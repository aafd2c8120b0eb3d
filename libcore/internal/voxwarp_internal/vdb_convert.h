/// @file vdb_convert.h
/// @brief Internal: voxmap <-> OpenVDB FloatGrid conversions shared by voxwarp's libraries.
/// Not installed, not public: it pulls in OpenVDB, which public headers keep out.
#pragma once

#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/voxmap.h>

#include <openvdb/openvdb.h>

#include <string>

namespace voxwarp::vdb_internal {

/// Transform taking grid index (i, j, k) to the world centre of voxmap voxel (i, j, k).
openvdb::math::Transform::Ptr voxmap_transform(const Voxmap& voxmap);
openvdb::math::Transform::Ptr voxmap_transform(const Eigen::Vector3d& origin, double voxel_size);

/// Sparse copy of a voxmap's density (background 0; constant blocks become tiles). Parallel.
openvdb::FloatGrid::Ptr to_density_grid(const Voxmap& voxmap);
openvdb::FloatGrid::Ptr to_density_grid(const SparseVoxmap& voxmap);

/// Dense voxmap of a float grid's active bounding box. Level sets (GRID_LEVEL_SET) are converted to
/// density with a ramp one voxel wide on each side of the zero crossing; other grids are clamped to [0, 1].
/// `source` names the file in messages. @throw InvalidInput, ResourceLimit.
Voxmap from_float_grid(const openvdb::FloatGrid& grid, const std::string& source);
/// The same, block-sparse, its origin moved down to the nearest multiple of 8 voxels (so blocks are leaves).
SparseVoxmap sparse_from_float_grid(const openvdb::FloatGrid& grid, const std::string& source);

} // namespace voxwarp::vdb_internal

namespace voxwarp {
class Progress;
}

namespace voxwarp::vdb_internal {

/// OpenVDB interrupter (start/end/wasInterrupted) reporting through a voxwarp::Progress. It never throws
/// inside OpenVDB; the caller calls progress.check() once the OpenVDB operation has returned.
struct ProgressInterrupter {
    Progress* progress = nullptr;
    void start(const char* = nullptr) {}
    void end() {}
    bool wasInterrupted(int percent = -1);
};

} // namespace voxwarp::vdb_internal
