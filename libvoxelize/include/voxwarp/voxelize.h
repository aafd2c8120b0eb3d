/// @file voxelize.h
/// @brief Mesh -> antialiased voxmap (density in [0, 1], surface at 0.5), robust to open and non-manifold scans.
///
/// The density is a linear ramp of the signed distance to the surface: density = 0.5 - d / (2 * ramp * h),
/// clamped to [0, 1], with d > 0 outside (world units). Along every voxel edge that crosses the surface both
/// ends lie within one voxel of it, so with ramp >= 1 the 0.5 crossing interpolated between voxel centres
/// lands exactly where the surface crosses that edge (for a locally flat surface).
///
/// Inside/outside: a watertight, consistently oriented mesh is signed by OpenVDB's level-set construction, unless
/// that flood fill loses the mesh's surface or its walls are thinner than a voxel (then, with SignMethod::automatic,
/// the winding number takes over, and VoxelizeReport says why); anything else (holes, non-manifold edges,
/// inconsistent orientation) by the generalized winding number thresholded at 0.5, which closes small holes with a minimal-looking cap and ignores stray triangles.
/// On that path walls thinner than a voxel are kept closed (a voxel next to the wall is made inside) and the
/// densities next to the surface are refit so that the 0.5 crossing along each voxel edge lands where the mesh
/// crosses that edge. Open sheets enclose no volume and vanish from the voxmap.
#pragma once

#include <voxwarp/progress.h>
#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/surface_samples.h>
#include <voxwarp/triangle_mesh.h>
#include <voxwarp/voxmap.h>

#include <cstdint>
#include <string>

namespace voxwarp {

/// How voxelize decides which voxels are inside.
enum class SignMethod {
    automatic,      ///< flood_fill for watertight oriented meshes whose flood fill holds, winding_number otherwise
    flood_fill,     ///< OpenVDB meshToLevelSet: fast, exact for watertight input, leaks through holes
    winding_number, ///< generalized winding number, inside where |w| >= 0.5: robust to holes, non-manifold spots and parts wound inside out
};

/// What voxelize did, for reports.
struct VoxelizeReport {
    SignMethod sign = SignMethod::automatic; ///< the inside/outside test it used
    std::string note;                        ///< why `automatic` gave up the flood fill for winding numbers; empty otherwise
};

/// "auto", "flood-fill" or "winding-number".
const char* to_string(SignMethod method);
/// The method a name gives (to_string's names). @throw InvalidInput for any other name.
SignMethod parse_sign(const std::string& name);

struct VoxelizeOptions {
    int resolution = 128;         ///< voxels along the mesh's longest bounding-box side (used when voxel_size <= 0)
    double voxel_size = 0;        ///< h in world units; > 0 overrides resolution
    int padding_voxels = 3;       ///< empty voxels between the mesh's bounds and the voxmap border (>= ramp + 1)
    double ramp_voxels = 1.0;     ///< half-width of the antialiasing ramp across the surface, voxels (>= 1 exact for flat surfaces)
    SignMethod sign = SignMethod::automatic;
    std::uint64_t max_memory_bytes = 0; ///< refuse requests estimated above this; 0 = 90 % of available memory
    ProgressCallback progress;          ///< optional progress / cancel
    VoxelizeReport* report = nullptr;   ///< optional: filled with what voxelize did
};

/// Voxel size and grid that voxelize would use for this mesh and these options (no heavy work).
/// @throw InvalidInput for an empty mesh, non-finite coordinates, a resolution outside [4, 8192], a
///        non-positive voxel size, or a grid with more than 2^31 voxels along an axis.
Voxmap voxelize_frame(const TriangleMesh& mesh, const VoxelizeOptions& options = {});

/// Area of the mesh's faces in voxels (units of h^2): what the memory of level sets, sparse voxmaps and warps
/// grows with.
double surface_voxels(const TriangleMesh& mesh, const VoxelizeOptions& options = {});

/// Estimated peak bytes voxelize (or, with `sparse`, voxelize_sparse) needs for this mesh and these options.
std::uint64_t voxelize_memory_estimate(const TriangleMesh& mesh, const VoxelizeOptions& options = {}, bool sparse = false);

/// Sign method `automatic` resolves to for this mesh.
SignMethod resolve_sign_method(const TriangleMesh& mesh);

/// Hermite data for the feature mesher (extract.h): the mesh's faces within 3 voxels of its sharp edges (two faces
/// meeting at more than `angle_degrees`), cut into triangles at most a voxel across. Empty for a mesh without
/// sharp edges. World units; `voxel_size` is the voxmap's.
FeatureSurface sharp_feature_surface(const TriangleMesh& mesh, double voxel_size, double angle_degrees = 35);

/// Voxelize a mesh (world units) into an antialiased voxmap whose voxel (0,0,0) centre sits padding_voxels
/// voxels below the mesh's minimum corner. Parallel (oneTBB).
/// @throw InvalidInput (see voxelize_frame), ResourceLimit when the estimate exceeds the memory limit,
///        Cancelled when the progress callback returns false.
Voxmap voxelize(const TriangleMesh& mesh, const VoxelizeOptions& options = {});

/// The same voxmap, block-sparse: on the flood-fill path OpenVDB's level-set leaves become the blocks directly,
/// so memory follows the surface's area (the winding-number path still builds the dense volume first).
SparseVoxmap voxelize_sparse(const TriangleMesh& mesh, const VoxelizeOptions& options = {});

} // namespace voxwarp
