// Domain set-up: granularity and padding from the voxmap (uniform placement), capture (clamped placement,
// True & Hughes section 5: the data pulled back through the undeformed map).
#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp/warp.h>

#include "resolve.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace voxwarp {

namespace {

/// Uniform placement: the most one region's side may exceed another's (see make_domain).
constexpr int kRegionAspect = 2;

void check_spec(const LatticeSpec& spec) {
    if (!(spec.padding >= 0 && spec.padding <= 4)) throw InvalidInput("lattice padding " + std::to_string(spec.padding) + " is outside [0, 4]");
    const int minimum = spec.placement == Placement::clamped ? 6 : 4;
    for (int a = 0; a < 3; ++a)
        if (spec.size[std::size_t(a)] < minimum || spec.size[std::size_t(a)] > 1024)
            throw InvalidInput("lattice size " + std::to_string(spec.size[std::size_t(a)]) + " along axis " + std::to_string(a) + " is outside [" +
                               std::to_string(minimum) + ", 1024] for the " + to_string(spec.placement) + " placement");
}

} // namespace

WarpDomain make_domain(const Voxmap& input, const LatticeSpec& spec, std::uint64_t max_memory_bytes) {
    check_spec(spec);
    if (input.voxel_count() <= 0 || input.density.size() != std::size_t(input.voxel_count())) throw InvalidInput("warp: the voxmap is empty");
    return make_domain(to_sparse(input), spec, max_memory_bytes);
}

WarpDomain make_domain(SparseVoxmap input, const LatticeSpec& spec, std::uint64_t max_memory_bytes) {
    check_spec(spec);
    if (input.empty()) throw InvalidInput("warp: the voxmap is empty");
    const double h = input.voxel_size();
    WarpDomain d;
    d.target_origin = input.origin();
    d.target_voxel_size = h;
    std::array<std::int64_t, 3> dims{};
    if (spec.placement == Placement::uniform) {
        std::array<std::int64_t, 3> offset{};
        for (std::size_t a = 0; a < 3; ++a) {
            const std::int64_t regions = spec.size[a] - 3;
            const std::int64_t pad = std::int64_t(std::ceil(spec.padding * double(input.dims()[a])));
            const std::int64_t wanted = input.dims()[a] + 2 * pad;
            d.granularity[a] = int((wanted + regions - 1) / regions);
        }
        // A flat model (a ring, a plate, a leaf) fits a lattice whose regions along its thin axis are a fraction of
        // the others': a move then shears it through its thickness, its top carried a region's length while its
        // bottom stays (a thin ring pulled out by a quarter of its size came out a ribbon under a voxel thick, its
        // surface full of holes: 9 extra handles). So no region is more than kRegionAspect times longer along one
        // axis than along another; the lattice reaches further beyond the thin axis instead (the padding is empty
        // and never stored).
        const int longest = *std::max_element(d.granularity.begin(), d.granularity.end());
        for (std::size_t a = 0; a < 3; ++a) {
            d.granularity[a] = std::max(d.granularity[a], (longest + kRegionAspect - 1) / kRegionAspect);
            dims[a] = std::int64_t(d.granularity[a]) * (spec.size[a] - 3);
            offset[a] = (dims[a] - input.dims()[a]) / 2;
        }
        const Eigen::Vector3d origin = input.origin() - h * Eigen::Vector3d(double(offset[0]), double(offset[1]), double(offset[2]));
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
        d.granularity[a] = int(std::max<std::int64_t>(1, (2 * input.dims()[a] + regions - 1) / regions));
        dims[a] = std::int64_t(d.granularity[a]) * regions;
    }
    // The capture is block-sparse like its input, but where its blocks are stored depends on the map: budget
    // for the dense worst case.
    require_memory(voxmap_bytes(dims) + input.bytes(), max_memory_bytes,
                   "captured warp domain of " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]) + " voxels");
    const auto& n = input.dims();
    const Eigen::Vector3d lo = input.origin(), hi = input.world(double(n[0] - 1), double(n[1] - 1), double(n[2] - 1));
    d.lattice = Lattice::clamped(spec.size, lo, hi);
    const Eigen::Vector3d spacing = (hi - lo).cwiseQuotient(Eigen::Vector3d(double(dims[0]), double(dims[1]), double(dims[2])));
    d.voxmap = SparseVoxmap(dims, lo, spacing.maxCoeff());
    d.dims = dims;
    // Capture: domain[e] = source(B(e / G)), trilinear in the source, block by block.
    constexpr std::int64_t S = SparseVoxmap::kSide;
    const auto& bd = d.voxmap.block_dims();
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, d.voxmap.block_count()), [&](const auto& r) {
        float values[SparseVoxmap::kBlockVoxels];
        for (std::int64_t b = r.begin(); b != r.end(); ++b) {
            const std::int64_t i0 = S * (b % bd[0]), j0 = S * ((b / bd[0]) % bd[1]), k0 = S * (b / (bd[0] * bd[1]));
            for (std::int64_t z = 0; z < S; ++z)
                for (std::int64_t y = 0; y < S; ++y)
                    for (std::int64_t x = 0; x < S; ++x) {
                        if (i0 + x >= dims[0] || j0 + y >= dims[1] || k0 + z >= dims[2]) { // past the domain: stored as 0
                            values[x + S * (y + S * z)] = 0.0f;
                            continue;
                        }
                        const Eigen::Vector3d stu(double(i0 + x) / d.granularity[0], double(j0 + y) / d.granularity[1], double(k0 + z) / d.granularity[2]);
                        values[x + S * (y + S * z)] = input.sample(input.index_of(d.lattice.evaluate(stu)));
                    }
            d.voxmap.set_block(b, values);
        }
    });
    return d;
}

} // namespace voxwarp

namespace voxwarp {

void push_points(const Lattice& rest, const Lattice& moved, std::vector<Eigen::Vector3d>& points) {
    if (rest.size() != moved.size()) throw InvalidInput("push_points: the lattices differ in size");
    // An undeformed uniform rest lattice (every warp's) is affine: its inverse once, not parameter_of's test of
    // every control point for each point.
    const bool affine = rest.placement() == Placement::uniform && rest.points() == rest.rest_points();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 1024), [&](const auto& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
            try {
                const Eigen::Vector3d stu = affine ? Eigen::Vector3d((points[i] - rest.rest_origin()).cwiseQuotient(rest.spacing())) : rest.parameter_of(points[i]);
                points[i] = moved.evaluate(stu);
            } catch (const SolverFailure&) {
                // beyond the map's reach: the point stays (the mesher will find no crossing near it)
            }
        }
    });
}

void push_feature_surface(const Lattice& rest, const Lattice& moved, FeatureSurface& surface) {
    push_points(rest, moved, surface.faces.vertices);
    std::vector<Eigen::Vector3d> ends;
    ends.reserve(2 * surface.edges.size());
    for (const auto& [a, b] : surface.edges) ends.push_back(a), ends.push_back(b);
    push_points(rest, moved, ends);
    for (std::size_t i = 0; i < surface.edges.size(); ++i) surface.edges[i] = {ends[2 * i], ends[2 * i + 1]};
}

} // namespace voxwarp

namespace voxwarp::warp_internal {

bool source_inside(const WarpDomain& domain, const Lattice& lattice, const std::array<std::int64_t, 3>& cell) {
    const Eigen::Vector3d world = domain.target_origin + domain.target_voxel_size * Eigen::Vector3d(double(cell[0]), double(cell[1]), double(cell[2]));
    Eigen::Vector3d stu;
    try {
        stu = lattice.parameter_of(world);
    } catch (const SolverFailure&) {
        return true;
    }
    std::array<std::int64_t, 3> at;
    for (std::size_t a = 0; a < 3; ++a) at[a] = std::int64_t(std::floor(stu[int(a)] * domain.granularity[a] + 0.5));
    return domain.density(at[0], at[1], at[2]) >= 0.5f;
}

} // namespace voxwarp::warp_internal
