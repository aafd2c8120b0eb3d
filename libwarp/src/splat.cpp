// The forward splat of True & Hughes section 6, evaluated region by region with the section 4 tables, and the
// section 7 incremental update. See warp.h for the conventions.
#include <voxwarp/basis.h>
#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp/warp.h>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>

namespace voxwarp {

namespace warp_internal {

/// Fixed-point unit of weight: 2^22. Splats deposit their image's volume, so a target voxel's weights sum to
/// about 1 where the map is injective; 32-bit sums hold up to 511 before overflowing, which only a map
/// compressing space eightfold along every axis could reach. Half the memory of 64-bit sums, and the memory
/// (zeroing and first-touch page faults) was what a warp's time went to.
constexpr double kFixedOne = 4194304.0;

/// Round a non-negative weight to fixed point. A truncating conversion of x + 0.5 rounds like llround for
/// x >= 0 and compiles to one instruction instead of a libm call (which dominated the splat).
inline std::int32_t to_fixed(double x) { return std::int32_t(x * kFixedOne + 0.5); }

using Index3 = std::array<std::int64_t, 3>;

/// Target-index-space bounds of what a region's splats touch (inclusive); empty when lo > hi.
struct Box {
    Index3 lo{std::numeric_limits<std::int64_t>::max(), std::numeric_limits<std::int64_t>::max(), std::numeric_limits<std::int64_t>::max()};
    Index3 hi{std::numeric_limits<std::int64_t>::min(), std::numeric_limits<std::int64_t>::min(), std::numeric_limits<std::int64_t>::min()};
    bool empty() const { return lo[0] > hi[0]; }
    void include(const Index3& a, const Index3& b) {
        for (int i = 0; i < 3; ++i) lo[std::size_t(i)] = std::min(lo[std::size_t(i)], a[std::size_t(i)]), hi[std::size_t(i)] = std::max(hi[std::size_t(i)], b[std::size_t(i)]);
    }
    void include(const Box& o) {
        if (!o.empty()) include(o.lo, o.hi);
    }
    bool overlaps(const Box& o) const {
        if (empty() || o.empty()) return false;
        for (std::size_t i = 0; i < 3; ++i)
            if (hi[i] < o.lo[i] || o.hi[i] < lo[i]) return false;
        return true;
    }
    bool contains(const Box& o) const {
        if (o.empty()) return true;
        for (std::size_t i = 0; i < 3; ++i)
            if (o.lo[i] < lo[i] || o.hi[i] > hi[i]) return false;
        return true;
    }
};

/// floor() for |x| < 2^62 without a libm call (the baseline x86-64 build has no roundsd, and the splat takes
/// six floors a voxel).
inline std::int64_t floor_index(double x) {
    const auto i = std::int64_t(x);
    return i - std::int64_t(double(i) > x);
}

/// Fixed-point sums of one target voxel, side by side so a splat touches one cache line per voxel.
struct Cell {
    std::int32_t weight, value;
};

struct ReleaseCells {
    std::size_t bytes = 0;
    void operator()(Cell* p) const noexcept { release_large(p, bytes); }
};

/// Fixed-point accumulators over a box of the (infinite) target grid.
struct Accumulator {
    Box box;
    Index3 dims{0, 0, 0};
    std::unique_ptr<Cell[], ReleaseCells> cells;
    std::size_t size = 0;
    void allocate(const Box& b) {
        box = b;
        for (std::size_t i = 0; i < 3; ++i) dims[i] = b.hi[i] - b.lo[i] + 1;
        size = std::size_t(dims[0] * dims[1] * dims[2]);
        cells = std::unique_ptr<Cell[], ReleaseCells>(static_cast<Cell*>(allocate_large(size * sizeof(Cell))), ReleaseCells{size * sizeof(Cell)});
        // Uninitialised until here: zeroed in parallel, so both cores take the (huge-page) faults.
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, size, 1 << 18), [&](const auto& r) {
            std::fill(cells.get() + r.begin(), cells.get() + r.end(), Cell{0, 0});
        });
    }
    std::int64_t index(std::int64_t i, std::int64_t j, std::int64_t k) const {
        return (i - box.lo[0]) + dims[0] * ((j - box.lo[1]) + dims[1] * (k - box.lo[2]));
    }
};

/// The splat of one domain voxel. The paper takes the bounding box of the six mapped face centres; under a
/// rotation that box is smaller than the voxel's image (0.71 wide at 45 degrees), so splats stop covering
/// the target and density is lost (a quarter of it at 30 degrees). Instead: the exact bounding box of the
/// voxel's linearised image, the parallelepiped centre + [-1/2, 1/2] x (ex, ey, ez) spanned by the central
/// differences (the Jacobian's columns), with every overlap scaled by |det| / box volume, so each voxel
/// deposits exactly its image's volume. For translations and axis scalings this is the paper's box, weight 1.
struct VoxelImage {
    Eigen::Vector3d lo, hi;
    double mass = 0; // |det(ex, ey, ez)| / box volume, in [0, 1]
};

inline VoxelImage voxel_image(const Eigen::Vector3d& centre, const Eigen::Vector3d& ex, const Eigen::Vector3d& ey, const Eigen::Vector3d& ez) {
    const Eigen::Vector3d half = 0.5 * (ex.cwiseAbs() + ey.cwiseAbs() + ez.cwiseAbs());
    const double box = 8.0 * half.prod();
    const double det = std::abs(ex.dot(ey.cross(ez)));
    return {centre - half, centre + half, box > 0 ? std::min(1.0, det / box) : 0.0};
}

/// Per-thread scratch for mapping one region: the z-contracted control points of the region, and a ring of
/// three mapped z-slices (a splat needs its voxel's neighbours one slice up and down). Streaming slices keeps
/// the working set at 3 (G+2)^2 points, in cache even for G ~ 130, where a whole region's map (G+2)^3 would not be.
struct RegionScratch {
    std::vector<Eigen::Vector3d> partial_z;  // (G+2) x 16: control points contracted with the z basis
    std::vector<Eigen::Vector3d> partial_yz; // (G+2) x 4 for one slice
    std::array<std::vector<Eigen::Vector3d>, 3> slice; // mapped centres of slices, (G+2)^2 each, x fastest
};

class Splatter {
public:
    Splatter(const WarpDomain& domain, const Eigen::Vector3d& target_origin, double h)
        : domain_(domain), target_origin_(target_origin), h_(h) {
        for (std::size_t a = 0; a < 3; ++a) {
            const int g = domain.granularity[a];
            // Halo entries l = -1 and l = G extrapolate / close the region's own polynomial, so a region's splat
            // depends on its 64 control points only: moving one point touches exactly the regions it supports.
            table_[a].resize(std::size_t(g) + 2);
            for (int l = -1; l <= g; ++l) table_[a][std::size_t(l + 1)] = cubic_basis(double(l) / g);
            regions_[a] = domain.lattice.regions()[a];
        }
        find_active_regions();
    }

    std::array<int, 3> regions() const { return regions_; }
    std::size_t region_count() const { return std::size_t(regions_[0]) * std::size_t(regions_[1]) * std::size_t(regions_[2]); }
    std::size_t region_index(int a, int b, int c) const { return std::size_t(a) + std::size_t(regions_[0]) * (std::size_t(b) + std::size_t(regions_[1]) * std::size_t(c)); }
    bool active(std::size_t r) const { return active_[r] != 0; }

    /// Map the region through `lattice` slice by slice and visit each of its voxels with its splat box
    /// [lo, hi] (target index units), mass share and density.
    template <class F>
    void for_each_box(const Lattice& lattice, int a, int b, int c, RegionScratch& s, F&& visit) const {
        const int gx = domain_.granularity[0], gy = domain_.granularity[1], gz = domain_.granularity[2];
        const std::size_t nx = std::size_t(gx) + 2, ny = std::size_t(gy) + 2, nz = std::size_t(gz) + 2;
        Eigen::Vector3d P[4][4][4];
        for (int k = 0; k < 4; ++k)
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i) P[i][j][k] = (lattice.point(a + i, b + j, c + k) - target_origin_) / h_;
        s.partial_z.resize(nz * 16);
        for (std::size_t g = 0; g < nz; ++g) {
            const auto& bz = table_[2][g];
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i)
                    s.partial_z[g * 16 + std::size_t(i * 4 + j)] = bz[0] * P[i][j][0] + bz[1] * P[i][j][1] + bz[2] * P[i][j][2] + bz[3] * P[i][j][3];
        }
        s.partial_yz.resize(ny * 4);
        auto map_slice = [&](std::size_t g, std::vector<Eigen::Vector3d>& out) {
            out.resize(nx * ny);
            for (std::size_t f = 0; f < ny; ++f) {
                const auto& by = table_[1][f];
                const Eigen::Vector3d* r = &s.partial_z[g * 16];
                for (int i = 0; i < 4; ++i)
                    s.partial_yz[f * 4 + std::size_t(i)] = by[0] * r[i * 4 + 0] + by[1] * r[i * 4 + 1] + by[2] * r[i * 4 + 2] + by[3] * r[i * 4 + 3];
            }
            for (std::size_t f = 0; f < ny; ++f) {
                const Eigen::Vector3d* q = &s.partial_yz[f * 4];
                Eigen::Vector3d* row = &out[f * nx];
                for (std::size_t e = 0; e < nx; ++e) {
                    const auto& bx = table_[0][e];
                    row[e] = bx[0] * q[0] + bx[1] * q[1] + bx[2] * q[2] + bx[3] * q[3];
                }
            }
        };
        map_slice(0, s.slice[0]);
        map_slice(1, s.slice[1]);
        for (int l = 0; l < gz; ++l) {
            map_slice(std::size_t(l) + 2, s.slice[std::size_t(l + 2) % 3]);
            const auto& below = s.slice[std::size_t(l) % 3];
            const auto& here = s.slice[std::size_t(l + 1) % 3];
            const auto& above = s.slice[std::size_t(l + 2) % 3];
            const std::int64_t g = std::int64_t(c) * gz + l;
            for (int m = 0; m < gy; ++m) {
                const std::int64_t e0 = std::int64_t(a) * gx, f = std::int64_t(b) * gy + m;
                for (int n = 0; n < gx; ++n) {
                    if (!near(e0 + n, f, g)) continue;
                    const std::size_t p = std::size_t(n + 1) + nx * std::size_t(m + 1);
                    const Eigen::Vector3d& centre = here[p];
                    const Eigen::Vector3d ex = 0.5 * (here[p + 1] - here[p - 1]);
                    const Eigen::Vector3d ey = 0.5 * (here[p + nx] - here[p - nx]);
                    const Eigen::Vector3d ez = 0.5 * (above[p] - below[p]);
                    const VoxelImage image = voxel_image(centre, ex, ey, ez);
                    visit(centre, image.lo, image.hi, domain_.density(e0 + n, f, g), image.mass);
                }
            }
        }
    }

    /// Target-index bounds the region's splats (or preview points) touch.
    Box region_box(const Lattice& lattice, int a, int b, int c, RegionScratch& s, bool preview) const {
        Box box;
        for_each_box(lattice, a, b, c, s, [&](const Eigen::Vector3d& centre, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, float, double) {
            Index3 l, u;
            for (std::size_t i = 0; i < 3; ++i) {
                if (preview) {
                    l[i] = u[i] = floor_index(centre[int(i)] + 0.5);
                } else {
                    l[i] = floor_index(lo[int(i)] + 0.5);
                    u[i] = floor_index(hi[int(i)] + 0.5);
                }
            }
            box.include(l, u);
        });
        return box;
    }

    /// Add (sign = +1) or remove (sign = -1) a mapped region's contributions.
    void splat_region(const Lattice& lattice, int a, int b, int c, RegionScratch& s, bool preview, int sign, Accumulator& acc) const {
        for_each_box(lattice, a, b, c, s, [&](const Eigen::Vector3d& centre, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, float density, double mass) {
            if (preview) {
                const std::int64_t t = acc.index(floor_index(centre.x() + 0.5), floor_index(centre.y() + 0.5), floor_index(centre.z() + 0.5));
                acc.cells[std::size_t(t)].weight += sign * std::int32_t(kFixedOne);
                acc.cells[std::size_t(t)].value += sign * to_fixed(double(density));
                return;
            }
            double overlap[3][16];
            std::int64_t first[3];
            int count[3];
            bool small = true;
            for (int i = 0; i < 3; ++i) {
                first[i] = floor_index(lo[i] + 0.5);
                if (hi[i] - lo[i] > 1.0) {
                    small = false;
                    break;
                }
                // A box at most one voxel wide covers the cell it starts in and at most the next one.
                const double edge = double(first[i]) + 0.5;
                overlap[i][0] = std::min(hi[i], edge) - lo[i];
                overlap[i][1] = hi[i] - edge;
                count[i] = overlap[i][1] > 0 ? 2 : 1;
            }
            if (!small)
                for (int i = 0; i < 3; ++i) {
                    first[i] = floor_index(lo[i] + 0.5);
                    const std::int64_t last = floor_index(hi[i] + 0.5);
                    count[i] = int(std::min<std::int64_t>(last - first[i] + 1, 16)); // a voxel stretched past 15 voxels is clipped
                    for (int q = 0; q < count[i]; ++q) {
                        const double cell = double(first[i] + q);
                        overlap[i][q] = std::max(0.0, std::min(hi[i], cell + 0.5) - std::max(lo[i], cell - 0.5));
                    }
                }
            const double scaled_density = double(density);
            const std::int64_t row_stride = acc.dims[0], slab_stride = acc.dims[0] * acc.dims[1];
            const std::int64_t base = acc.index(first[0], first[1], first[2]);
            for (int z = 0; z < count[2]; ++z)
                for (int y = 0; y < count[1]; ++y) {
                    const double oyz = overlap[1][y] * overlap[2][z] * mass;
                    Cell* cell = &acc.cells[std::size_t(base + z * slab_stride + y * row_stride)];
                    for (int x = 0; x < count[0]; ++x) {
                        const double w = overlap[0][x] * oyz;
                        cell[x].weight += sign * to_fixed(w);
                        cell[x].value += sign * to_fixed(w * scaled_density);
                    }
                }
        });
    }
private:
    /// Skipping empty space. A domain voxel with no density within kReach voxels only adds weight to target
    /// voxels that no density reaches (unless the map compresses space about threefold there): it cannot change
    /// the result, so neither the full warp nor an incremental update splats it (the same rule in both keeps
    /// them bit-identical). near_ marks the voxels within kReach of density (a separable max filter), over the
    /// voxmap grown by kReach on every side; a region with no marked voxel is skipped whole.
    static constexpr std::int64_t kReach = 3;

    bool near(std::int64_t e, std::int64_t f, std::int64_t g) const {
        const std::int64_t i = e - domain_.offset[0] + kReach, j = f - domain_.offset[1] + kReach, k = g - domain_.offset[2] + kReach;
        if (i < 0 || j < 0 || k < 0 || i >= near_dims_[0] || j >= near_dims_[1] || k >= near_dims_[2]) return false;
        return near_[std::size_t(i + near_dims_[0] * (j + near_dims_[1] * k))] != 0;
    }

    void find_active_regions() {
        const auto& dm = domain_.voxmap;
        for (std::size_t a = 0; a < 3; ++a) near_dims_[a] = dm.dims[a] + 2 * kReach;
        const std::int64_t nx = near_dims_[0], ny = near_dims_[1], nz = near_dims_[2];
        near_.assign(std::size_t(nx * ny * nz), 0);
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, dm.dims[2]), [&](const auto& r) {
            for (std::int64_t k = r.begin(); k != r.end(); ++k)
                for (std::int64_t j = 0; j < dm.dims[1]; ++j)
                    for (std::int64_t i = 0; i < dm.dims[0]; ++i)
                        near_[std::size_t((i + kReach) + nx * ((j + kReach) + ny * (k + kReach)))] = dm.at(i, j, k) != 0.0f;
        });
        // Dilate by kReach along x, then y, then z (a cube of radius kReach).
        const std::array<std::int64_t, 3> stride{1, nx, nx * ny};
        for (std::size_t axis = 0; axis < 3; ++axis) {
            const std::int64_t len = near_dims_[axis], step = stride[axis];
            const std::int64_t lines = std::int64_t(near_.size()) / len;
            tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, lines, 256), [&](const auto& r) {
                std::vector<std::uint8_t> line(static_cast<std::size_t>(len));
                for (std::int64_t q = r.begin(); q != r.end(); ++q) {
                    // Line q: all cells sharing the other two coordinates.
                    std::int64_t base;
                    if (axis == 0) base = q * nx;
                    else if (axis == 1) base = (q % nx) + (q / nx) * nx * ny;
                    else base = q;
                    for (std::int64_t t = 0; t < len; ++t) line[std::size_t(t)] = near_[std::size_t(base + t * step)];
                    std::int64_t last = -(kReach + 1);
                    for (std::int64_t t = 0; t < len; ++t) { // forward: within kReach after a set cell
                        if (line[std::size_t(t)]) last = t;
                        if (t - last <= kReach) near_[std::size_t(base + t * step)] = 1;
                    }
                    last = len + kReach + 1;
                    for (std::int64_t t = len - 1; t >= 0; --t) { // backward: within kReach before one
                        if (line[std::size_t(t)]) last = t;
                        if (last - t <= kReach) near_[std::size_t(base + t * step)] = 1;
                    }
                }
            });
        }
        active_.assign(region_count(), 0);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, region_count()), [&](const auto& range) {
            for (std::size_t r = range.begin(); r != range.end(); ++r) {
                const int a = int(r % std::size_t(regions_[0])), b = int((r / std::size_t(regions_[0])) % std::size_t(regions_[1])),
                          c = int(r / (std::size_t(regions_[0]) * std::size_t(regions_[1])));
                const int ga = domain_.granularity[0], gb = domain_.granularity[1], gc = domain_.granularity[2];
                bool any = false;
                for (std::int64_t g = std::int64_t(c) * gc; !any && g < std::int64_t(c + 1) * gc; ++g)
                    for (std::int64_t f = std::int64_t(b) * gb; !any && f < std::int64_t(b + 1) * gb; ++f)
                        for (std::int64_t e = std::int64_t(a) * ga; e < std::int64_t(a + 1) * ga; ++e)
                            if (near(e, f, g)) {
                                any = true;
                                break;
                            }
                active_[r] = any;
            }
        });
    }

    const WarpDomain& domain_;
    Eigen::Vector3d target_origin_;
    double h_;
    std::array<std::vector<std::array<double, 4>>, 3> table_;
    std::array<int, 3> regions_{};
    std::vector<std::uint8_t> active_;
    std::vector<std::uint8_t> near_;
    std::array<std::int64_t, 3> near_dims_{};
};

/// Density of one target voxel from its fixed-point sums (paper: wv if weight < 1, else wv / weight).
inline float resolve(const Cell& cell) {
    if (cell.weight <= 0 || cell.value <= 0) return 0.0f;
    const double d = cell.weight < std::int32_t(kFixedOne) ? double(cell.value) / kFixedOne : double(cell.value) / double(cell.weight);
    return float(std::min(1.0, d));
}

} // namespace warp_internal

using namespace warp_internal;

struct Warp::State {
    std::shared_ptr<const WarpDomain> domain_ptr; // owned by a Warp, borrowed by the one-shot warp()
    const WarpDomain& domain;
    explicit State(std::shared_ptr<const WarpDomain> d) : domain_ptr(std::move(d)), domain(*domain_ptr) {}
    Lattice lattice;
    WarpOptions options;
    std::unique_ptr<Splatter> splatter;
    std::vector<Box> boxes; // per region, what its current splat touches
    Accumulator acc;
    Voxmap result;
    tbb::enumerable_thread_specific<RegionScratch> scratch;

    std::vector<std::size_t> active_regions() const {
        std::vector<std::size_t> out;
        for (std::size_t r = 0; r < splatter->region_count(); ++r)
            if (splatter->active(r)) out.push_back(r);
        return out;
    }
    std::array<int, 3> unpack(std::size_t r) const {
        const auto n = splatter->regions();
        return {int(r % std::size_t(n[0])), int((r / std::size_t(n[0])) % std::size_t(n[1])), int(r / (std::size_t(n[0]) * std::size_t(n[1])))};
    }

    /// Recompute the boxes of `regions` for the current lattice.
    void compute_boxes(const std::vector<std::size_t>& regions) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, regions.size(), 1), [&](const auto& range) {
            auto& s = scratch.local();
            for (std::size_t q = range.begin(); q != range.end(); ++q) {
                const auto [a, b, c] = unpack(regions[q]);
                boxes[regions[q]] = splatter->region_box(lattice, a, b, c, s, options.preview);
            }
        });
    }

    /// Splat `regions` with `sign`, in eight parity phases: regions two apart along every axis write disjoint
    /// target voxels unless the map compresses a region to nothing, which is checked (then the phase runs serially).
    void splat(const std::vector<std::size_t>& regions, int sign, Progress* progress) {
        std::size_t done = 0;
        for (int phase = 0; phase < 8; ++phase) {
            std::vector<std::size_t> batch;
            for (auto r : regions) {
                const auto [a, b, c] = unpack(r);
                if ((a & 1) == (phase & 1) && (b & 1) == ((phase >> 1) & 1) && (c & 1) == ((phase >> 2) & 1)) batch.push_back(r);
            }
            bool disjoint = true;
            for (std::size_t x = 0; x < batch.size() && disjoint; ++x)
                for (std::size_t y = x + 1; y < batch.size(); ++y)
                    if (boxes[batch[x]].overlaps(boxes[batch[y]])) {
                        disjoint = false;
                        break;
                    }
            auto work = [&](std::size_t q) {
                auto& s = scratch.local();
                const auto [a, b, c] = unpack(batch[q]);
                splatter->splat_region(lattice, a, b, c, s, options.preview, sign, acc);
            };
            if (disjoint)
                tbb::parallel_for(tbb::blocked_range<std::size_t>(0, batch.size(), 1), [&](const auto& range) {
                    for (std::size_t q = range.begin(); q != range.end(); ++q) work(q);
                });
            else
                for (std::size_t q = 0; q < batch.size(); ++q) work(q);
            done += batch.size();
            if (progress) progress->report(double(done) / double(std::max<std::size_t>(1, regions.size())));
        }
    }

    /// Resolve densities inside `box` (target index space) into the result voxmap.
    void resolve_box(const Box& box) {
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(box.lo[2], box.hi[2] + 1), [&](const auto& range) {
            for (std::int64_t k = range.begin(); k != range.end(); ++k)
                for (std::int64_t j = box.lo[1]; j <= box.hi[1]; ++j) {
                    std::int64_t t = acc.index(box.lo[0], j, k);
                    const std::int64_t out = result.index(box.lo[0] - acc.box.lo[0], j - acc.box.lo[1], k - acc.box.lo[2]);
                    for (std::int64_t i = 0; i <= box.hi[0] - box.lo[0]; ++i, ++t)
                        result.density[std::size_t(out + i)] = resolve(acc.cells[std::size_t(t)]);
                }
        });
    }

    void full(Progress* progress) {
        const auto regions = active_regions();
        compute_boxes(regions);
        Box all;
        for (auto r : regions) all.include(boxes[r]);
        if (all.empty()) { // no density at all: a one-voxel empty target at the domain's origin
            all.lo = all.hi = Index3{0, 0, 0};
        }
        // A margin of two voxels lets small incremental moves stay inside without regrowing.
        for (std::size_t i = 0; i < 3; ++i) all.lo[i] -= 2, all.hi[i] += 2;
        Index3 dims;
        for (std::size_t i = 0; i < 3; ++i) dims[i] = all.hi[i] - all.lo[i] + 1;
        require_memory(std::uint64_t(dims[0]) * std::uint64_t(dims[1]) * std::uint64_t(dims[2]) * (sizeof(Cell) + sizeof(float)), 0,
                       "warp target of " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]) + " voxels");
        acc.allocate(all);
        result = Voxmap(dims, domain.target_origin + domain.target_voxel_size * Eigen::Vector3d(double(all.lo[0]), double(all.lo[1]), double(all.lo[2])),
                        domain.target_voxel_size);
        splat(regions, +1, progress);
        resolve_box(all);
    }
};

Warp::Warp(WarpDomain domain, const Lattice& lattice, const WarpOptions& options)
    : Warp(std::make_shared<const WarpDomain>(std::move(domain)), lattice, options) {}

Warp::Warp(std::shared_ptr<const WarpDomain> domain, const Lattice& lattice, const WarpOptions& options)
    : state_(std::make_unique<State>(std::move(domain))) {
    auto& s = *state_;
    if (lattice.size() != s.domain.lattice.size()) throw InvalidInput("warp: the lattice's size differs from the domain's");
    s.lattice = lattice;
    s.options = options;
    s.splatter = std::make_unique<Splatter>(s.domain, s.domain.target_origin, s.domain.target_voxel_size);
    s.boxes.resize(s.splatter->region_count());
    Progress progress(options.progress, "warp");
    s.full(&progress);
}

Warp::~Warp() = default;
Warp::Warp(Warp&&) noexcept = default;
Warp& Warp::operator=(Warp&&) noexcept = default;

const Lattice& Warp::lattice() const { return state_->lattice; }
const WarpDomain& Warp::domain() const { return state_->domain; }
Voxmap Warp::target() const { return state_->result; }

void Warp::move_control_point(int i, int j, int k, const Eigen::Vector3d& position) {
    auto& s = *state_;
    const auto n = s.lattice.size();
    if (i < 0 || j < 0 || k < 0 || i >= n[0] || j >= n[1] || k >= n[2])
        throw InvalidInput("control point (" + std::to_string(i) + ", " + std::to_string(j) + ", " + std::to_string(k) + ") is outside the " +
                           std::to_string(n[0]) + "x" + std::to_string(n[1]) + "x" + std::to_string(n[2]) + " lattice");
    if (!position.allFinite()) throw InvalidInput("control point position is not finite");
    // Regions a in [i-3, i] (clamped) use point i along x; likewise along y and z.
    const auto r = s.splatter->regions();
    std::vector<std::size_t> affected;
    for (int c = std::max(0, k - 3); c <= std::min(r[2] - 1, k); ++c)
        for (int b = std::max(0, j - 3); b <= std::min(r[1] - 1, j); ++b)
            for (int a = std::max(0, i - 3); a <= std::min(r[0] - 1, i); ++a) {
                const std::size_t idx = s.splatter->region_index(a, b, c);
                if (s.splatter->active(idx)) affected.push_back(idx);
            }
    Box touched;
    for (auto idx : affected) touched.include(s.boxes[idx]);
    s.splat(affected, -1, nullptr);
    s.lattice.set_point(i, j, k, position);
    s.compute_boxes(affected);
    Box after;
    for (auto idx : affected) after.include(s.boxes[idx]);
    if (!s.acc.box.contains(after)) { // the moved regions reach outside the target: grow it
        s.full(nullptr);
        return;
    }
    s.splat(affected, +1, nullptr);
    touched.include(after);
    if (!touched.empty()) s.resolve_box(touched);
}

Voxmap warp(const WarpDomain& domain, const Lattice& lattice, const WarpOptions& options) {
    // Borrow the domain (no copy of its voxmap) for the lifetime of this call.
    Warp w(std::shared_ptr<const WarpDomain>(&domain, [](const WarpDomain*) {}), lattice, options);
    return std::move(w.state_->result);
}

} // namespace voxwarp
