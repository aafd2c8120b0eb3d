#include "carry.h"
#include "resolve.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <array>

namespace voxwarp::warp_internal {

namespace {

constexpr std::int64_t S = SparseVoxmap::kSide;
// A block's window: the block and 3 voxels around it (a thin test reaches 2 voxels, its neighbours' one more),
// one 16-bit row per (y, z), bit x + 3 for block-relative x in [-3, 11).
constexpr int kHalo = 3, kWindow = int(S) + 2 * kHalo;
using Rows = std::array<std::array<std::uint16_t, kWindow>, kWindow>; // [z][y]
constexpr std::uint16_t kAll = (1u << kWindow) - 1;
static_assert(kThickBlock == 3, "the masks below test 3 x 3 x 3 blocks");

/// Per block: 0 uniform outside, 1 uniform inside, 2 stored; and for stored blocks the inside bit of each voxel,
/// one byte per (y, z) row.
struct Sides {
    const SparseVoxmap& vm;
    std::vector<std::uint8_t> kind;
    std::vector<std::array<std::uint8_t, S * S>> bits; // per block (empty rows for uniform blocks)
    std::vector<std::int64_t> slot;                    // per block: its index into bits, or -1

    explicit Sides(const SparseVoxmap& v) : vm(v), kind(std::size_t(v.block_count())), slot(std::size_t(v.block_count()), -1) {
        std::int64_t stored = 0;
        for (std::int64_t b = 0; b < v.block_count(); ++b) {
            kind[std::size_t(b)] = v.block_values(b) ? 2 : v.block_uniform(b) >= 0.5f ? 1 : 0;
            if (kind[std::size_t(b)] == 2) slot[std::size_t(b)] = stored++;
        }
        bits.resize(std::size_t(stored));
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, v.block_count()), [&](const auto& r) {
            for (std::int64_t b = r.begin(); b != r.end(); ++b) {
                if (slot[std::size_t(b)] < 0) continue;
                const float* values = v.block_values(b);
                auto& rows = bits[std::size_t(slot[std::size_t(b)])];
                for (std::int64_t row = 0; row < S * S; ++row) {
                    std::uint8_t byte = 0;
                    for (std::int64_t x = 0; x < S; ++x) byte |= std::uint8_t((values[row * S + x] >= 0.5f) << x);
                    rows[std::size_t(row)] = byte;
                }
            }
        });
    }

    /// Inside bits of voxmap row (j, k), voxels 8 bx .. 8 bx + 7 (0 outside the voxmap).
    std::uint8_t row(std::int64_t bx, std::int64_t j, std::int64_t k) const {
        const auto& d = vm.dims();
        if (bx < 0 || j < 0 || k < 0 || bx >= vm.block_dims()[0] || j >= d[1] || k >= d[2]) return 0;
        const std::int64_t b = vm.block_index(bx, j / S, k / S);
        if (kind[std::size_t(b)] == 2) return bits[std::size_t(slot[std::size_t(b)])][std::size_t((j % S) + S * (k % S))];
        if (kind[std::size_t(b)] == 0) return 0;
        const std::int64_t valid = d[0] - S * bx; // a border block's voxels past dims read 0
        return valid >= S ? std::uint8_t(0xFF) : std::uint8_t((1u << valid) - 1);
    }
};

/// Thin voxels of one side (`on`: that side's bits) at window rows [2, 12): not in any full 3 x 3 x 3 block.
void thin_bits(const Rows& on, Rows& thin) {
    Rows a{}, b{};
    // Full 3 x 3 x 3 blocks by their centres: along x, then y, then z (valid in [1, 13) each).
    for (int z = 0; z < kWindow; ++z)
        for (int y = 0; y < kWindow; ++y) a[z][y] = std::uint16_t(on[z][y] & (on[z][y] << 1) & (on[z][y] >> 1));
    for (int z = 0; z < kWindow; ++z)
        for (int y = 1; y + 1 < kWindow; ++y) b[z][y] = std::uint16_t(a[z][y - 1] & a[z][y] & a[z][y + 1]);
    for (int z = 1; z + 1 < kWindow; ++z)
        for (int y = 1; y + 1 < kWindow; ++y) a[z][y] = std::uint16_t(b[z - 1][y] & b[z][y] & b[z + 1][y]);
    // Voxels some full block covers: the centres grown by one along each axis (valid in [2, 12)).
    for (int z = 1; z + 1 < kWindow; ++z)
        for (int y = 1; y + 1 < kWindow; ++y) b[z][y] = std::uint16_t((a[z][y] | (a[z][y] << 1) | (a[z][y] >> 1)) & kAll);
    for (int z = 1; z + 1 < kWindow; ++z)
        for (int y = 2; y + 2 < kWindow; ++y) a[z][y] = std::uint16_t(b[z][y - 1] | b[z][y] | b[z][y + 1]);
    for (int z = 2; z + 2 < kWindow; ++z)
        for (int y = 2; y + 2 < kWindow; ++y) thin[z][y] = std::uint16_t(on[z][y] & ~(a[z - 1][y] | a[z][y] | a[z + 1][y]) & kAll);
}

} // namespace

std::vector<std::uint64_t> carried_voxels(const SparseVoxmap& voxmap) {
    const Sides sides(voxmap);
    const auto& bd = voxmap.block_dims();
    const auto& d = voxmap.dims();
    tbb::enumerable_thread_specific<std::vector<std::uint64_t>> found;
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, voxmap.block_count()), [&](const auto& range) {
        auto& out = found.local();
        for (std::int64_t blk = range.begin(); blk != range.end(); ++blk) {
            const std::int64_t bx = blk % bd[0], by = (blk / bd[0]) % bd[1], bz = blk / (bd[0] * bd[1]);
            // A uniform block whose 26 neighbours are uniform on its side has no other side within 8 voxels.
            const std::uint8_t own = sides.kind[std::size_t(blk)];
            bool quiet = own != 2;
            for (int dz = -1; dz <= 1 && quiet; ++dz)
                for (int dy = -1; dy <= 1 && quiet; ++dy)
                    for (int dx = -1; dx <= 1 && quiet; ++dx) {
                        const std::int64_t x = bx + dx, y = by + dy, z = bz + dz;
                        const bool in_map = x >= 0 && y >= 0 && z >= 0 && x < bd[0] && y < bd[1] && z < bd[2];
                        quiet = (in_map ? sides.kind[std::size_t(voxmap.block_index(x, y, z))] : 0) == own;
                    }
            if (quiet && (own == 0 || (S * (bx + 2) <= d[0] && S * (by + 2) <= d[1] && S * (bz + 2) <= d[2]))) continue;
            Rows inside{}, outside{};
            for (int z = 0; z < kWindow; ++z)
                for (int y = 0; y < kWindow; ++y) {
                    const std::int64_t j = S * by + y - kHalo, k = S * bz + z - kHalo;
                    const std::uint32_t three = std::uint32_t(sides.row(bx - 1, j, k)) | std::uint32_t(sides.row(bx, j, k)) << 8 |
                                                std::uint32_t(sides.row(bx + 1, j, k)) << 16;
                    inside[z][y] = std::uint16_t((three >> (S - kHalo)) & kAll);
                    outside[z][y] = std::uint16_t(~inside[z][y] & kAll);
                }
            Rows thin_in{}, thin_out{};
            thin_bits(inside, thin_in);
            thin_bits(outside, thin_out);
            for (int z = kHalo; z < kHalo + int(S); ++z)
                for (int y = kHalo; y < kHalo + int(S); ++y) {
                    auto grown = [&](const Rows& t) {
                        return std::uint16_t(t[z][y] | (t[z][y] << 1) | (t[z][y] >> 1) | t[z][y - 1] | t[z][y + 1] | t[z - 1][y] | t[z + 1][y]);
                    };
                    const std::uint16_t carried = std::uint16_t(((grown(thin_in) & inside[z][y]) | (grown(thin_out) & outside[z][y])) >> kHalo) & 0xFF;
                    if (!carried) continue;
                    const std::int64_t j = S * by + y - kHalo, k = S * bz + z - kHalo;
                    if (j >= d[1] || k >= d[2]) continue;
                    for (int x = 0; x < int(S); ++x) {
                        const std::int64_t i = S * bx + x;
                        if ((carried >> x & 1) && i < d[0]) out.push_back(std::uint64_t(i + d[0] * (j + d[1] * k)));
                    }
                }
        }
    });
    std::vector<std::uint64_t> all;
    for (auto& list : found) all.insert(all.end(), list.begin(), list.end());
    tbb::parallel_sort(all.begin(), all.end());
    return all;
}

} // namespace voxwarp::warp_internal
