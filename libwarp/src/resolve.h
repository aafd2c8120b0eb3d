// The last step of the splat (paper section 6), shared by the fast path and the naive reference: turn a target
// voxel's accumulated weight and weighted value into a density, and put back the thin parts the box filter lost.
//
// The paper: density = wv if weight < 1, else wv / weight. Its "wv if weight < 1" treats the part of a voxel that
// no splat covered as empty, which is right at the edge of the warped data and wrong inside it: there the
// box-filter approximation leaves small coverage gaps (a few percent under rotation) that the paper's rule
// turns into dips of density inside the solid. So the uncovered part takes the covered part's mean: density =
// wv / weight for any weight. At the edge of the warped data that is still 0 (the domain's border is empty), and
// a voxmap whose inside is not full (a fog volume, CT data, a wall too thin for the ramp to reach 1) keeps its
// values. A voxel no splat touched takes the side (1 or 0) of the last touched voxel before it along its x row
// (inside: wv >= weight / 2; rows start outside: the target covers the warped domain and a margin). That rule is
// what lets the fast path splat only the narrow band around the surface: deep inside and far outside, the
// skipped voxels are pure (density exactly 1 or 0), so they would only confirm the side.
//
// Thin parts. The box filter averages: a wall one voxel thick, whose single layer of inside voxels holds
// densities just above 0.5 (a scan's shell, a wall voxelize kept closed), comes out below 0.5 wherever the map
// shifts it by a fraction of a voxel, and the surface opens in holes (the snowden bust came apart in 24 pieces
// for a 3-voxel move); a gap one voxel wide closes the same way. So a voxel on a *thin* side (in no 3 x 3 x 3
// block of voxels on its side), and its face neighbours on that side, are also *carried*: the target cells it
// holds are put back on its side, just across 0.5 (kCarriedInside, kCarriedOutside), wherever the box filter
// left them on the other. The cells it holds are those whose centres lie in the bounding box of its image,
// with every image edge shorter than a voxel first stretched to a voxel:
// - extract joins inside voxels across faces only and keeps outside ones apart only across faces and edges, so
//   a wall stays closed only as a layer as thick as a standard digital plane (|n|_1 voxels along its normal n,
//   up to 1.7 for a turned wall): a cube's image box swept along a sheet gives exactly that, the image itself
//   (or the cell nearest each centre) leaves 18-connected pinholes (Euler characteristic -62 against -4 on the
//   snowden edit);
// - a squeezed image edge stretched back to a voxel keeps the layer that thick however hard an edit presses it.
// Between face neighbours whose nearest cells are diagonal neighbours a path of face neighbours is carried too.
// Under a translation that is the shifted layer, cell for cell; under a turn, a stretch or a squeeze, a layer
// stays joined and closed. A thick part (every voxel in a full 3 x 3 x 3 block of its side) is never carried,
// so a smooth solid comes out of the box filter as before.
#pragma once

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <tuple>
#include <vector>

namespace voxwarp {
struct WarpDomain;
class Lattice;
} // namespace voxwarp

namespace voxwarp::warp_internal {

/// Whether target cell `cell` (target index space) pulls back through `lattice` into an inside voxel of the
/// domain (density >= 0.5 at the nearest domain voxel of its preimage). Where the inverse is not found, inside.
bool source_inside(const WarpDomain& domain, const Lattice& lattice, const std::array<std::int64_t, 3>& cell);

/// Density of a target voxel with weight `w` and weighted value `v` (any units): the covered part's mean.
/// `inside` carries the side along a row: read for an untouched voxel, updated by a touched one.
template <class T>
inline float resolve_density(T w, T v, bool& inside) {
    if (w <= 0) return inside ? 1.0f : 0.0f;
    inside = 2.0 * double(v) >= double(w);
    return float(std::clamp(double(v) / double(w), 0.0, 1.0));
}

/// A part is thick where a K x K x K block of voxels on its side holds the voxel.
constexpr int kThickBlock = 3;

/// What a carried target cell becomes when the box filter left it on the other side: just inside (or just
/// outside), so the surface passes close to its centre, as it passed close to the thin voxel's. One value for
/// every carrier, so the result does not depend on their order (the full warp and an incremental update agree
/// bit for bit).
constexpr float kCarriedInside = 0.5f + 1.0f / 64.0f, kCarriedOutside = 0.5f - 1.0f / 64.0f;

/// Whether domain voxel (e, f, g) is thin on side `inside` (density >= 0.5, or < 0.5 for the outside): on that
/// side, and in no K x K x K block of voxels on that side. `density(e, f, g)` reads the domain (0 outside it).
template <class Density>
inline bool is_thin(const Density& density, std::int64_t e, std::int64_t f, std::int64_t g, bool inside) {
    constexpr int K = kThickBlock, W = 2 * K - 1;
    if ((density(e, f, g) >= 0.5f) != inside) return false;
    bool on[W][W][W];
    for (int z = 0; z < W; ++z)
        for (int y = 0; y < W; ++y)
            for (int x = 0; x < W; ++x) on[z][y][x] = (density(e + x - (K - 1), f + y - (K - 1), g + z - (K - 1)) >= 0.5f) == inside;
    for (int z = 0; z < K; ++z)
        for (int y = 0; y < K; ++y)
            for (int x = 0; x < K; ++x) {
                bool full = true;
                for (int dz = 0; dz < K && full; ++dz)
                    for (int dy = 0; dy < K && full; ++dy)
                        for (int dx = 0; dx < K && full; ++dx) full = on[z + dz][y + dy][x + dx];
                if (full) return false;
            }
    return true;
}

/// Whether domain voxel (e, f, g) is carried on its side: thin there, or with a face neighbour thin on the same
/// side (so that a thin part's image stays joined to the thick part it hangs from). The slow, obvious test: the
/// reference's, and the definition the fast path's (carry.cpp) is checked against.
template <class Density>
inline bool is_carried(const Density& density, std::int64_t e, std::int64_t f, std::int64_t g) {
    const bool inside = density(e, f, g) >= 0.5f;
    return is_thin(density, e, f, g, inside) || is_thin(density, e - 1, f, g, inside) || is_thin(density, e + 1, f, g, inside) ||
           is_thin(density, e, f - 1, g, inside) || is_thin(density, e, f + 1, g, inside) || is_thin(density, e, f, g - 1, inside) ||
           is_thin(density, e, f, g + 1, inside);
}

/// A carried domain voxel's image: its domain index (e + D0 (f + D1 g)), the target cell nearest its image's
/// centre, and its side.
struct CarryImage {
    std::uint64_t voxel;
    std::array<std::int64_t, 3> cell;
    bool inside;
};

/// The target cell nearest a point (target index units).
inline std::array<std::int64_t, 3> nearest_cell(const double* p) {
    return {std::int64_t(std::floor(p[0] + 0.5)), std::int64_t(std::floor(p[1] + 0.5)), std::int64_t(std::floor(p[2] + 0.5))};
}

/// A target cell carried to side `inside`.
struct Carry {
    std::array<std::int64_t, 3> cell;
    bool inside;
    bool operator==(const Carry&) const = default;
};
/// Rows' order: z, then y, then x, then the side (the outside first).
inline bool carry_less(const Carry& p, const Carry& q) {
    return std::tie(p.cell[2], p.cell[1], p.cell[0], p.inside) < std::tie(q.cell[2], q.cell[1], q.cell[0], q.inside);
}

/// Most cells one carried voxel's image box may hold (8^3). A wild edit stretches a voxel over hundreds of voxels
/// along each axis, and its box, millions of cells per voxel, once took all memory (a frame turned 178 degrees on
/// the box at 32: 17 GB and growing) whatever --max-memory said; a wall stretched that far is past keeping
/// closed anyway. Such a voxel holds only the cells nearest its image's centre (link_carries adds them).
constexpr std::int64_t kMaxImageCells = 512;

/// The target cells a carried voxel holds: those whose centres (integer index points) lie in the bounding box of
/// its image, centre + J [-1/2, 1/2]^3 (J's columns: the map's derivatives per voxel step, target index units),
/// half-open, and never less than a voxel wide along an axis; none when that box would hold more than
/// kMaxImageCells. See the file comment for why the box and not the image itself. `push(cell)` for each.
template <class Push>
inline void image_cells(const Eigen::Vector3d& centre, const Eigen::Matrix3d& J, Push&& push) {
    std::int64_t first[3], last[3];
    Eigen::Matrix3d edges = J;
    for (int k = 0; k < 3; ++k) {
        const double length = edges.col(k).norm();
        if (length > 0 && length < 1) edges.col(k) /= length;
    }
    for (int a = 0; a < 3; ++a) {
        const double half = std::max(0.5, 0.5 * edges.row(a).cwiseAbs().sum());
        first[a] = std::int64_t(std::ceil(centre[a] - half));
        last[a] = std::int64_t(std::ceil(centre[a] + half)) - 1;
    }
    double cells = 1;
    for (int a = 0; a < 3; ++a) cells *= double(last[a] - first[a] + 1);
    if (!(cells <= double(kMaxImageCells))) return; // also a non-finite map
    for (std::int64_t z = first[2]; z <= last[2]; ++z)
        for (std::int64_t y = first[1]; y <= last[1]; ++y)
            for (std::int64_t x = first[0]; x <= last[0]; ++x) push(std::array<std::int64_t, 3>{x, y, z});
}

/// The cells the carried voxels hold on their sides: `cells` (their images' cells, image_cells), each voxel's
/// nearest cell (a compressed image may hold none), and between two face neighbours of one side whose nearest
/// cells are diagonal neighbours (a compression's or rotation's diagonal step), the cells of a path of face
/// neighbours from the lower voxel's cell, x first, then y, then z. `images` (sorted here) come from a domain of
/// `dims` voxels; the result is sorted by carry_less, each cell and side once.
inline std::vector<Carry> link_carries(std::vector<CarryImage>& images, std::vector<Carry> cells, const std::array<std::int64_t, 3>& dims) {
    std::sort(images.begin(), images.end(), [](const CarryImage& p, const CarryImage& q) { return p.voxel < q.voxel; });
    const std::uint64_t strides[3] = {1, std::uint64_t(dims[0]), std::uint64_t(dims[0] * dims[1])};
    for (const auto& image : images) {
        cells.push_back({image.cell, image.inside});
        const std::uint64_t at[3] = {image.voxel % strides[1], (image.voxel / strides[1]) % std::uint64_t(dims[1]), image.voxel / strides[2]};
        for (std::size_t axis = 0; axis < 3; ++axis) {
            if (at[axis] + 1 >= std::uint64_t(dims[axis])) continue;
            const std::uint64_t key = image.voxel + strides[axis];
            const auto n = std::lower_bound(images.begin(), images.end(), key, [](const CarryImage& p, std::uint64_t k) { return p.voxel < k; });
            if (n == images.end() || n->voxel != key || n->inside != image.inside) continue;
            int steps = 0;
            bool near = true;
            for (std::size_t a = 0; a < 3; ++a) {
                const std::int64_t d = std::abs(n->cell[a] - image.cell[a]);
                steps += d != 0;
                near = near && d <= 1;
            }
            if (!near || steps < 2) continue; // the same cell, face neighbours, or a stretch the images' cells fill
            std::array<std::int64_t, 3> c = image.cell;
            for (std::size_t a = 0; a < 2; ++a)
                if (c[a] != n->cell[a]) {
                    c[a] = n->cell[a];
                    if (c != n->cell) cells.push_back({c, image.inside});
                }
        }
    }
    std::sort(cells.begin(), cells.end(), carry_less);
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
    return cells;
}

/// A resolved density `d` after the carries on its cell: put back on the side thin voxels carry it to. Where both
/// sides carry it (a thin wall beside a thin gap, the wall's image box reaching into the gap's), the inside
/// wins: the box is what keeps a turned wall closed, and letting the gap's voxels take it back punched holes in
/// walls (Euler characteristic -40 against the input's -4 on the snowden bust, against -8 this way). The few
/// such cells that then bridge the gap are given back to it afterwards (bridges).
inline float carried_density(float d, bool carried_inside, bool carried_outside) {
    if (carried_inside) return d < 0.5f ? kCarriedInside : d;
    if (carried_outside && d >= 0.5f) return kCarriedOutside;
    return d;
}

/// How far (voxels, each way) bridges looks for another way between a cell's inside neighbours. On the snowden
/// nose edit at 128 one bridge's loop closes only 24 voxels out (the glasses' rim joins the face at its ends):
/// 8 left two of the three bridges, 16 one. The search stops as soon as every neighbour is reached.
constexpr std::int64_t kBridgeReach = 32;

/// Parts of one side around a cell, in its 3 x 3 x 3 neighbourhood `n` ([z][y][x], true inside; the centre left
/// out): for the inside, cells of its 18 neighbours joined across faces, counted where they hold one of its face
/// neighbours; for the outside, cells of its 26 neighbours joined across faces and edges, counted where they hold
/// one of its 18 neighbours (extract's connectivity: inside across faces, outside across faces and edges).
inline int local_parts(const bool (&n)[3][3][3], bool inside) {
    // The 27 cells as bits (x + 3 y + 9 z), with each cell's neighbours across faces (inside) or faces and edges
    // (outside) as masks: a part is grown by OR-ing its cells' masks.
    struct Tables {
        std::uint32_t faces[27], edges[27], near1 = 0, near2 = 0;
        Tables() {
            for (int q = 0; q < 27; ++q) {
                faces[q] = edges[q] = 0;
                const int d = std::abs(q % 3 - 1) + std::abs(q / 3 % 3 - 1) + std::abs(q / 9 - 1);
                if (q != 13 && d <= 1) near1 |= 1u << q;
                if (q != 13 && d <= 2) near2 |= 1u << q;
                for (int r = 0; r < 27; ++r) {
                    const int dx = std::abs(q % 3 - r % 3), dy = std::abs(q / 3 % 3 - r / 3 % 3), dz = std::abs(q / 9 - r / 9);
                    if (dx > 1 || dy > 1 || dz > 1 || q == r) continue;
                    if (dx + dy + dz == 1) faces[q] |= 1u << r;
                    if (dx + dy + dz <= 2) edges[q] |= 1u << r;
                }
            }
        }
    };
    static const Tables tables;
    std::uint32_t members = 0;
    for (int q = 0; q < 27; ++q)
        if (q != 13 && n[q / 9][q / 3 % 3][q % 3] == inside) members |= 1u << q;
    if (inside) members &= tables.near2; // the 18 neighbours
    const std::uint32_t* joins = inside ? tables.faces : tables.edges;
    std::uint32_t seeds = members & (inside ? tables.near1 : tables.near2);
    int parts = 0;
    while (seeds) {
        std::uint32_t part = seeds & (~seeds + 1), grown = part;
        do {
            part = grown;
            for (std::uint32_t bits = part; bits; bits &= bits - 1) grown |= joins[std::countr_zero(bits)] & members;
        } while (grown != part);
        members &= ~part, seeds &= ~part;
        ++parts;
    }
    return parts;
}

/// The cells carried to both sides that bridge a gap, to be put outside (kCarriedOutside). carried_density gives
/// such a cell to the wall; where a wall's image box reaches across a gap one voxel wide to the next wall (the
/// snowden bust's glasses against its face, turned by the nose edit) the cell joins the two: a handle the input
/// does not have (Euler characteristic -8 against the round trip's -4 at 128, -4 against -2 at 192). A cell
/// bridges when, with it inside:
/// - its inside neighbours are apart around it and its outside ones are one part (local_parts): it joins two
///   things across a gap, where a wall's cell (outside on two sides) or a corner of one part (one inside part)
///   does not;
/// - its inside face neighbours are joined without it within kBridgeReach voxels, so it closes a loop. A cell
///   whose neighbours join only through it is kept: giving it up would cut a wall in two (a scan at 64 lost a
///   piece that way);
/// - its centre pulls back to an outside voxel of the input (`source_inside` false): the gap's, not the wall's.
/// Cells are taken in carry_less order, each judged with the ones before it as decided: the result does not
/// depend on threads, and an incremental update that judges them all again agrees with the full warp.
/// `carries`: sorted by carry_less (link_carries); `resolved_inside(x, y, z)`: whether target cell (x, y, z) is
/// inside after carried_density (so every cell carried to both sides reads inside); `source_inside(cell)`: as the
/// free function. Returns the cells in carry_less order.
template <class ResolvedInside, class SourceInside>
std::vector<std::array<std::int64_t, 3>> bridges(const std::vector<Carry>& carries, const ResolvedInside& resolved_inside, const SourceInside& source_inside) {
    using Cell3 = std::array<std::int64_t, 3>;
    std::vector<Cell3> both; // sorted by carry_less: (z, y, x)
    for (std::size_t q = 0; q + 1 < carries.size(); ++q) // per cell: the outside, then the inside
        if (carries[q].cell == carries[q + 1].cell) both.push_back(carries[q].cell);
    std::vector<Cell3> out; // the cells given to the gap so far, in carry_less order
    if (both.empty()) return out;
    // Every cell carried to both sides resolved inside (carried_density), so a cell is inside as resolved unless
    // this pass gave it to the gap.
    auto cell_less = [](const Cell3& p, const Cell3& q) { return std::tie(p[2], p[1], p[0]) < std::tie(q[2], q[1], q[0]); };
    auto inside = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
        if (!resolved_inside(x, y, z)) return false;
        return out.empty() || !std::binary_search(out.begin(), out.end(), Cell3{x, y, z}, cell_less);
    };
    constexpr std::int64_t R = kBridgeReach, W = 2 * R + 1;
    static constexpr int kFace[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
    std::vector<std::uint32_t> seen; // == stamp: visited by this cell's search (no clearing between searches)
    std::uint32_t stamp = 0;
    std::vector<std::int64_t> queue;
    for (std::size_t q = 0; q < both.size(); ++q) {
        const Cell3 c = both[q];
        bool n[3][3][3];
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) n[dz + 1][dy + 1][dx + 1] = (dx | dy | dz) == 0 || inside(c[0] + dx, c[1] + dy, c[2] + dz);
        int inside_faces = 0;
        for (const auto& f : kFace) inside_faces += n[f[2] + 1][f[1] + 1][f[0] + 1];
        if (inside_faces < 2) continue; // one inside part at most
        // A bridge joins inside parts that are apart around it (faces joined, within its 18 neighbours) and
        // stands in one outside part (faces and edges joined, within its 26): a wall's cell has outside on two sides.
        if (local_parts(n, true) < 2 || local_parts(n, false) != 1) continue;
        // Breadth-first from one inside face neighbour over the window around c, c left out.
        if (seen.empty()) seen.assign(std::size_t(W * W * W), 0);
        ++stamp;
        queue.clear();
        auto key = [&](std::int64_t x, std::int64_t y, std::int64_t z) { return (x - c[0] + R) + W * ((y - c[1] + R) + W * (z - c[2] + R)); };
        seen[std::size_t(key(c[0], c[1], c[2]))] = stamp;
        std::int64_t targets[6];
        int count = 0, reached = 1;
        for (const auto& f : kFace)
            if (n[f[2] + 1][f[1] + 1][f[0] + 1]) targets[count++] = key(c[0] + f[0], c[1] + f[1], c[2] + f[2]);
        queue.push_back(targets[0]), seen[std::size_t(targets[0])] = stamp;
        for (std::size_t head = 0; head < queue.size() && reached < count; ++head) {
            const std::int64_t k = queue[head];
            const std::int64_t x = k % W, y = (k / W) % W, z = k / (W * W);
            for (const auto& f : kFace) {
                const std::int64_t u = x + f[0], v = y + f[1], w = z + f[2];
                if (u < 0 || v < 0 || w < 0 || u >= W || v >= W || w >= W) continue;
                const std::int64_t m = u + W * (v + W * w);
                if (seen[std::size_t(m)] == stamp || !inside(c[0] + u - R, c[1] + v - R, c[2] + w - R)) continue;
                seen[std::size_t(m)] = stamp;
                queue.push_back(m);
                reached += std::count(targets + 1, targets + count, m) > 0;
            }
        }
        if (reached == count && !source_inside(c)) out.push_back(c); // in carry_less order, so out stays sorted
    }
    return out;
}

} // namespace voxwarp::warp_internal
