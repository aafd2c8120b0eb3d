#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp_internal/vdb_convert.h>

#include <openvdb/tools/Dense.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <bit>
#include <cmath>

namespace voxwarp::vdb_internal {

openvdb::math::Transform::Ptr voxmap_transform(const Voxmap& voxmap) {
    auto xform = openvdb::math::Transform::createLinearTransform(voxmap.voxel_size);
    xform->postTranslate(openvdb::Vec3d(voxmap.origin.x(), voxmap.origin.y(), voxmap.origin.z()));
    return xform;
}

openvdb::FloatGrid::Ptr to_density_grid(const Voxmap& voxmap) {
    // Classify the voxmap's 8^3 blocks (aligned with OpenVDB's leaves) in parallel: all background, uniform
    // (a tile), or mixed (a leaf, built in parallel). Only the tree insertions are serial. copyFromDense did
    // the same job visiting every voxel through the tree, and was a seventh of a 512^3 round trip.
    using LeafT = openvdb::FloatTree::LeafNodeType;
    constexpr std::int64_t B = LeafT::DIM;
    const std::int64_t nx = voxmap.dims[0], ny = voxmap.dims[1], nz = voxmap.dims[2];
    const std::int64_t bx = (nx + B - 1) / B, by = (ny + B - 1) / B, bz = (nz + B - 1) / B;
    const std::size_t blocks = std::size_t(bx * by * bz);
    std::vector<LeafT*> leaves(blocks, nullptr);
    std::vector<float> tile(blocks, 0.0f);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks), [&](const auto& range) {
        for (std::size_t b = range.begin(); b != range.end(); ++b) {
            const std::int64_t i0 = std::int64_t(b % std::size_t(bx)) * B, j0 = std::int64_t((b / std::size_t(bx)) % std::size_t(by)) * B,
                               k0 = std::int64_t(b / std::size_t(bx * by)) * B;
            auto value = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
                return i < nx && j < ny && k < nz ? voxmap.at(i, j, k) : 0.0f; // past the voxmap: background
            };
            const float first = value(i0, j0, k0);
            bool uniform = true;
            if (i0 + B <= nx && j0 + B <= ny && k0 + B <= nz) { // inside the voxmap: whole rows, bit patterns
                const std::uint32_t pattern = std::bit_cast<std::uint32_t>(first);
                for (std::int64_t k = k0; k < k0 + B && uniform; ++k)
                    for (std::int64_t j = j0; j < j0 + B && uniform; ++j) {
                        const float* row = &voxmap.density[std::size_t(voxmap.index(i0, j, k))];
                        std::uint32_t differs = 0;
                        for (std::int64_t i = 0; i < B; ++i) differs |= std::bit_cast<std::uint32_t>(row[i]) ^ pattern;
                        uniform = differs == 0;
                    }
            } else {
                for (std::int64_t k = k0; k < k0 + B && uniform; ++k)
                    for (std::int64_t j = j0; j < j0 + B && uniform; ++j)
                        for (std::int64_t i = i0; i < i0 + B; ++i)
                            if (value(i, j, k) != first) {
                                uniform = false;
                                break;
                            }
            }
            if (uniform) {
                tile[b] = first;
                continue;
            }
            auto* leaf = new LeafT(openvdb::Coord(int(i0), int(j0), int(k0)), 0.0f, false);
            for (std::int64_t k = 0; k < B; ++k)
                for (std::int64_t j = 0; j < B; ++j)
                    for (std::int64_t i = 0; i < B; ++i) {
                        const float v = value(i0 + i, j0 + j, k0 + k);
                        if (v != 0.0f) leaf->setValueOn(LeafT::coordToOffset(openvdb::Coord(int(i0 + i), int(j0 + j), int(k0 + k))), v);
                    }
            leaves[b] = leaf;
        }
    });
    auto grid = openvdb::FloatGrid::create(0.0f);
    auto& tree = grid->tree();
    for (std::size_t b = 0; b < blocks; ++b) {
        if (leaves[b]) {
            tree.addLeaf(leaves[b]);
        } else if (tile[b] != 0.0f) {
            const openvdb::Coord origin(int(std::int64_t(b % std::size_t(bx)) * B), int(std::int64_t((b / std::size_t(bx)) % std::size_t(by)) * B),
                                        int(std::int64_t(b / std::size_t(bx * by)) * B));
            tree.addTile(1, origin, tile[b], true); // level 1: a tile the size of one leaf
        }
    }
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
