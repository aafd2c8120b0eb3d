/// @file session.h
/// @brief A deform in progress, for interactive front ends (the editor's server): the input mesh voxelized once
///        per resolution and kept, so each new edit script costs a solve, a warp and an extraction only.
///
/// Frames and the report as in deform.h. Not thread-safe: callers serialise deform() (the server runs one
/// request at a time and cancels the older one through its progress callback).
#pragma once

#include <voxwarp/deform.h>

#include <map>
#include <memory>

namespace voxwarp {

class DeformSession {
public:
    /// `options` as for deform_mesh; options.voxelize.resolution is the default resolution.
    /// @throw InvalidInput when the mesh is unusable (check_mesh).
    DeformSession(TriangleMesh mesh, DeformOptions options);

    /// deform_mesh(mesh(), script, options at `resolution`) with the voxelization of that resolution reused
    /// (made on first use; the two most recent resolutions are kept). resolution 0: the default.
    /// report.seconds_voxelize is 0 when the voxelization was reused. @throw as deform_mesh.
    TriangleMesh deform(const EditScript& script, int resolution, DeformReport& report, const ProgressCallback& progress = {});

    const TriangleMesh& mesh() const { return mesh_; }
    const DeformOptions& options() const { return options_; }
    /// Voxel size at `resolution` (0: the default), world units.
    double voxel_size(int resolution = 0) const;

private:
    TriangleMesh mesh_;
    DeformOptions options_;
    std::map<int, std::shared_ptr<const SparseVoxmap>> voxmaps_;
    std::vector<int> recent_;
};

} // namespace voxwarp
