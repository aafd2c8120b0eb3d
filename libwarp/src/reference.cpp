// The slow, obvious warp: 64-term basis sum per voxel, no tables, one thread, double accumulators.
// The yardstick for the fast one (tests compare them; BM_WarpNaive times it).
#include <voxwarp/basis.h>
#include <voxwarp/warp.h>

#include "resolve.h"

#include <cmath>

namespace voxwarp {

Voxmap warp_reference(const WarpDomain& domain, const Lattice& lattice) {
    const double h = domain.target_voxel_size;
    const auto regions = lattice.regions();
    // Each voxel is mapped with its own region's polynomial, and its image's edges are the map's derivatives
    // per voxel step (the Jacobian's columns over G), summed the same 64-term way.
    auto map = [&](const std::array<std::int64_t, 3>& idx, int derivative_axis) {
        std::array<int, 3> region;
        std::array<std::array<double, 4>, 3> b;
        for (std::size_t a = 0; a < 3; ++a) {
            const int g = domain.granularity[a];
            region[a] = int(std::min<std::int64_t>(idx[a] / g, regions[a] - 1));
            const double t = double(idx[a] - std::int64_t(region[a]) * g) / g;
            b[a] = cubic_basis(t);
            if (int(a) == derivative_axis) {
                b[a] = cubic_basis_derivative(t);
                for (double& v : b[a]) v /= g;
            }
        }
        Eigen::Vector3d p = Eigen::Vector3d::Zero();
        for (int k = 0; k < 4; ++k)
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i)
                    p += b[0][std::size_t(i)] * b[1][std::size_t(j)] * b[2][std::size_t(k)] * lattice.point(region[0] + i, region[1] + j, region[2] + k);
        return Eigen::Vector3d((derivative_axis < 0 ? p - domain.target_origin : p) / h);
    };
    // The voxel's image: the bounding box of the parallelepiped spanned by the Jacobian's columns, and the
    // share |det| / box volume of each overlap that keeps the deposited weight equal to the image's volume.
    auto splat_box = [&](std::int64_t e, std::int64_t f, std::int64_t g, Eigen::Vector3d& lo, Eigen::Vector3d& hi, double& mass) {
        const std::array<std::int64_t, 3> at{e, f, g};
        const Eigen::Vector3d c = map(at, -1);
        Eigen::Matrix3d edges;
        for (int axis = 0; axis < 3; ++axis) edges.col(axis) = map(at, axis);
        const Eigen::Vector3d half = 0.5 * edges.cwiseAbs().rowwise().sum();
        lo = c - half, hi = c + half;
        const double box = 8.0 * half.prod();
        mass = box > 0 ? std::min(1.0, std::abs(edges.col(0).dot(edges.col(1).cross(edges.col(2)))) / box) : 0.0;
    };
    auto density = [&](std::int64_t e, std::int64_t f, std::int64_t g) { return domain.density(e, f, g); };
    auto for_each_voxel = [&](auto&& visit) {
        for (std::int64_t g = 0; g < domain.dims[2]; ++g)
            for (std::int64_t f = 0; f < domain.dims[1]; ++f)
                for (std::int64_t e = 0; e < domain.dims[0]; ++e) {
                    Eigen::Vector3d lo, hi;
                    double mass;
                    splat_box(e, f, g, lo, hi, mass);
                    visit(lo, hi, mass, double(domain.density(e, f, g)), std::array<std::int64_t, 3>{e, f, g});
                }
    };
    // Pass 1: the target's bounds, and the cells thin parts carry (resolve.h).
    Eigen::Vector3d all_lo = Eigen::Vector3d::Constant(1e300), all_hi = -all_lo;
    std::vector<warp_internal::CarryImage> images;
    std::vector<warp_internal::Carry> cells;
    for_each_voxel([&](const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double, double, const std::array<std::int64_t, 3>& at) {
        all_lo = all_lo.cwiseMin(lo), all_hi = all_hi.cwiseMax(hi);
        // Voxels of the voxmap only: the zero padding around it is never carried (carry.h).
        const auto& n = domain.voxmap.dims();
        for (std::size_t a = 0; a < 3; ++a)
            if (at[a] - domain.offset[a] < 0 || at[a] - domain.offset[a] >= n[a]) return;
        if (!warp_internal::is_carried(density, at[0], at[1], at[2])) return;
        const bool inside = density(at[0], at[1], at[2]) >= 0.5f;
        const Eigen::Vector3d centre = map(at, -1);
        images.push_back({std::uint64_t(at[0] + domain.dims[0] * (at[1] + domain.dims[1] * at[2])), warp_internal::nearest_cell(centre.data()), inside});
        Eigen::Matrix3d J;
        for (int axis = 0; axis < 3; ++axis) J.col(axis) = map(at, axis);
        warp_internal::image_cells(centre, J, [&](const std::array<std::int64_t, 3>& x) { cells.push_back({x, inside}); });
    });
    const auto carried = warp_internal::link_carries(images, std::move(cells), domain.dims);
    std::array<std::int64_t, 3> first, dims;
    for (std::size_t a = 0; a < 3; ++a) {
        first[a] = std::int64_t(std::floor(all_lo[int(a)] + 0.5));
        dims[a] = std::int64_t(std::floor(all_hi[int(a)] + 0.5)) - first[a] + 1;
    }
    Voxmap out(dims, domain.target_origin + h * Eigen::Vector3d(double(first[0]), double(first[1]), double(first[2])), h);
    std::vector<double> weight(out.density.size(), 0.0), value(out.density.size(), 0.0);
    // Pass 2: splat.
    for_each_voxel([&](const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double mass, double density, const std::array<std::int64_t, 3>&) {
        for (std::int64_t z = std::int64_t(std::floor(lo.z() + 0.5)); z <= std::int64_t(std::floor(hi.z() + 0.5)); ++z)
            for (std::int64_t y = std::int64_t(std::floor(lo.y() + 0.5)); y <= std::int64_t(std::floor(hi.y() + 0.5)); ++y)
                for (std::int64_t x = std::int64_t(std::floor(lo.x() + 0.5)); x <= std::int64_t(std::floor(hi.x() + 0.5)); ++x) {
                    const double w = std::max(0.0, std::min(hi.x(), x + 0.5) - std::max(lo.x(), x - 0.5)) *
                                     std::max(0.0, std::min(hi.y(), y + 0.5) - std::max(lo.y(), y - 0.5)) *
                                     std::max(0.0, std::min(hi.z(), z + 0.5) - std::max(lo.z(), z - 0.5)) * mass;
                    const std::size_t t = std::size_t(out.index(x - first[0], y - first[1], z - first[2]));
                    weight[t] += w;
                    value[t] += w * density;
                }
    });
    for (std::int64_t k = 0; k < dims[2]; ++k)
        for (std::int64_t j = 0; j < dims[1]; ++j) {
            bool inside = false;
            for (std::int64_t i = 0; i < dims[0]; ++i) {
                const std::size_t t = std::size_t(out.index(i, j, k));
                out.density[t] = warp_internal::resolve_density(weight[t], value[t], inside);
            }
        }
    std::vector<std::uint8_t> sides(out.density.size(), 0); // bit 0: carried inside, bit 1: outside
    for (const auto& c : carried) {
        const std::int64_t i = c.cell[0] - first[0], j = c.cell[1] - first[1], k = c.cell[2] - first[2];
        if (i < 0 || j < 0 || k < 0 || i >= dims[0] || j >= dims[1] || k >= dims[2]) continue;
        sides[std::size_t(out.index(i, j, k))] |= c.inside ? 1 : 2;
    }
    for (std::size_t t = 0; t < sides.size(); ++t) out.density[t] = warp_internal::carried_density(out.density[t], sides[t] & 1, sides[t] & 2);
    auto at = [&](std::int64_t x, std::int64_t y, std::int64_t z) -> float* {
        const std::int64_t i = x - first[0], j = y - first[1], k = z - first[2];
        if (i < 0 || j < 0 || k < 0 || i >= dims[0] || j >= dims[1] || k >= dims[2]) return nullptr;
        return &out.density[std::size_t(out.index(i, j, k))];
    };
    for (const auto& c : warp_internal::bridges(carried, [&](std::int64_t x, std::int64_t y, std::int64_t z) {
             const float* d = at(x, y, z);
             return d && *d >= 0.5f;
         },
         [&](const std::array<std::int64_t, 3>& cell) { return warp_internal::source_inside(domain, lattice, cell); }))
        if (float* d = at(c[0], c[1], c[2])) *d = warp_internal::kCarriedOutside;
    return out;
}

} // namespace voxwarp
