#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp_internal/vdb_convert.h>

#include <openvdb/tools/Dense.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>

namespace voxwarp::vdb_internal {

openvdb::math::Transform::Ptr voxmap_transform(const Voxmap& voxmap) {
    auto xform = openvdb::math::Transform::createLinearTransform(voxmap.voxel_size);
    xform->postTranslate(openvdb::Vec3d(voxmap.origin.x(), voxmap.origin.y(), voxmap.origin.z()));
    return xform;
}

openvdb::FloatGrid::Ptr to_density_grid(const Voxmap& voxmap) {
    using DenseT = openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ>;
    const openvdb::CoordBBox box(openvdb::Coord(0, 0, 0),
                                 openvdb::Coord(int(voxmap.dims[0] - 1), int(voxmap.dims[1] - 1), int(voxmap.dims[2] - 1)));
    // Dense only reads through this pointer here; its API wants a mutable one.
    DenseT dense(box, const_cast<float*>(voxmap.density.data()));
    auto grid = openvdb::FloatGrid::create(0.0f);
    openvdb::tools::copyFromDense(dense, *grid, 0.0f);
    grid->setTransform(voxmap_transform(voxmap));
    return grid;
}

Voxmap from_float_grid(const openvdb::FloatGrid& grid, const std::string& source) {
    const auto& xform = grid.transform();
    if (!xform.isLinear() || !xform.hasUniformScale())
        throw InvalidInput(source + ": grid '" + grid.getName() + "' has a non-uniform or non-linear transform; voxmaps need cubic voxels");
    // Rotation would leave index axes off the world axes: compare the mapped unit axes with a pure scale.
    const double h = xform.voxelSize()[0];
    const auto o = xform.indexToWorld(openvdb::Vec3d(0, 0, 0));
    for (int a = 0; a < 3; ++a) {
        openvdb::Vec3d e(0, 0, 0);
        e[a] = 1;
        const auto d = xform.indexToWorld(e) - o;
        for (int b = 0; b < 3; ++b)
            if (std::abs(d[b] - (a == b ? h : 0.0)) > 1e-9 * h)
                throw InvalidInput(source + ": grid '" + grid.getName() + "' is rotated or sheared; voxmaps need axis-aligned voxels");
    }
    if (!(h > 0) || !std::isfinite(h)) throw InvalidInput(source + ": grid '" + grid.getName() + "' has voxel size " + std::to_string(h));

    openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
    if (box.empty()) throw InvalidInput(source + ": grid '" + grid.getName() + "' has no active voxels");
    const bool level_set = grid.getGridClass() == openvdb::GRID_LEVEL_SET;
    if (level_set) box.expand(1); // the ramp can reach one voxel past the band's last active voxel
    if (auto meta = grid.getMetadata<openvdb::Vec3IMetadata>("voxwarp_dims")) {
        const auto d = meta->value();
        if (d[0] > 0 && d[1] > 0 && d[2] > 0) box.expand(openvdb::CoordBBox(openvdb::Coord(0, 0, 0), openvdb::Coord(d[0] - 1, d[1] - 1, d[2] - 1)));
    }
    const std::array<std::int64_t, 3> dims{box.dim()[0], box.dim()[1], box.dim()[2]};
    require_memory(voxmap_bytes(dims), 0, source + ": a dense voxmap of " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]));

    const auto origin = xform.indexToWorld(box.min());
    Voxmap voxmap(dims, Eigen::Vector3d(origin[0], origin[1], origin[2]), h);
    using DenseT = openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ>;
    DenseT dense(box, voxmap.density.data());
    openvdb::tools::copyToDense(grid, dense);

    std::atomic<bool> non_finite{false};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, voxmap.density.size(), 1 << 16), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            float v = voxmap.density[i];
            if (!std::isfinite(v)) {
                non_finite = true;
                v = 0;
            }
            if (level_set) v = 0.5f - 0.5f * v / float(h);
            voxmap.density[i] = v < 0 ? 0.0f : (v > 1 ? 1.0f : v);
        }
    });
    if (non_finite) throw InvalidInput(source + ": grid '" + grid.getName() + "' holds non-finite values (NaN or infinity)");
    return voxmap;
}

} // namespace voxwarp::vdb_internal

#include <voxwarp/progress.h>

namespace voxwarp::vdb_internal {

bool ProgressInterrupter::wasInterrupted(int percent) {
    if (!progress) return false;
    return percent >= 0 ? !progress->poll(percent / 100.0) : progress->cancelled();
}

} // namespace voxwarp::vdb_internal
