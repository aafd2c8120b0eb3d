/// @file vdb_io.h
/// @brief Voxmaps in and out of OpenVDB .vdb files (for Houdini, Blender and OpenVDB's tools).
///
/// A voxmap is stored as a FloatGrid named "density" with class "fog volume": voxel values are the density
/// in [0, 1], background 0, the grid's transform has the voxmap's voxel size and origin (voxel (0,0,0) of
/// the voxmap is index (0,0,0) of the grid). Metadata: "voxwarp_density_convention" = "density in [0,1],
/// surface at 0.5", "voxwarp_dims" (x, y, z counts). Reading accepts any float grid: a level set (class
/// "level set") is converted to density with a one-voxel ramp on each side of its zero crossing.
#pragma once

#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/voxmap.h>

#include <string>

namespace voxwarp {

/// Write `voxmap` to `path` (temp file + rename). @throw IOError on failure.
void write_vdb(const Voxmap& voxmap, const std::string& path);
void write_vdb(const SparseVoxmap& voxmap, const std::string& path);

/// Read the first float grid of a .vdb file in the file's order (or the first named `grid_name` when given) as a
/// voxmap covering the grid's active bounding box (plus the stored dims when written by voxwarp). Only that grid is
/// read, after its bytes are checked as far as OpenVDB's reader trusts them.
/// @throw IOError when the file cannot be opened; InvalidInput when it is truncated or damaged, holds no float grid,
///        the grid is empty, its transform is not a uniform scale + translation, or it holds non-finite values;
///        ResourceLimit when the voxmap would outgrow the memory available.
Voxmap read_vdb(const std::string& path, const std::string& grid_name = {});

/// The same grid, block-sparse (memory along the surface only). Its origin is moved down to a multiple of 8 of
/// the grid's index space, so each block is one of the grid's leaves; the extra voxels hold the grid's values.
/// @throw as read_vdb.
SparseVoxmap read_vdb_sparse(const std::string& path, const std::string& grid_name = {});

} // namespace voxwarp
