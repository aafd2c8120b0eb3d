// The forward splat of True & Hughes section 6, evaluated region by region with the section 4 tables, and the
// section 7 incremental update. See warp.h for the conventions.
#include <voxwarp/basis.h>
#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp/warp.h>

#include "carry.h"
#include "resolve.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <limits>
#include <mutex>
#include <tuple>
#include <utility>

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

/// Fixed-point accumulators over a box of the target grid, stored sparsely in 8^3 blocks allocated on first
/// touch: only the narrow band's image is ever splatted, and a block no splat reached resolves to its side
/// (resolve.h), so the dense accumulator of the whole target (8 bytes a voxel) is never needed.
class BlockAccumulator {
public:
    static constexpr std::int64_t kSide = 8, kCells = kSide * kSide * kSide;

    Box box;
    Index3 blocks{0, 0, 0}; // per axis

    /// `limit_bytes`: what the cells may take in all (the chunks, as they are allocated).
    void reset(const Box& b, std::uint64_t limit_bytes) {
        box = b;
        limit_ = limit_bytes;
        allocated_ = 0;
        for (std::size_t a = 0; a < 3; ++a) blocks[a] = (b.hi[a] - b.lo[a] + kSide) / kSide;
        table_ = std::vector<std::atomic<Cell*>>(std::size_t(blocks[0] * blocks[1] * blocks[2]));
        chunks_.clear();
        arenas_.clear();
    }

    /// The block holding target-relative cell (x, y, z) (relative to box.lo), allocated zeroed if absent.
    /// Thread-safe: two threads racing for one block agree on one (compare-and-swap), the loser keeps its
    /// fresh block for its next request.
    Cell* block(std::int64_t x, std::int64_t y, std::int64_t z) {
        auto& slot = table_[std::size_t((x >> 3) + blocks[0] * ((y >> 3) + blocks[1] * (z >> 3)))];
        Cell* p = slot.load(std::memory_order_acquire);
        if (p) return p;
        Arena& arena = arenas_.local();
        Cell* fresh = take(arena);
        if (slot.compare_exchange_strong(p, fresh, std::memory_order_acq_rel)) return fresh;
        arena.spare = fresh;
        return p;
    }
    /// Block (bx, by, bz) (block coordinates, relative to box.lo), or null where no splat reached.
    const Cell* find(std::int64_t bx, std::int64_t by, std::int64_t bz) const {
        return table_[std::size_t(bx + blocks[0] * (by + blocks[1] * bz))].load(std::memory_order_acquire);
    }
    static std::int64_t offset(std::int64_t x, std::int64_t y, std::int64_t z) { return (x & 7) + kSide * ((y & 7) + kSide * (z & 7)); }
    /// Block (bx, by, bz)'s place in the block table, and the block there (null where no splat reached).
    std::size_t slot(std::int64_t bx, std::int64_t by, std::int64_t bz) const { return std::size_t(bx + blocks[0] * (by + blocks[1] * bz)); }
    Cell* at_slot(std::size_t slot) const { return table_[slot].load(std::memory_order_acquire); }

private:
    static constexpr std::size_t kChunkBlocks = 512; // 2 MiB: one huge page
    struct Arena {
        Cell* next = nullptr;
        Cell* end = nullptr;
        Cell* spare = nullptr; // zeroed, never handed out
    };
    Cell* take(Arena& arena) {
        if (arena.spare) return std::exchange(arena.spare, nullptr);
        if (arena.next == arena.end) {
            const std::size_t bytes = kChunkBlocks * kCells * sizeof(Cell);
            // Checked as the band grows, since no bound known beforehand is tight: a fold-free map that stretches
            // a wall over hundreds of voxels fills every cell it crosses.
            const std::uint64_t total = allocated_.fetch_add(bytes) + bytes;
            if (total > limit_)
                throw ResourceLimit("warp: the warped surface band needs more than " + format_bytes(total) + ", the limit (--max-memory, or 90% of available memory) being " +
                                    format_bytes(limit_) + "; the map stretches space too far for this resolution: lower it, split the edit, or raise --max-memory");
            std::unique_ptr<Cell[], ReleaseCells> chunk(static_cast<Cell*>(allocate_large(bytes)), ReleaseCells{bytes});
            arena.next = chunk.get();
            arena.end = arena.next + kChunkBlocks * kCells;
            const std::lock_guard lock(mutex_);
            chunks_.push_back(std::move(chunk));
        }
        Cell* p = arena.next;
        arena.next += kCells;
        std::fill(p, p + kCells, Cell{0, 0});
        return p;
    }

    std::vector<std::atomic<Cell*>> table_;
    std::uint64_t limit_ = std::numeric_limits<std::uint64_t>::max();
    std::atomic<std::uint64_t> allocated_{0};
    std::vector<std::unique_ptr<Cell[], ReleaseCells>> chunks_;
    std::mutex mutex_;
    tbb::enumerable_thread_specific<Arena> arenas_;
};

/// What a region's carried voxels (resolve.h) carry through the map as it stands.
struct RegionCarry {
    std::vector<CarryImage> images;
    std::vector<Carry> cells; // their images' cells
};

/// The splat of one domain voxel. The paper takes the bounding box of the six mapped face centres; under a
/// rotation that box is smaller than the voxel's image (0.71 wide at 45 degrees), so splats stop covering
/// the target and density is lost (a quarter of it at 30 degrees). Instead: the exact bounding box of the
/// voxel's linearised image, the parallelepiped centre + [-1/2, 1/2] x (ex, ey, ez) spanned by the map's
/// Jacobian columns (per voxel step), with every overlap scaled by |det| / box volume, so each voxel deposits
/// exactly its image's volume. For translations and axis scalings this is the paper's box, weight 1.
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

/// Basis values and derivatives (per voxel step) at one tabulated parameter l / G.
struct BasisEntry {
    std::array<double, 4> value, slope;
};

inline Eigen::Vector3d combine(const std::array<double, 4>& w, const Eigen::Vector3d* p, std::size_t stride = 1) {
    return w[0] * p[0] + w[1] * p[stride] + w[2] * p[2 * stride] + w[3] * p[3 * stride];
}

class Splatter {
public:
    Splatter(const WarpDomain& domain, const Eigen::Vector3d& target_origin, double h)
        : domain_(domain), target_origin_(target_origin), h_(h) {
        for (std::size_t a = 0; a < 3; ++a) {
            const int g = domain.granularity[a];
            table_[a].resize(std::size_t(g));
            for (int l = 0; l < g; ++l) {
                auto& entry = table_[a][std::size_t(l)];
                entry.value = cubic_basis(double(l) / g);
                entry.slope = cubic_basis_derivative(double(l) / g);
                for (double& d : entry.slope) d /= g;
            }
            regions_[a] = domain.lattice.regions()[a];
        }
        find_band();
        find_thin();
    }

    std::array<int, 3> regions() const { return regions_; }
    std::size_t region_count() const { return std::size_t(regions_[0]) * std::size_t(regions_[1]) * std::size_t(regions_[2]); }
    std::size_t region_index(int a, int b, int c) const { return std::size_t(a) + std::size_t(regions_[0]) * (std::size_t(b) + std::size_t(regions_[1]) * std::size_t(c)); }
    bool active(std::size_t r) const { return active_[r] != 0; }

    /// Map the band voxels of region (a, b, c) through `lattice` and visit each with its splat box [lo, hi]
    /// (target index units), mass share, density, index within the region (e - e0 + Gx (f - f0 + Gy (g - g0)),
    /// increasing in visiting order) and the map's derivatives per voxel step (the image's edges). Separable, as in the paper's section 4: the region's 64
    /// control points are contracted with the z table once per slice, with the y table once per row, and with
    /// the x table per voxel; the derivative tables give the Jacobian the same way. Only rows holding band
    /// voxels are contracted at all.
    template <class F>
    void for_each_box(const Lattice& lattice, int a, int b, int c, F&& visit) const {
        const int gx = domain_.granularity[0], gy = domain_.granularity[1], gz = domain_.granularity[2];
        Eigen::Vector3d P[4][4][4]; // [k][j][i]
        for (int k = 0; k < 4; ++k)
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i) P[k][j][i] = (lattice.point(a + i, b + j, c + k) - target_origin_) / h_;
        const std::int64_t e0 = std::int64_t(a) * gx;
        for (int l = 0; l < gz; ++l) {
            const std::int64_t g = std::int64_t(c) * gz + l;
            bool contracted = false;
            Eigen::Vector3d zv[4][4], zs[4][4]; // [j][i]: contracted with the z values / z slopes
            for (int m = 0; m < gy; ++m) {
                const std::int64_t f = std::int64_t(b) * gy + m;
                const auto [run, runs_end] = band_runs(f, g);
                if (!any_run_within(run, runs_end, e0, e0 + gx - 1)) continue;
                if (!contracted) {
                    const auto& bz = table_[2][std::size_t(l)];
                    for (int j = 0; j < 4; ++j)
                        for (int i = 0; i < 4; ++i) {
                            zv[j][i] = combine(bz.value, &P[0][j][i], 16);
                            zs[j][i] = combine(bz.slope, &P[0][j][i], 16);
                        }
                    contracted = true;
                }
                const auto& by = table_[1][std::size_t(m)];
                Eigen::Vector3d q[4], qy[4], qz[4];
                for (int i = 0; i < 4; ++i) {
                    q[i] = combine(by.value, &zv[0][i], 4);
                    qy[i] = combine(by.slope, &zv[0][i], 4);
                    qz[i] = combine(by.value, &zs[0][i], 4);
                }
                // The voxmap blocks under this domain row (none in the zero padding).
                const SparseVoxmap& vm = domain_.voxmap;
                const std::int64_t vy = f - domain_.offset[1], vz = g - domain_.offset[2];
                const bool inside_row = vy >= 0 && vz >= 0 && vy < vm.dims()[1] && vz < vm.dims()[2];
                const std::int64_t first_block = inside_row ? vm.block_index(0, vy >> 3, vz >> 3) : 0;
                const std::int64_t in_block = SparseVoxmap::kSide * ((vy & 7) + SparseVoxmap::kSide * (vz & 7));
                auto density_at = [&](std::int64_t vx) {
                    if (!inside_row || vx < 0 || vx >= vm.dims()[0]) return 0.0f;
                    const std::int64_t b = first_block + (vx >> 3);
                    const float* values = vm.block_values(b);
                    return values ? values[in_block + (vx & 7)] : vm.block_uniform(b);
                };
                for (auto r = run; r != runs_end; ++r) {
                    const std::int64_t first = std::max<std::int64_t>(e0, (*r)[0] + domain_.offset[0] - kReach);
                    const std::int64_t last = std::min<std::int64_t>(e0 + gx - 1, (*r)[1] + domain_.offset[0] - kReach);
                    for (std::int64_t e = first; e <= last; ++e) {
                        const auto& bx = table_[0][std::size_t(e - e0)];
                        const Eigen::Vector3d centre = combine(bx.value, q);
                        const Eigen::Vector3d ex = combine(bx.slope, q), ey = combine(bx.value, qy), ez = combine(bx.value, qz);
                        const VoxelImage image = voxel_image(centre, ex, ey, ez);
                        const std::int64_t vx = e - domain_.offset[0];
                        visit(centre, image.lo, image.hi, density_at(vx), image.mass, std::uint64_t(e - e0) + std::uint64_t(gx) * (std::uint64_t(m) + std::uint64_t(gy) * std::uint64_t(l)), ex, ey, ez);
                    }
                }
            }
        }
    }

    /// The target cells a splat writes: `count` cells from `first` per axis, with the overlap of each. A box at
    /// most one voxel wide always gets two cells (the second possibly with zero overlap): branch-free.
    struct Footprint {
        std::int64_t first[3];
        int count[3];
        double overlap[3][16];
    };
    static void footprint(const Eigen::Vector3d& centre, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, bool preview, Footprint& fp) {
        for (int i = 0; i < 3; ++i) {
            if (preview) {
                // Map and round, with the gaps filled: a voxel lands on the cells around its image's centre with
                // tent weights reaching half its image box and half a cell beyond (at the identity: its own cell,
                // weight 1), and cells resolve to their weighted mean. Rounding the centre alone leaves gaps
                // wherever the map stretches; the row rule then carried an inside voxel across them to the grid's
                // edge. Overlapping tents make the mean linear between voxel centres, the surface stays put.
                const double r = 0.5 * (hi[i] - lo[i]) + 0.5;
                fp.first[i] = std::int64_t(std::ceil(centre[i] - r + 1e-9));
                fp.count[i] = int(std::clamp<std::int64_t>(std::int64_t(std::floor(centre[i] + r - 1e-9)) - fp.first[i] + 1, 0, 16));
                for (int q = 0; q < fp.count[i]; ++q) fp.overlap[i][q] = std::max(0.0, 1.0 - std::abs(double(fp.first[i] + q) - centre[i]) / r);
                continue;
            }
            fp.first[i] = floor_index(lo[i] + 0.5);
            if (hi[i] - lo[i] <= 1.0) {
                const double edge = double(fp.first[i]) + 0.5;
                fp.overlap[i][0] = std::min(hi[i], edge) - lo[i];
                fp.overlap[i][1] = std::max(0.0, hi[i] - edge);
                fp.count[i] = 2;
                continue;
            }
            const std::int64_t last = floor_index(hi[i] + 0.5);
            fp.count[i] = int(std::min<std::int64_t>(last - fp.first[i] + 1, 16)); // a voxel stretched past 15 voxels is clipped
            for (int q = 0; q < fp.count[i]; ++q) {
                const double cell = double(fp.first[i] + q);
                fp.overlap[i][q] = std::max(0.0, std::min(hi[i], cell + 0.5) - std::max(lo[i], cell - 0.5));
            }
        }
    }

    /// Conservative target-index bounds of the cells region (a, b, c)'s splats write, from its control points
    /// alone (no voxel is mapped): the region's patch lies in the convex hull of its 64 Bezier points (the
    /// B-spline segment converted per axis), and a splat reaches at most half its Jacobian box beyond its centre,
    /// each Jacobian component being a convex combination of control-point differences over G. Exact for
    /// affine maps up to the splat's extent.
    Box region_bound(const Lattice& lattice, int a, int b, int c) const {
        Eigen::Vector3d P[4][4][4]; // [k][j][i], target index units
        for (int k = 0; k < 4; ++k)
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i) P[k][j][i] = (lattice.point(a + i, b + j, c + k) - target_origin_) / h_;
        Eigen::Vector3d reach = Eigen::Vector3d::Zero(); // half-extent bound of a splat box, per component
        for (int axis = 0; axis < 3; ++axis) {
            Eigen::Vector3d largest = Eigen::Vector3d::Zero();
            for (int k = 0; k < 4; ++k)
                for (int j = 0; j < 4; ++j)
                    for (int i = 0; i < 3; ++i) {
                        const Eigen::Vector3d d = axis == 0 ? P[k][j][i + 1] - P[k][j][i] : axis == 1 ? P[k][i + 1][j] - P[k][i][j] : P[i + 1][k][j] - P[i][k][j];
                        largest = largest.cwiseMax(d.cwiseAbs());
                    }
            reach += 0.5 * largest / domain_.granularity[std::size_t(axis)];
        }
        // B-spline segment -> Bezier points, one axis at a time.
        auto to_bezier = [](Eigen::Vector3d* p, int stride) {
            const Eigen::Vector3d p0 = p[0], p1 = p[stride], p2 = p[2 * stride], p3 = p[3 * stride];
            p[0] = (p0 + 4 * p1 + p2) / 6;
            p[stride] = (2 * p1 + p2) / 3;
            p[2 * stride] = (p1 + 2 * p2) / 3;
            p[3 * stride] = (p1 + 4 * p2 + p3) / 6;
        };
        Eigen::Vector3d* flat = &P[0][0][0];
        for (int q = 0; q < 16; ++q) to_bezier(flat + 4 * q, 1);                      // along i
        for (int k = 0; k < 4; ++k)
            for (int i = 0; i < 4; ++i) to_bezier(flat + 16 * k + i, 4);              // along j
        for (int q = 0; q < 16; ++q) to_bezier(flat + q, 16);                          // along k
        Eigen::Vector3d lo = flat[0], hi = flat[0];
        for (int q = 1; q < 64; ++q) lo = lo.cwiseMin(flat[q]), hi = hi.cwiseMax(flat[q]);
        lo -= reach, hi += reach; // the preview rounds the same boxes
        Box box;
        Index3 l, u;
        for (std::size_t i = 0; i < 3; ++i) {
            // floor(x + 0.5) is the cell of x; one more each side for rounding, and the splat's second cell.
            l[i] = floor_index(lo[int(i)] + 0.5) - 1;
            u[i] = floor_index(hi[int(i)] + 0.5) + 2;
        }
        box.include(l, u);
        return box;
    }

    /// Add (sign = +1) or remove (sign = -1) a mapped region's contributions; returns the bounds of the cells
    /// written. A cell outside the accumulator's box is not written and sets `overflow`. With `carried`, the
    /// target cells the region's thin voxels carry (resolve.h) are appended to it.
    Box splat_region(const Lattice& lattice, int a, int b, int c, bool preview, int sign, BlockAccumulator& acc, bool& overflow,
                     RegionCarry* carried = nullptr) const {
        const Index3 origin = acc.box.lo, extent{acc.box.hi[0] - acc.box.lo[0], acc.box.hi[1] - acc.box.lo[1], acc.box.hi[2] - acc.box.lo[2]};
        Box box;
        Footprint fp;
        const auto& thin = thin_[region_index(a, b, c)];
        auto next_thin = thin.begin();
        const std::uint64_t gx = std::uint64_t(domain_.granularity[0]), gy = std::uint64_t(domain_.granularity[1]), gz = std::uint64_t(domain_.granularity[2]);
        const std::array<std::uint64_t, 3> dims{std::uint64_t(domain_.dims[0]), std::uint64_t(domain_.dims[1]), std::uint64_t(domain_.dims[2])};
        for_each_box(lattice, a, b, c, [&](const Eigen::Vector3d& centre, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, float density, double mass,
                                           std::uint64_t local, const Eigen::Vector3d& ex, const Eigen::Vector3d& ey, const Eigen::Vector3d& ez) {
            if (carried && next_thin != thin.end()) { // both in visiting order: a merge
                while (next_thin != thin.end() && *next_thin < local) ++next_thin;
                if (next_thin != thin.end() && *next_thin == local) {
                    const std::uint64_t e = std::uint64_t(a) * gx + local % gx, f = std::uint64_t(b) * gy + (local / gx) % gy,
                                        g = std::uint64_t(c) * gz + local / (gx * gy);
                    const bool inside = density >= 0.5f;
                    const auto cell = nearest_cell(centre.data());
                    carried->images.push_back({e + dims[0] * (f + dims[1] * g), cell, inside});
                    box.include(cell, cell);
                    Eigen::Matrix3d J;
                    J << ex, ey, ez;
                    image_cells(centre, J, [&](const Index3& x) {
                        carried->cells.push_back({x, inside});
                        box.include(x, x); // so an incremental move resolves again the rows its old carries reached
                    });
                }
            }
            footprint(centre, lo, hi, preview, fp);
            if (fp.count[0] == 0 || fp.count[1] == 0 || fp.count[2] == 0) return; // a preview box between cell centres
            const Index3 last{fp.first[0] + fp.count[0] - 1, fp.first[1] + fp.count[1] - 1, fp.first[2] + fp.count[2] - 1};
            box.include({fp.first[0], fp.first[1], fp.first[2]}, last);
            const std::int64_t x0 = fp.first[0] - origin[0], y0 = fp.first[1] - origin[1], z0 = fp.first[2] - origin[2];
            if (x0 < 0 || y0 < 0 || z0 < 0 || last[0] - origin[0] > extent[0] || last[1] - origin[1] > extent[1] || last[2] - origin[2] > extent[2]) {
                overflow = true;
                return;
            }
            // Most splats (2 x 2 x 2 cells) fall inside one block: look it up once.
            const bool one_block = (x0 & 7) + fp.count[0] <= 8 && (y0 & 7) + fp.count[1] <= 8 && (z0 & 7) + fp.count[2] <= 8;
            Cell* shared = one_block ? acc.block(x0, y0, z0) : nullptr;
            const double value = preview ? double(density) : double(density) * mass;
            const double weight = preview ? 1.0 : mass;
            for (int z = 0; z < fp.count[2]; ++z)
                for (int y = 0; y < fp.count[1]; ++y) {
                    const double oyz = fp.overlap[1][y] * fp.overlap[2][z];
                    for (int x = 0; x < fp.count[0]; ++x) {
                        const double o = fp.overlap[0][x] * oyz;
                        const std::int64_t cx = x0 + x, cy = y0 + y, cz = z0 + z;
                        Cell& cell = (shared ? shared : acc.block(cx, cy, cz))[BlockAccumulator::offset(cx, cy, cz)];
                        cell.weight += sign * to_fixed(o * weight);
                        cell.value += sign * to_fixed(o * value);
                    }
                }
        });
        return box;
    }

private:
    /// The narrow band. Only domain voxels within kReach (Chebyshev distance) of a *mixed* voxel (density strictly
    /// between 0 and 1, or a sharp 0/1 step to a face neighbour) are splatted; the rest are pure, deep inside (1)
    /// or far outside (0). A target voxel that skipped voxels reach then receives from the band only pure voxels
    /// of the same side (between pure voxels of opposite sides lies a fractional voxel or a sharp step, both
    /// mixed, and so within reach of neither being skipped), so the resolve rule
    /// (resolve.h) fills what the skipped ones would have added exactly, and the result equals the full splat's.
    /// That holds unless one target voxel gathers domain voxels kReach + 1 apart: a map compressing space about
    /// threefold. kReach = 2 (3 measured 20 % slower and changed nothing in the tests). The same rule in the full
    /// warp and the incremental update keeps them bit-identical. The band (the mixed voxels dilated by a cube of
    /// radius kReach) covers the voxmap grown by kReach on every side (outside the voxmap the domain is empty)
    /// and is kept as runs per row; a region with no band voxel is skipped whole.
    static constexpr std::int64_t kReach = 2;

    /// row |= other, over n bytes (separate arrays, so the loop vectorises).
    static void or_into(std::uint8_t* __restrict row, const std::uint8_t* __restrict other, std::int64_t n) {
        for (std::int64_t i = 0; i < n; ++i) row[i] |= other[i];
    }

    /// A voxmap row as mixed_slab reads it, `pad` zeros either side, and what each of its blocks is: kZero,
    /// kOne (uniform pure values) or kOther. A row whose blocks are all uniform zero is not read: its buffer is
    /// zeroed once and remembered as such, so empty space costs a few block lookups.
    static constexpr std::uint8_t kZero = 0, kOne = 1, kOther = 2;
    struct RowBuffer {
        std::vector<float> values;
        std::vector<std::uint8_t> kinds; // per block along x
        std::int64_t pad = 0;
        bool any = false;  // some value is nonzero
        bool zero = true;  // values are all zero
        RowBuffer(std::int64_t n, std::int64_t p)
            : values(std::size_t(n + 2 * p), 0.0f), kinds(std::size_t((n + SparseVoxmap::kSide - 1) / SparseVoxmap::kSide), kZero), pad(p) {}
        void load(const SparseVoxmap& vm, std::int64_t j, std::int64_t k) {
            if (vm.row_is_zero(j, k)) {
                if (!zero) std::fill(values.begin(), values.end(), 0.0f), std::fill(kinds.begin(), kinds.end(), kZero);
                zero = true;
                any = false;
                return;
            }
            any = vm.read_row(j, k, values.data() + pad);
            zero = !any;
            const std::int64_t b0 = vm.block_index(0, j >> 3, k >> 3);
            for (std::size_t bx = 0; bx < kinds.size(); ++bx) {
                const std::int64_t b = b0 + std::int64_t(bx);
                const float u = vm.block_uniform(b);
                kinds[bx] = vm.block_values(b) ? kOther : u == 0.0f ? kZero : u == 1.0f ? kOne : kOther;
            }
        }
        const float* data() const { return values.data() + pad; }
    };
    /// Row (j, vz), padded for its x neighbours, and its neighbours along y (kept as j advances) and z.
    struct RowWindow {
        RowBuffer previous, here, next, below, above;
        explicit RowWindow(std::int64_t n) : previous(n, 1), here(n, 1), next(n, 1), below(n, 0), above(n, 0) {}
    };

    /// The mixed voxels of voxmap slice vz, dilated by kReach along x and y, into `slab` (a near-grid z-slab,
    /// nx x ny bytes). A voxel is mixed when fractional, or pure with a face neighbour of the other pure value
    /// (a sharp step; 0 outside the voxmap). A pure voxel next to a fractional one is not: it is on its own side.
    void mixed_slab(std::int64_t vz, std::vector<std::uint8_t>& slab, std::vector<std::uint8_t>& line, RowWindow& w) const {
        const auto& dm = domain_.voxmap;
        const std::int64_t nx = near_dims_[0], n = dm.dims()[0];
        std::fill(slab.begin(), slab.end(), std::uint8_t(0));
        if (vz < 0 || vz >= dm.dims()[2]) return;
        std::vector<std::uint8_t> mixed(static_cast<std::size_t>(nx + 2 * kReach), 0); // near-grid row, kReach more zeros each side
        w.previous.load(dm, -1, vz);
        w.here.load(dm, 0, vz);
        for (std::int64_t j = 0; j < dm.dims()[1]; ++j) {
            w.next.load(dm, j + 1, vz);
            w.below.load(dm, j, vz - 1);
            w.above.load(dm, j, vz + 1);
            if (w.previous.any || w.here.any || w.next.any || w.below.any || w.above.any) {
                const float *c = w.here.data(), *s = w.previous.data(), *nb = w.next.data(), *d = w.below.data(), *u = w.above.data();
                std::uint8_t* m = mixed.data() + 2 * kReach;
                bool any = false;
                const std::int64_t blocks = std::int64_t(w.here.kinds.size());
                for (std::int64_t bx = 0; bx < blocks; ++bx) {
                    const std::int64_t i0 = bx * SparseVoxmap::kSide, i1 = std::min(n, i0 + SparseVoxmap::kSide);
                    // Eight voxels whose five rows' blocks, and the row's neighbour blocks along x, are all one pure
                    // value hold no mixed voxel: skipped without a comparison.
                    const std::uint8_t kind = w.here.kinds[std::size_t(bx)];
                    const std::uint8_t left = bx > 0 ? w.here.kinds[std::size_t(bx - 1)] : kZero, right = bx + 1 < blocks ? w.here.kinds[std::size_t(bx + 1)] : kZero;
                    if (kind != kOther && left == kind && right == kind && w.previous.kinds[std::size_t(bx)] == kind && w.next.kinds[std::size_t(bx)] == kind &&
                        w.below.kinds[std::size_t(bx)] == kind && w.above.kinds[std::size_t(bx)] == kind) {
                        std::fill(m + i0, m + i1, std::uint8_t(0));
                        continue;
                    }
                    for (std::int64_t i = i0; i < i1; ++i) {
                        const float v = c[i];
                        const float other = 1.0f - v; // for a pure voxel: the other side's value
                        m[i] = (v != 0.0f && v != 1.0f) || c[i - 1] == other || c[i + 1] == other || s[i] == other || nb[i] == other || d[i] == other ||
                               u[i] == other;
                        any |= m[i] != 0;
                    }
                }
                if (any) {
                    // Along x into `line`, then OR-ed into the 2 kReach + 1 slab rows it reaches along y.
                    std::fill(line.begin(), line.end(), std::uint8_t(0));
                    for (std::int64_t dx = -kReach; dx <= kReach; ++dx) or_into(line.data(), mixed.data() + kReach + dx, nx);
                    for (std::int64_t dy = -kReach; dy <= kReach; ++dy) or_into(&slab[std::size_t(nx * (j + kReach + dy))], line.data(), nx);
                }
            }
            std::swap(w.previous, w.here);
            std::swap(w.here, w.next);
        }
    }

    void find_band() {
        const auto& dm = domain_.voxmap;
        for (std::size_t a = 0; a < 3; ++a) near_dims_[a] = dm.dims()[a] + 2 * kReach;
        const std::int64_t nx = near_dims_[0], ny = near_dims_[1], nz = near_dims_[2];
        // Streamed over z in chunks of slabs, never as a whole mask: each chunk keeps a ring of the
        // 2 kReach + 1 xy-dilated slabs around its current one, ORs them (the z dilation) and keeps the runs.
        constexpr std::int64_t kChunk = 32;
        const std::int64_t chunks = (nz + kChunk - 1) / kChunk;
        std::vector<std::vector<Run>> chunk_runs(static_cast<std::size_t>(chunks));
        run_offsets_.assign(std::size_t(ny * nz) + 1, 0);
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, chunks, 1), [&](const auto& r) {
            const std::size_t slab_bytes = std::size_t(nx * ny);
            std::vector<std::vector<std::uint8_t>> ring(2 * kReach + 1, std::vector<std::uint8_t>(slab_bytes));
            std::vector<std::uint8_t> line(static_cast<std::size_t>(nx)), band(slab_bytes);
            RowWindow window(dm.dims()[0]);
            for (std::int64_t c = r.begin(); c != r.end(); ++c) {
                const std::int64_t k0 = c * kChunk, k1 = std::min(nz, k0 + kChunk);
                // Near slab k is voxmap slice k - kReach; ring slot (k mod 2R+1) holds near slab k.
                for (std::int64_t k = k0 - kReach; k < k0 + kReach; ++k)
                    mixed_slab(k - kReach, ring[std::size_t((k + 2 * kReach + 1) % (2 * kReach + 1))], line, window);
                auto& runs = chunk_runs[std::size_t(c)];
                for (std::int64_t k = k0; k < k1; ++k) {
                    mixed_slab(k, ring[std::size_t((k + kReach) % (2 * kReach + 1))], line, window); // near slab k + kReach
                    std::fill(band.begin(), band.end(), std::uint8_t(0));
                    for (const auto& slab : ring) or_into(band.data(), slab.data(), std::int64_t(slab_bytes));
                    for (std::int64_t j = 0; j < ny; ++j) {
                        const std::uint8_t* row = &band[std::size_t(j * nx)];
                        std::uint64_t count = 0;
                        for (std::int64_t i = 0; i < nx;) {
                            if (!row[i]) {
                                ++i;
                                continue;
                            }
                            const std::int64_t start = i;
                            while (i < nx && row[i]) ++i;
                            runs.push_back({std::int32_t(start), std::int32_t(i - 1)});
                            ++count;
                        }
                        run_offsets_[std::size_t(j + ny * k) + 1] = count;
                    }
                }
            }
        });
        for (std::size_t q = 1; q < run_offsets_.size(); ++q) run_offsets_[q] += run_offsets_[q - 1];
        runs_.clear();
        runs_.reserve(run_offsets_.back());
        for (const auto& runs : chunk_runs) runs_.insert(runs_.end(), runs.begin(), runs.end());
        active_.assign(region_count(), 0);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, region_count()), [&](const auto& range) {
            for (std::size_t r = range.begin(); r != range.end(); ++r) {
                const int a = int(r % std::size_t(regions_[0])), b = int((r / std::size_t(regions_[0])) % std::size_t(regions_[1])),
                          c = int(r / (std::size_t(regions_[0]) * std::size_t(regions_[1])));
                const int ga = domain_.granularity[0], gb = domain_.granularity[1], gc = domain_.granularity[2];
                bool any = false;
                for (std::int64_t g = std::int64_t(c) * gc; !any && g < std::int64_t(c + 1) * gc; ++g)
                    for (std::int64_t f = std::int64_t(b) * gb; !any && f < std::int64_t(b + 1) * gb; ++f) {
                        const auto [run, end] = band_runs(f, g);
                        any = any_run_within(run, end, std::int64_t(a) * ga, std::int64_t(a + 1) * ga - 1);
                    }
                active_[r] = any;
            }
        });
    }

    using Run = std::array<std::int32_t, 2>; // first and last band voxel of a run, near-grid x

    /// The carried voxels (resolve.h, carry.h) of every region, as sorted indices within the region (the order
    /// for_each_box visits them in). They lie in the band: each has a voxel of the other side within three.
    void find_thin() {
        thin_.assign(region_count(), {});
        const auto& vm = domain_.voxmap;
        if (vm.empty()) return;
        const auto& n = vm.dims();
        const int gx = domain_.granularity[0], gy = domain_.granularity[1], gz = domain_.granularity[2];
        for (const std::uint64_t v : carried_voxels(vm)) {
            const std::int64_t e = std::int64_t(v % std::uint64_t(n[0])) + domain_.offset[0], f = std::int64_t((v / std::uint64_t(n[0])) % std::uint64_t(n[1])) + domain_.offset[1],
                               g = std::int64_t(v / std::uint64_t(n[0] * n[1])) + domain_.offset[2];
            if (e < 0 || f < 0 || g < 0 || e >= domain_.dims[0] || f >= domain_.dims[1] || g >= domain_.dims[2]) continue;
            const int a = int(e / gx), b = int(f / gy), c = int(g / gz);
            thin_[region_index(a, b, c)].push_back(std::uint64_t((e - std::int64_t(a) * gx) + gx * ((f - std::int64_t(b) * gy) + gy * (g - std::int64_t(c) * gz))));
        }
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, thin_.size()), [&](const auto& r) {
            for (std::size_t q = r.begin(); q != r.end(); ++q) std::sort(thin_[q].begin(), thin_[q].end());
        });
    }

    /// The band's runs along domain row (f, g).
    std::pair<const Run*, const Run*> band_runs(std::int64_t f, std::int64_t g) const {
        const std::int64_t j = f - domain_.offset[1] + kReach, k = g - domain_.offset[2] + kReach;
        if (j < 0 || k < 0 || j >= near_dims_[1] || k >= near_dims_[2]) return {nullptr, nullptr};
        const std::size_t q = std::size_t(j + near_dims_[1] * k);
        return {runs_.data() + run_offsets_[q], runs_.data() + run_offsets_[q + 1]};
    }
    /// Whether a run reaches domain x range [lo, hi].
    bool any_run_within(const Run* run, const Run* end, std::int64_t lo, std::int64_t hi) const {
        for (; run != end; ++run)
            if ((*run)[0] + domain_.offset[0] - kReach <= hi && (*run)[1] + domain_.offset[0] - kReach >= lo) return true;
        return false;
    }

    const WarpDomain& domain_;
    Eigen::Vector3d target_origin_;
    double h_;
    std::array<std::vector<BasisEntry>, 3> table_;
    std::array<int, 3> regions_{};
    std::vector<std::uint8_t> active_;
    std::array<std::int64_t, 3> near_dims_{};
    std::vector<std::uint64_t> run_offsets_; // per near-grid row (j + ny k), into runs_
    std::vector<Run> runs_;
    std::vector<std::vector<std::uint64_t>> thin_; // per region
};

} // namespace warp_internal

using namespace warp_internal;

struct Warp::State {
    std::shared_ptr<const WarpDomain> domain_ptr; // owned by a Warp, borrowed by the one-shot warp()
    const WarpDomain& domain;
    explicit State(std::shared_ptr<const WarpDomain> d) : domain_ptr(std::move(d)), domain(*domain_ptr) {}
    Lattice lattice;
    WarpOptions options;
    std::uint64_t memory_limit = 0; // options.max_memory_bytes, or 90% of what was available when the warp began
    std::unique_ptr<Splatter> splatter;
    std::vector<Box> boxes; // per region, what its current splat touches
    BlockAccumulator acc;
    Box target; // the result's bounds, target index space
    SparseVoxmap result;
    WarpDomain* consumed = nullptr; // a one-shot warp's domain, emptied once splatted
    std::vector<RegionCarry> carried; // per region, what its carried voxels carry (resolve.h)
    std::vector<Carry> carry_index;   // all the cells carried, sorted by carry_less
    std::vector<std::pair<Index3, float>> unbridged; // the bridges (resolve.h) put outside, and what the resolve gave them
    /// The accumulator without one control point's regions, where they can reach while that point is dragged: the
    /// other regions' sums over the blocks meeting its regions' boxes grown by kDragMargin voxels, kept on the
    /// point's second move in a row. While the same point moves on within that reach, a move puts these blocks
    /// back and splats its regions once, instead of taking their last splat out first (as much work again). The
    /// sums are fixed-point, so either way gives the same bits.
    struct Drag {
        std::array<int, 3> point{-1, -1, -1}; // the point moved last
        Box reach;                      // target index space; empty: no base kept
        bool refused = false;           // too large to keep: the point's moves go on as first moves
        std::vector<std::size_t> slots; // the blocks in reach that hold sums, in table order
        std::vector<Cell> cells;        // their sums, a block after another
    } drag;
    static constexpr std::int64_t kDragMargin = 12;

    /// Calls visit(slot) for each accumulator block meeting `box` (target index space), in table order.
    template <class Visit>
    void each_slot(const Box& box, const Visit& visit) const {
        std::array<std::int64_t, 3> lo{}, hi{};
        for (std::size_t a = 0; a < 3; ++a) {
            lo[a] = std::clamp<std::int64_t>((box.lo[a] - acc.box.lo[a]) >> 3, 0, acc.blocks[a] - 1);
            hi[a] = std::clamp<std::int64_t>((box.hi[a] - acc.box.lo[a]) >> 3, 0, acc.blocks[a] - 1);
        }
        for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
            for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
                for (std::int64_t x = lo[0]; x <= hi[0]; ++x) visit(acc.slot(x, y, z));
    }
    /// Keeps the accumulator over `reach` as point's drag base (none where that would take more than an eighth of
    /// the memory the warp may use).
    void keep_drag(const std::array<int, 3>& point, const Box& reach) {
        drag = Drag{};
        drag.point = point;
        std::size_t held = 0;
        each_slot(reach, [&](std::size_t slot) { held += acc.at_slot(slot) != nullptr; });
        if (held * std::size_t(BlockAccumulator::kCells) * sizeof(Cell) > memory_limit / 8) {
            drag.refused = true;
            return;
        }
        drag.slots.reserve(held);
        drag.cells.resize(held * std::size_t(BlockAccumulator::kCells));
        each_slot(reach, [&](std::size_t slot) {
            if (const Cell* cells = acc.at_slot(slot)) {
                std::copy_n(cells, BlockAccumulator::kCells, &drag.cells[drag.slots.size() * std::size_t(BlockAccumulator::kCells)]);
                drag.slots.push_back(slot);
            }
        });
        drag.reach = reach;
    }
    /// Puts the drag base back: its blocks as kept, every other block in its reach empty.
    void restore_drag() {
        std::size_t next = 0;
        each_slot(drag.reach, [&](std::size_t slot) {
            Cell* cells = acc.at_slot(slot);
            if (next < drag.slots.size() && drag.slots[next] == slot) std::copy_n(&drag.cells[next++ * std::size_t(BlockAccumulator::kCells)], BlockAccumulator::kCells, cells);
            else if (cells) std::fill_n(cells, BlockAccumulator::kCells, Cell{0, 0});
        });
    }

    void gather_carried() {
        std::vector<CarryImage> images;
        std::vector<Carry> cells;
        for (const auto& region : carried) {
            images.insert(images.end(), region.images.begin(), region.images.end());
            cells.insert(cells.end(), region.cells.begin(), region.cells.end());
        }
        carry_index = link_carries(images, std::move(cells), domain.dims);
    }

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

    /// Conservative boxes of `regions` for the current lattice (region_bound).
    void bound_boxes(const std::vector<std::size_t>& regions) {
        for (auto r : regions) {
            const auto [a, b, c] = unpack(r);
            boxes[r] = splatter->region_bound(lattice, a, b, c);
        }
    }

    /// Splat `regions` with `sign`, in eight parity phases: regions two apart along every axis write disjoint
    /// target voxels unless the map compresses a region to nothing, which is checked against `boxes` (then the
    /// phase runs serially). `boxes` may be conservative; each region's exact box replaces it. With `previous`,
    /// each region's splat through that lattice is first taken out (an incremental move: region by region, so
    /// the cells both touch are still in cache for the second). Returns false, with the accumulator spoilt,
    /// when a splat reached outside the accumulator's box.
    bool splat(const std::vector<std::size_t>& regions, int sign, Progress* progress, const Lattice* previous = nullptr) {
        std::size_t done = 0;
        std::atomic<bool> overflow{false};
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
            std::vector<Box> exact(batch.size());
            auto work = [&](std::size_t q) {
                const auto [a, b, c] = unpack(batch[q]);
                bool out = false;
                if (previous) splatter->splat_region(*previous, a, b, c, options.preview, -sign, acc, out);
                RegionCarry* list = sign > 0 ? &carried[batch[q]] : nullptr;
                if (list) list->images.clear(), list->cells.clear();
                exact[q] = splatter->splat_region(lattice, a, b, c, options.preview, sign, acc, out, list);
                if (out) overflow = true;
            };
            if (disjoint)
                tbb::parallel_for(tbb::blocked_range<std::size_t>(0, batch.size(), 1), [&](const auto& range) {
                    for (std::size_t q = range.begin(); q != range.end(); ++q) work(q);
                });
            else
                for (std::size_t q = 0; q < batch.size(); ++q) work(q);
            for (std::size_t q = 0; q < batch.size(); ++q) boxes[batch[q]] = exact[q];
            done += batch.size();
            if (progress) progress->report(double(done) / double(std::max<std::size_t>(1, regions.size())));
        }
        return !overflow;
    }

    /// Resolve the target rows (whole x rows: an untouched voxel's side is carried along its row) that cross
    /// `box` (target index space) into the result, a row of result blocks at a time (the 8 x 8 rows they hold,
    /// resolved into a buffer, then stored block by block).
    void resolve_rows(const Box& box) {
        constexpr std::int64_t S = SparseVoxmap::kSide;
        const auto& dims = result.dims();
        const std::int64_t nx = dims[0], padded = result.block_dims()[0] * S;
        const std::int64_t bz0 = (std::max(box.lo[2], target.lo[2]) - target.lo[2]) / S, bz1 = (std::min(box.hi[2], target.hi[2]) - target.lo[2]) / S;
        const std::int64_t by0 = (std::max(box.lo[1], target.lo[1]) - target.lo[1]) / S, by1 = (std::min(box.hi[1], target.hi[1]) - target.lo[1]) / S;
        if (bz1 < bz0 || by1 < by0) return;
        const std::int64_t rows_y = by1 - by0 + 1;
        tbb::enumerable_thread_specific<std::vector<float>> buffers([&] { return std::vector<float>(std::size_t(padded * S * S)); });
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, (bz1 - bz0 + 1) * rows_y), [&](const auto& range) {
            std::vector<float>& buffer = buffers.local();
            float block[SparseVoxmap::kBlockVoxels];
            for (std::int64_t q = range.begin(); q != range.end(); ++q) {
                const std::int64_t by = by0 + q % rows_y, bz = bz0 + q / rows_y;
                for (std::int64_t r = 0; r < S * S; ++r) {
                    const std::int64_t y = S * by + r % S, z = S * bz + r / S; // result index
                    float* out = &buffer[std::size_t(r * padded)];
                    std::fill(out + nx, out + padded, 0.0f);
                    if (y >= dims[1] || z >= dims[2]) {
                        std::fill(out, out + nx, 0.0f);
                        continue;
                    }
                    const std::int64_t ay = y + target.lo[1] - acc.box.lo[1], az = z + target.lo[2] - acc.box.lo[2];
                    bool inside = false;
                    for (std::int64_t x = 0; x < nx;) { // one accumulator block at a time
                        const std::int64_t ax = x + target.lo[0] - acc.box.lo[0];
                        const std::int64_t end = std::min(nx - 1, x + (BlockAccumulator::kSide - 1 - (ax & 7)));
                        const Cell* cells = acc.find(ax >> 3, ay >> 3, az >> 3);
                        if (!cells) {
                            std::fill(out + x, out + end + 1, inside ? 1.0f : 0.0f);
                        } else {
                            const Cell* cell = cells + BlockAccumulator::offset(ax, ay, az);
                            for (std::int64_t p = x; p <= end; ++p, ++cell) out[p] = resolve_density(cell->weight, cell->value, inside);
                        }
                        x = end + 1;
                    }
                    // Thin parts the box filter lost, put back (resolve.h).
                    const Carry row_start{{std::numeric_limits<std::int64_t>::min(), y + target.lo[1], z + target.lo[2]}, false};
                    auto c = std::lower_bound(carry_index.begin(), carry_index.end(), row_start, carry_less);
                    while (c != carry_index.end() && c->cell[1] == row_start.cell[1] && c->cell[2] == row_start.cell[2]) {
                        const std::int64_t x = c->cell[0];
                        bool in = false, outside = false;
                        for (; c != carry_index.end() && c->cell[0] == x && c->cell[1] == row_start.cell[1] && c->cell[2] == row_start.cell[2]; ++c)
                            (c->inside ? in : outside) = true;
                        const std::int64_t p = x - target.lo[0];
                        if (p >= 0 && p < nx) out[p] = carried_density(out[p], in, outside);
                    }
                }
                for (std::int64_t bx = 0; bx < result.block_dims()[0]; ++bx) {
                    for (std::int64_t r = 0; r < S * S; ++r) std::copy_n(&buffer[std::size_t(r * padded + S * bx)], S, block + S * r);
                    result.set_block(result.block_index(bx, by, bz), block);
                }
            }
        });
    }

    /// Set one target cell (target index space) of the result; cells outside it are left alone.
    void set_cell(const Index3& cell, float value) {
        constexpr std::int64_t S = SparseVoxmap::kSide;
        const std::int64_t i = cell[0] - target.lo[0], j = cell[1] - target.lo[1], k = cell[2] - target.lo[2];
        const auto& d = result.dims();
        if (i < 0 || j < 0 || k < 0 || i >= d[0] || j >= d[1] || k >= d[2]) return;
        const std::int64_t b = result.block_index(i / S, j / S, k / S);
        float block[SparseVoxmap::kBlockVoxels];
        if (const float* stored = result.block_values(b)) std::copy_n(stored, SparseVoxmap::kBlockVoxels, block);
        else std::fill_n(block, SparseVoxmap::kBlockVoxels, result.block_uniform(b));
        block[(i % S) + S * ((j % S) + S * (k % S))] = value;
        result.set_block(b, block);
    }
    float cell_value(const Index3& cell) const { return result.at(cell[0] - target.lo[0], cell[1] - target.lo[1], cell[2] - target.lo[2]); }

    /// Put back what the last unbridge took, before the rows are resolved again (an incremental update judges
    /// every bridge again: resolve.h).
    void restore_bridges() {
        for (const auto& [cell, prior] : unbridged) set_cell(cell, prior);
        unbridged.clear();
    }
    /// Put the bridges (resolve.h) of the resolved result outside.
    void unbridge() {
        const auto found = bridges(
            carry_index, [&](std::int64_t x, std::int64_t y, std::int64_t z) { return cell_value({x, y, z}) >= 0.5f; },
            [&](const Index3& cell) { return source_inside(domain, lattice, cell); });
        for (const auto& cell : found) {
            unbridged.push_back({cell, cell_value(cell)});
            set_cell(cell, kCarriedOutside);
        }
    }

    void full(Progress* progress) {
        const auto regions = active_regions();
        // The accumulator spans the regions' conservative bounds (its block table is all it costs), the target
        // the splats' exact reach, known after the splat, with a margin of two voxels that lets small
        // incremental moves stay inside without regrowing.
        bound_boxes(regions);
        Box bound;
        for (auto r : regions) bound.include(boxes[r]);
        if (bound.empty()) bound.lo = bound.hi = Index3{0, 0, 0}; // no density at all
        for (std::size_t i = 0; i < 3; ++i) bound.lo[i] -= 2, bound.hi[i] += 2;
        // What grows with the target's extent rather than its surface: the accumulator's and the result's block
        // tables (a map that stretches space far could ask for more than there is).
        std::uint64_t blocks = 1;
        for (std::size_t i = 0; i < 3; ++i) blocks *= std::uint64_t((bound.hi[i] - bound.lo[i]) / BlockAccumulator::kSide + 1);
        require_memory(blocks * (sizeof(std::atomic<Cell*>) + sizeof(float) + sizeof(void*)), options.max_memory_bytes,
                       "warp target of " + std::to_string(bound.hi[0] - bound.lo[0] + 1) + "x" + std::to_string(bound.hi[1] - bound.lo[1] + 1) + "x" +
                           std::to_string(bound.hi[2] - bound.lo[2] + 1) + " voxels");
        acc.reset(bound, memory_limit);
        drag = Drag{};
        carried.assign(splatter->region_count(), {});
        if (!splat(regions, +1, progress)) throw SolverFailure("warp: a splat reached outside the bounds computed for it (internal error)");
        if (consumed) consumed->voxmap = SparseVoxmap(); // the splat was its last use: free it before the result grows
        target = Box();
        for (auto r : regions) target.include(boxes[r]);
        if (target.empty()) target.lo = target.hi = Index3{0, 0, 0}; // a one-voxel empty target at the domain's origin
        for (std::size_t i = 0; i < 3; ++i) target.lo[i] -= 2, target.hi[i] += 2;
        Index3 dims;
        for (std::size_t i = 0; i < 3; ++i) dims[i] = target.hi[i] - target.lo[i] + 1;
        result = SparseVoxmap(dims, domain.target_origin + domain.target_voxel_size * Eigen::Vector3d(double(target.lo[0]), double(target.lo[1]), double(target.lo[2])),
                              domain.target_voxel_size);
        unbridged.clear();
        gather_carried();
        resolve_rows(target);
        unbridge();
    }
};

Warp::Warp(WarpDomain domain, const Lattice& lattice, const WarpOptions& options)
    : Warp(std::make_shared<const WarpDomain>(std::move(domain)), lattice, options, nullptr) {}

Warp::Warp(std::shared_ptr<const WarpDomain> domain, const Lattice& lattice, const WarpOptions& options, WarpDomain* consumed)
    : state_(std::make_unique<State>(std::move(domain))) {
    auto& s = *state_;
    s.consumed = consumed;
    if (lattice.size() != s.domain.lattice.size()) throw InvalidInput("warp: the lattice's size differs from the domain's");
    s.lattice = lattice;
    s.options = options;
    s.memory_limit = memory_limit(options.max_memory_bytes);
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
const SparseVoxmap& Warp::target() const { return state_->result; }

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
    // No separate pass to bound the new splats: a point moved by d shifts its regions' images by at most
    // (2/3)^3 d (the basis' largest tensor value) and their Jacobians by less, so the old boxes grown by d + 2
    // voxels bound the old and the new splats for the parity phases' disjointness check; the splat records
    // the exact new boxes.
    const double reach = (position - s.lattice.point(i, j, k)).norm() / s.domain.target_voxel_size + 2;
    const std::int64_t grow = reach < 1e9 ? std::int64_t(std::ceil(reach)) : std::int64_t(1e9);
    auto grow_boxes = [&] {
        Box bound;
        for (auto idx : affected) {
            for (std::size_t a = 0; a < 3; ++a) s.boxes[idx].lo[a] -= grow, s.boxes[idx].hi[a] += grow;
            bound.include(s.boxes[idx]);
        }
        return bound;
    };
    const std::array<int, 3> point{i, j, k};
    const Box bound = grow_boxes();
    const Lattice before = s.lattice;
    const Lattice* take_out = nullptr; // the lattice whose splat each region takes out first, if any
    if (s.drag.point == point && !s.drag.reach.empty() && s.drag.reach.contains(bound)) {
        s.restore_drag(); // the other regions' sums, as when the drag began
    } else if (s.drag.point == point && !s.drag.refused) {
        // The point's second move in a row: a drag. Take its regions' splat out, keep what is left as the drag's
        // base, then splat them where they go.
        s.splat(affected, -1, nullptr);
        Box kept;
        for (auto idx : affected) kept.include(s.boxes[idx]);
        for (std::size_t a = 0; a < 3; ++a) kept.lo[a] -= State::kDragMargin, kept.hi[a] += State::kDragMargin;
        if (!kept.empty()) s.keep_drag(point, kept);
        grow_boxes();
    } else {
        // A first move: each region's splat out and in again in one pass, its cells still in cache for the second.
        if (s.drag.point != point) s.drag = State::Drag{};
        s.drag.point = point;
        take_out = &before;
    }
    s.lattice.set_point(i, j, k, position);
    Box after;
    const bool inside_accumulator = s.splat(affected, +1, nullptr, take_out);
    for (auto idx : affected) after.include(s.boxes[idx]);
    if (!inside_accumulator || !s.target.contains(after)) { // the moved regions reach outside the target: grow it
        s.full(nullptr);
        return;
    }
    touched.include(after);
    // The rows the moved regions' carried cells left or reached lie in the old and new boxes: resolved again.
    s.restore_bridges();
    s.gather_carried();
    if (!touched.empty()) s.resolve_rows(touched);
    s.unbridge();
}

SparseVoxmap warp(const WarpDomain& domain, const Lattice& lattice, const WarpOptions& options) {
    // Borrow the domain (no copy of its voxmap) for the lifetime of this call.
    Warp w(std::shared_ptr<const WarpDomain>(&domain, [](const WarpDomain*) {}), lattice, options, nullptr);
    return std::move(w.state_->result);
}

SparseVoxmap warp(WarpDomain&& domain, const Lattice& lattice, const WarpOptions& options) {
    Warp w(std::shared_ptr<const WarpDomain>(&domain, [](const WarpDomain*) {}), lattice, options, &domain);
    domain.voxmap = SparseVoxmap();
    return std::move(w.state_->result);
}

} // namespace voxwarp
