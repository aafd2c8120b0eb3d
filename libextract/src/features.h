/// @file features.h
/// @brief Internal: sharp edges and corners put back on marching cubes' output (features.cpp).
#pragma once

#include <voxwarp/extract.h>

#include "marching_cubes.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <tbb/parallel_for.h>
#include <utility>
#include <vector>

namespace voxwarp::extract_internal {

using Index3 = std::array<std::int64_t, 3>;

/// A cell's key: 21 bits per axis, offset so that the border's cells (index -1) fit.
inline std::uint64_t cell_key(const Index3& c) {
    return std::uint64_t(c[0] + 2) | std::uint64_t(c[1] + 2) << 21 | std::uint64_t(c[2] + 2) << 42;
}

/// The cell a key names (cell_key's inverse).
inline Index3 key_cell(std::uint64_t key) {
    return {std::int64_t(key & 0x1fffff) - 2, std::int64_t(key >> 21 & 0x1fffff) - 2, std::int64_t(key >> 42) - 2};
}

/// The cell (voxel index of its low corner) holding a point given in index space.
inline Index3 cell_containing(const Eigen::Vector3d& q) {
    return {std::int64_t(std::floor(q.x())), std::int64_t(std::floor(q.y())), std::int64_t(std::floor(q.z()))};
}

/// The indices in the ascending, disjoint runs [first, second) for which `keep` holds, ascending: runs in parallel,
/// then joined (the result does not depend on the thread count).
template <class Keep>
std::vector<std::uint32_t> select_in_runs(const std::vector<std::pair<std::uint32_t, std::uint32_t>>& runs, const Keep& keep) {
    std::vector<std::vector<std::uint32_t>> parts(runs.size());
    tbb::parallel_for(std::size_t(0), runs.size(), [&](std::size_t r) {
        for (std::uint32_t i = runs[r].first; i < runs[r].second; ++i)
            if (keep(std::size_t(i))) parts[r].push_back(i);
    });
    std::size_t total = 0;
    for (const auto& p : parts) total += p.size();
    std::vector<std::uint32_t> out;
    out.reserve(total);
    for (const auto& p : parts) out.insert(out.end(), p.begin(), p.end());
    return out;
}

/// The indices in [0, n) for which `keep` holds, ascending: fixed blocks in parallel (the result does not depend on
/// the thread count), then joined. For the passes that look for the few triangles or vertices near a feature.
template <class Keep>
std::vector<std::uint32_t> select_in_parallel(std::size_t n, const Keep& keep) {
    constexpr std::size_t kBlock = std::size_t(1) << 14;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> runs;
    for (std::size_t i = 0; i < n; i += kBlock) runs.push_back({std::uint32_t(i), std::uint32_t(std::min(n, i + kBlock))});
    return select_in_runs(runs, keep);
}

/// The cycle the sides `next` (a -> b, sorted by a, no a twice, at least one) chain into from the first a, or an
/// empty list where they do not close one cycle through all of them: a fan's loop, the loop around a vertex.
inline std::vector<std::int32_t> closed_cycle(const std::vector<std::pair<std::int32_t, std::int32_t>>& next) {
    std::vector<std::int32_t> cycle{next.front().first};
    while (cycle.size() <= next.size()) {
        const auto it = std::lower_bound(next.begin(), next.end(), std::pair(cycle.back(), std::numeric_limits<std::int32_t>::min()));
        if (it == next.end() || it->first != cycle.back()) return {};
        if (it->second == cycle.front()) break;
        cycle.push_back(it->second);
    }
    if (cycle.size() != next.size()) return {};
    return cycle;
}

/// The grid of 8^3-cell blocks over a voxmap and 8 cells around it: CoarseMarks and CellBuckets index by it.
class BlockGrid {
public:
    static constexpr std::int64_t kSide = 8, kCells = kSide * kSide * kSide;
    explicit BlockGrid(const SparseVoxmap& v) {
        for (std::size_t a = 0; a < 3; ++a) dims_[a] = (v.dims()[a] + 2 * kMargin) / kSide + 1;
    }
    std::size_t block_count() const { return std::size_t(dims_[0] * dims_[1] * dims_[2]); }
    /// Calls `f` with the index of each block holding a cell in [lo, hi] (within the grid), in order, until it
    /// returns true; whether it did.
    template <class F>
    bool visit_blocks(const Index3& lo, const Index3& hi, const F& f) const {
        Index3 a, b;
        for (std::size_t k = 0; k < 3; ++k) {
            a[k] = std::max<std::int64_t>(0, block(lo[k])), b[k] = std::min(dims_[k] - 1, block(hi[k]));
            if (a[k] > b[k]) return false;
        }
        for (std::int64_t z = a[2]; z <= b[2]; ++z)
            for (std::int64_t y = a[1]; y <= b[1]; ++y)
                for (std::int64_t x = a[0]; x <= b[0]; ++x)
                    if (f(block_index(x, y, z))) return true;
        return false;
    }
    std::size_t block_index(std::int64_t x, std::int64_t y, std::int64_t z) const { return std::size_t(x + dims_[0] * (y + dims_[1] * z)); }
    /// The block of a cell, or -1 when the cell lies outside the grid.
    std::int64_t block_of(const Index3& c) const {
        Index3 b;
        for (std::size_t k = 0; k < 3; ++k) {
            b[k] = block(c[k]);
            if (b[k] < 0 || b[k] >= dims_[k]) return -1;
        }
        return std::int64_t(block_index(b[0], b[1], b[2]));
    }
    /// A cell's place in its block.
    static std::size_t local(const Index3& c) {
        return std::size_t(((c[0] + kMargin) & (kSide - 1)) + kSide * (((c[1] + kMargin) & (kSide - 1)) + kSide * ((c[2] + kMargin) & (kSide - 1))));
    }

private:
    static constexpr std::int64_t kMargin = 8;
    static std::int64_t block(std::int64_t cell) { return cell + kMargin >= 0 ? (cell + kMargin) / kSide : -1; }
    Index3 dims_{};
};

/// Which 8^3 blocks of cells hold a marked cell, a byte per block, so that a cell or box with nothing marked in it
/// is known without looking further (a pass over every vertex or triangle spent most of its time asking about
/// empty cells).
class CoarseMarks {
public:
    explicit CoarseMarks(const SparseVoxmap& v) : grid_(v), marks_(grid_.block_count(), 0) {}
    /// Mark the cells in [lo, hi] (inclusive; those beyond the grid are never asked about).
    void mark(const Index3& lo, const Index3& hi) {
        grid_.visit_blocks(lo, hi, [&](std::size_t b) {
            marks_[b] = 1;
            return false;
        });
    }
    /// False when no cell in [lo, hi] is marked (true may still mean none: blocks are coarse).
    bool any(const Index3& lo, const Index3& hi) const {
        return grid_.visit_blocks(lo, hi, [&](std::size_t b) { return marks_[b] != 0; });
    }

private:
    BlockGrid grid_;
    std::vector<std::uint8_t> marks_;
};

/// Ids filed by the cells their boxes cover (index space): the feature surface's triangles, the sharp edges. add()
/// all, then build(); a cell's ids, in the order added, are then two array reads away. Block-sparse arrays, where
/// a hash map of vectors took a fifth of the feature mesher's time to fill.
class CellBuckets {
public:
    explicit CellBuckets(const SparseVoxmap& v) : grid_(v) {}
    void reserve(std::size_t n) { items_.reserve(n); }
    void add(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, std::uint32_t id) { items_.push_back({narrow(cell_containing(lo)), narrow(cell_containing(hi)), id}); }
    void build() {
        std::vector<std::int32_t> slot(grid_.block_count(), -1);
        std::int32_t slots = 0;
        auto for_cells = [&](const Item& item, auto&& f) {
            for (std::int64_t z = item.lo[2]; z <= std::int64_t(item.hi[2]); ++z)
                for (std::int64_t y = item.lo[1]; y <= std::int64_t(item.hi[1]); ++y)
                    for (std::int64_t x = item.lo[0]; x <= std::int64_t(item.hi[0]); ++x) {
                        const Index3 c{x, y, z};
                        const std::int64_t b = grid_.block_of(c);
                        if (b >= 0) f(std::size_t(b), grid_.local(c));
                    }
        };
        for (const Item& item : items_)
            for_cells(item, [&](std::size_t b, std::size_t) {
                if (slot[b] < 0) slot[b] = slots++;
            });
        offsets_.assign(std::size_t(slots) * BlockGrid::kCells + 1, 0);
        for (const Item& item : items_) for_cells(item, [&](std::size_t b, std::size_t l) { ++offsets_[std::size_t(slot[b]) * BlockGrid::kCells + l + 1]; });
        for (std::size_t i = 1; i < offsets_.size(); ++i) offsets_[i] += offsets_[i - 1];
        ids_.resize(offsets_.back());
        // Each cell's place in ids_ advanced past its ids as they go in, then shifted back a cell: no second
        // array as large as the offsets (fresh pages, which cost more than the filing).
        for (const Item& item : items_) for_cells(item, [&](std::size_t b, std::size_t l) { ids_[offsets_[std::size_t(slot[b]) * BlockGrid::kCells + l]++] = item.id; });
        for (std::size_t i = offsets_.size() - 1; i > 0; --i) offsets_[i] = offsets_[i - 1];
        offsets_[0] = 0;
        slot_ = std::move(slot);
        items_ = {};
    }
    /// The ids in cell `c`, in the order added (none before build()).
    std::span<const std::uint32_t> at(const Index3& c) const {
        const std::int64_t b = grid_.block_of(c);
        if (b < 0 || slot_.empty() || slot_[std::size_t(b)] < 0) return {};
        const std::size_t i = std::size_t(slot_[std::size_t(b)]) * BlockGrid::kCells + BlockGrid::local(c);
        return {ids_.data() + offsets_[i], ids_.data() + offsets_[i + 1]};
    }
    /// False when no cell in [lo, hi] holds an id (true may still mean none: blocks are coarse).
    bool any(const Index3& lo, const Index3& hi) const {
        return !slot_.empty() && grid_.visit_blocks(lo, hi, [&](std::size_t b) { return slot_[b] >= 0; });
    }

private:
    /// Cells in 32 bits: a surface the size of the bunny's at 256 files 59,000 triangles, and the list's fresh
    /// pages cost more than filing them. A cell farther off than 2^30 stays beyond the grid.
    using Cell32 = std::array<std::int32_t, 3>;
    static Cell32 narrow(const Index3& c) {
        constexpr std::int64_t kFar = std::int64_t(1) << 30;
        return {std::int32_t(std::clamp(c[0], -kFar, kFar)), std::int32_t(std::clamp(c[1], -kFar, kFar)), std::int32_t(std::clamp(c[2], -kFar, kFar))};
    }
    struct Item {
        Cell32 lo, hi;
        std::uint32_t id;
    };
    BlockGrid grid_;
    std::vector<Item> items_;
    std::vector<std::int32_t> slot_;       ///< per block: its place in offsets_, or -1 when no cell of it holds an id
    std::vector<std::uint32_t> offsets_;   ///< per cell of each filled block: where its ids begin in ids_
    std::vector<std::uint32_t> ids_;
};

/// Whether triangle t of `v` faces against `reference`, the sum of its corners' known normals (zero: none known):
/// folded over in the plane of a face. unfold() flips such triangles, and restore_features() builds around them.
inline bool faces_against(const std::vector<Eigen::Vector3d>& v, const std::array<std::int32_t, 3>& t, const Eigen::Vector3d& reference) {
    const Eigen::Vector3d& a = v[std::size_t(t[0])];
    return !reference.isZero() && !((v[std::size_t(t[1])] - a).cross(v[std::size_t(t[2])] - a).dot(reference) > 0);
}

/// Whether `p` lies on an edge of the voxmap's grid (or a node), to round-off: every vertex of marching cubes does.
bool on_grid_edge(const SparseVoxmap& voxmap, const Eigen::Vector3d& p);

/// `mesh`, marching cubes' output for `voxmap` (every vertex on a grid edge, every triangle in one cell), with
/// the cells that hold a sharp part re-meshed as fans around their feature points and those points joined.
/// `blocks`: where marching cubes put each block's vertices and triangles (marching_cubes' own list for `mesh`);
/// the passes over all of them visit only the blocks near the feature surface (all of them without one), and the
/// output is the same.
TriangleMesh restore_features(TriangleMesh mesh, const SparseVoxmap& voxmap, const ExtractOptions& options, const std::vector<MarchingBlock>& blocks);

/// The feature mesher's last step (feature_edges.cpp): each mesh edge that passes under one of the input's sharp
/// `edges` (world units), its ends on either side, is split at the sharp edge's point nearest it; edges whose ends'
/// `normals` (one per vertex of marching cubes' output, zero where unknown) agree within `cos_feature` lie on one
/// face and are left. No split is made within a hundredth of a voxel of another, of a vertex past `normals` (the
/// fans' centres) or of the edge's triangles' third corners. The mesh stays a closed 2-manifold. Each split is
/// appended to `splits` as (the new vertex, the edge's ends).
void split_across_sharp_edges(std::vector<Eigen::Vector3d>& vertices, std::vector<std::array<std::int32_t, 3>>& triangles, const std::vector<Eigen::Vector3d>& normals,
                              double cos_feature, const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& edges, const SparseVoxmap& voxmap,
                              std::vector<std::array<std::int32_t, 3>>& splits);

/// After the splits: a triangle that faces against its corners' `normals` (folded in the plane of a face) has the
/// edge it shares with a neighbour flipped, where the two new triangles face the right way; where no flip does,
/// a corner whose triangles all lie in one plane moves to the middle of its loop, where they then all face the
/// plane's way, and a corner between two neighbours on one line (a sharp edge) slides along it until its triangles
/// unfold. The mesh stays a closed 2-manifold, its surface the same. Returns the triangles it rewrote (those
/// around a moved vertex included).
std::vector<std::uint32_t> unfold(std::vector<Eigen::Vector3d>& vertices, std::vector<std::array<std::int32_t, 3>>& triangles,
                                  const std::vector<Eigen::Vector3d>& normals);

/// Puts back the corners of triangles that cross another (uncross.cpp), repeating while that changes something:
/// a vertex of marching cubes to `marching` (their positions, the first of `vertices`), a split (split_across_sharp_
/// edges' `splits`) to the middle of the edge it split, which undoes it, a fan's centre to the middle of its loop.
/// Crossing means each triangle passes through the other's plane by more than 1e-4 of the voxmap's voxel size:
/// sheets that only touch, or cross by less (round-off at a model's corners, where fans meet), do not count.
/// Relies on the triangles of marching cubes being in its order, each rewritten one (by unfold()) listed in
/// `unfolded`, and every other triangle having a vertex the mesher added (a fan's centre, a split). Returns the
/// triangles that still cross with every corner back, ascending.
std::vector<std::uint32_t> uncross(std::vector<Eigen::Vector3d>& vertices, const std::vector<std::array<std::int32_t, 3>>& triangles,
                                   const std::vector<Eigen::Vector3d>& marching, const std::vector<std::array<std::int32_t, 3>>& splits,
                                   const std::vector<std::uint32_t>& unfolded, const SparseVoxmap& voxmap);

} // namespace voxwarp::extract_internal
