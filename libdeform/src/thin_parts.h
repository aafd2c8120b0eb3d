// Internal to libdeform: finding the parts of a model that the voxmap loses (ThinPart in deform.h).
#pragma once

#include <voxwarp/deform.h>
#include <voxwarp/lattice.h>

#include <cstdint>
#include <tuple>
#include <vector>

namespace voxwarp::deform_internal {

/// Samples of the input mesh's surface (one per two voxels of area), carried through every step of every edit
/// as the space is, and checked against the voxmap each stage leaves: a sample with no voxel of density >= 0.5
/// within about a voxel and a half is surface the voxmap no longer holds. Lost samples are grouped into parts,
/// whose thickness (where it was lost) is measured by rays through the input mesh carried the same way.
class SurfaceProbe {
public:
    static constexpr int kVoxelize = -1; ///< the stage of voxelizing; edits are 0, 1, ...

    SurfaceProbe(const TriangleMesh& mesh, double voxel_size);
    /// One warp step of edit `edit`: the samples go where `moved` takes them.
    void push(const Lattice& rest, const Lattice& moved, int edit);
    /// Mark the samples still held until now that `voxmap` (the result of `stage`) no longer holds.
    void check(const SparseVoxmap& voxmap, int stage);
    /// The lost parts thinner than 1.5 voxels where they were lost (largest first, at most 16), with the voxel size
    /// that would keep each; `resolution` is the one the run used (voxels along the model's longest side).
    std::vector<ThinPart> parts(double resolution) const;

private:
    Eigen::Vector3d carry(Eigen::Vector3d p, int stage) const; ///< a rest point through the edits up to `stage`

    const TriangleMesh& mesh_;      ///< the input (outlives the probe)
    TriangleMesh storage_;          ///< its triangles when it has quads
    const std::vector<std::array<std::int32_t, 3>>& triangles_;
    double h_;
    std::vector<Eigen::Vector3d> rest_, at_, normal_;
    std::vector<std::int32_t> face_;
    std::vector<double> area_;            ///< world units^2 each sample stands for
    std::vector<int> lost_;               ///< the stage that lost the sample, or kHeld
    std::vector<std::tuple<int, Lattice, Lattice>> steps_; ///< (edit, rest, moved) in order
    static constexpr int kHeld = -2;
};

} // namespace voxwarp::deform_internal
