// Domain set-up: granularity and padding from the voxmap (uniform placement), capture (clamped placement,
// True & Hughes section 5: the data pulled back through the undeformed map).
#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp/warp.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>

namespace voxwarp {

namespace {

void check_spec(const LatticeSpec& spec) {
    if (!(spec.padding >= 0 && spec.padding <= 4)) throw InvalidInput("lattice padding " + std::to_string(spec.padding) + " is outside [0, 4]");
    const int minimum = spec.placement == Placement::clamped ? 6 : 4;
    for (int a = 0; a < 3; ++a)
        if (spec.size[std::size_t(a)] < minimum || spec.size[std::size_t(a)] > 1024)
            throw InvalidInput("lattice size " + std::to_string(spec.size[std::size_t(a)]) + " along axis " + std::to_string(a) + " is outside [" +
                               std::to_string(minimum) + ", 1024] for the " + to_string(spec.placement) + " placement");
}

} // namespace

WarpDomain make_domain(Voxmap input, const LatticeSpec& spec, std::uint64_t max_memory_bytes) {
    check_spec(spec);
    if (input.voxel_count() <= 0 || input.density.size() != std::size_t(input.voxel_count())) throw InvalidInput("warp: the voxmap is empty");
    const double h = input.voxel_size;
    WarpDomain d;
    d.target_origin = input.origin;
    d.target_voxel_size = h;
    std::array<std::int64_t, 3> dims{};
    if (spec.placement == Placement::uniform) {
        std::array<std::int64_t, 3> offset{};
        for (std::size_t a = 0; a < 3; ++a) {
            const std::int64_t regions = spec.size[a] - 3;
            const std::int64_t pad = std::int64_t(std::ceil(spec.padding * double(input.dims[a])));
            const std::int64_t wanted = input.dims[a] + 2 * pad;
            d.granularity[a] = int((wanted + regions - 1) / regions);
            dims[a] = std::int64_t(d.granularity[a]) * regions;
            offset[a] = (dims[a] - input.dims[a]) / 2;
        }
        const Eigen::Vector3d origin = input.origin - h * Eigen::Vector3d(double(offset[0]), double(offset[1]), double(offset[2]));
        d.voxmap = std::move(input); // last use of input
        d.offset = offset;
        d.dims = dims;
        d.lattice = Lattice::uniform(spec.size, origin,
                                     h * Eigen::Vector3d(d.granularity[0], d.granularity[1], d.granularity[2]));
        return d;
    }

    // Clamped: the lattice's image is exactly the data box; the domain samples it at about twice the input's
    // resolution (the paper's DSIZE = 2 ISIZE), so the capture's resampling loses little.
    for (std::size_t a = 0; a < 3; ++a) {
        const std::int64_t regions = spec.size[a] - 3;
        d.granularity[a] = int(std::max<std::int64_t>(1, (2 * input.dims[a] + regions - 1) / regions));
        dims[a] = std::int64_t(d.granularity[a]) * regions;
    }
    require_memory(voxmap_bytes(dims) + voxmap_bytes(input.dims), max_memory_bytes,
                   "captured warp domain of " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]) + " voxels");
    const Eigen::Vector3d lo = input.origin, hi = input.world(double(input.dims[0] - 1), double(input.dims[1] - 1), double(input.dims[2] - 1));
    d.lattice = Lattice::clamped(spec.size, lo, hi);
    const Eigen::Vector3d spacing = (hi - lo).cwiseQuotient(Eigen::Vector3d(double(dims[0]), double(dims[1]), double(dims[2])));
    d.voxmap = Voxmap(dims, lo, spacing.maxCoeff());
    d.dims = dims;
    // Capture: domain[e] = source(B(e / G)), trilinear in the source.
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, dims[2]), [&](const auto& r) {
        for (std::int64_t k = r.begin(); k != r.end(); ++k)
            for (std::int64_t j = 0; j < dims[1]; ++j)
                for (std::int64_t i = 0; i < dims[0]; ++i) {
                    const Eigen::Vector3d stu(double(i) / d.granularity[0], double(j) / d.granularity[1], double(k) / d.granularity[2]);
                    d.voxmap.at(i, j, k) = input.sample(input.index_of(d.lattice.evaluate(stu)));
                }
    });
    return d;
}

} // namespace voxwarp
