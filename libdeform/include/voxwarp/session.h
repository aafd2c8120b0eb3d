/// @file session.h
/// @brief A deform in progress, for interactive front ends (the editor's server): the input mesh voxelized once
///        per resolution and kept (and indexed once for snapping), so each new edit script costs a solve, a warp, an
///        extraction and a snap only.
///
/// Frames and the report as in deform.h. Not thread-safe: callers serialise deform() (the server runs one
/// request at a time and cancels the older one through its progress callback).
#pragma once

#include <voxwarp/deform.h>
#include <voxwarp/snap.h>

#include <map>
#include <memory>

namespace voxwarp {

class DeformSession {
public:
    /// `options` as for deform_mesh; options.voxelize.resolution is the default resolution.
    /// @throw InvalidInput when the mesh is unusable (check_mesh).
    DeformSession(TriangleMesh mesh, DeformOptions options);
    // The index of the input for snapping refers to the session's own mesh: a session stays where it was made.
    DeformSession(const DeformSession&) = delete;
    DeformSession& operator=(const DeformSession&) = delete;

    /// deform_mesh(mesh(), script, options at `resolution`) with the voxelization of that resolution reused
    /// (made on first use; the two most recent resolutions are kept). resolution 0: the default.
    /// report.seconds_voxelize is 0 when the voxelization was reused. `full` false gives a quick preview: no
    /// snapping and no attributes carried, even where options() ask for them. @throw as deform_mesh.
    TriangleMesh deform(const EditScript& script, int resolution, DeformReport& report, const ProgressCallback& progress = {}, bool full = true);

    const TriangleMesh& mesh() const { return mesh_; }
    const DeformOptions& options() const { return options_; }
    /// Voxel size at `resolution` (0: the default), world units.
    double voxel_size(int resolution = 0) const;

private:
    TriangleMesh mesh_;
    DeformOptions options_;
    std::map<int, std::shared_ptr<const SparseVoxmap>> voxmaps_;
    std::vector<int> recent_;
    std::unique_ptr<SourceSurface> surface_; ///< mesh_ indexed for snapping, made on first use
};

} // namespace voxwarp
