#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp/session.h>

#include <algorithm>
#include <chrono>

namespace voxwarp {

namespace deform_internal {
SparseVoxmap voxelize_for_deform(const TriangleMesh& mesh, const VoxelizeOptions& options, const ProgressCallback& progress, VoxelizeReport* report,
                                 std::uint64_t estimate);
TriangleMesh deform_voxelized(const TriangleMesh& mesh, SparseVoxmap voxmap, const EditScript& script, const DeformOptions& options, DeformReport& report,
                              const SourceSurface* surface = nullptr);
} // namespace deform_internal

DeformSession::DeformSession(TriangleMesh mesh, DeformOptions options) : mesh_(std::move(mesh)), options_(std::move(options)) { check_mesh(mesh_, "mesh"); }

double DeformSession::voxel_size(int resolution) const {
    VoxelizeOptions vo = options_.voxelize;
    if (resolution > 0) vo.resolution = resolution, vo.voxel_size = 0;
    return voxelize_frame(mesh_, vo).voxel_size;
}

TriangleMesh DeformSession::deform(const EditScript& script, int resolution, DeformReport& report, const ProgressCallback& progress, bool full) {
    DeformOptions o = options_;
    o.snap = o.snap && full;
    o.attributes = o.attributes && full;
    if (resolution > 0) o.voxelize.resolution = resolution, o.voxelize.voxel_size = 0;
    const int key = resolution > 0 ? resolution : 0;
    o.progress = progress;
    report.resident_bytes_at_start = resident_bytes();
    report.memory_estimate_bytes = 0; // worked out (an O(faces) pass) only when the voxmap is not kept
    auto it = voxmaps_.find(key);
    if (it == voxmaps_.end()) {
        report.memory_estimate_bytes = deform_memory_estimate(mesh_, o);
        const auto t = std::chrono::steady_clock::now();
        auto voxmap = std::make_shared<const SparseVoxmap>(deform_internal::voxelize_for_deform(mesh_, o.voxelize, progress, nullptr, report.memory_estimate_bytes));
        report.seconds_voxelize = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
        it = voxmaps_.emplace(key, std::move(voxmap)).first;
    }
    recent_.erase(std::remove(recent_.begin(), recent_.end(), key), recent_.end());
    recent_.push_back(key);
    while (recent_.size() > 2) voxmaps_.erase(recent_.front()), recent_.erase(recent_.begin());
    if ((o.snap || (o.attributes && mesh_.has_attributes())) && !surface_) surface_ = std::make_unique<SourceSurface>(mesh_);
    return deform_internal::deform_voxelized(mesh_, *it->second, script, o, report, surface_.get());
}

} // namespace voxwarp
