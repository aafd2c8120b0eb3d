// Marching cubes with one fixed rule for ambiguous grid faces (inside corners on one diagonal, outside corners on
// the other): the outside corners join, the inside corners stay apart. A face's decision depends on its four
// corners alone, so the two cells that share it agree and the surface is a closed 2-manifold; inside is 6-connected
// and outside 18-connected. voxelize's thin-wall pass (keep_thin_walls) is written for this rule: where a wall
// thinner than a voxel runs between an ambiguous face's outside corners, it makes one of them inside. Every vertex
// lies on a grid edge at the linear zero of its two voxels' densities, so a crossing that voxelize placed
// (fit_crossings) is met exactly; a dual mesher such as OpenVDB's VolumeToMesh averages a cell's crossings into one
// vertex, which lands between the two faces of a wall about a voxel thick.
#include "marching_cubes.h"

#include <voxwarp_internal/geometry.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace voxwarp::extract_internal {

namespace {

/// Cell corner c sits at offset (c & 1, (c >> 1) & 1, c >> 2). Edge e joins corners along axis e / 4; its
/// low corner is the (e % 4)-th corner with that axis' bit clear.
struct CellTable {
    std::array<std::array<int, 2>, 12> edge_corners{};
    /// Per edge: the two faces of the cell it bounds, as bits 2 axis + side.
    std::array<std::uint8_t, 12> edge_faces{};
    /// Per inside-corner mask: the surface's loops in the cell, as edge lists, clockwise seen from outside.
    std::array<std::vector<std::vector<int>>, 256> loops;

    CellTable() {
        int edge_of[8][8];
        for (int axis = 0, e = 0; axis < 3; ++axis)
            for (int c = 0; c < 8; ++c)
                if (!(c >> axis & 1)) {
                    edge_corners[std::size_t(e)] = {c, c | 1 << axis};
                    edge_of[c][c | 1 << axis] = edge_of[c | 1 << axis][c] = e;
                    for (int other = 0; other < 3; ++other)
                        if (other != axis) edge_faces[std::size_t(e)] |= std::uint8_t(1 << (2 * other + (c >> other & 1)));
                    ++e;
                }
        for (int mask = 0; mask < 256; ++mask) {
            auto inside = [&](int c) { return (mask >> c & 1) != 0; };
            std::array<int, 12> next;
            next.fill(-1);
            for (int axis = 0; axis < 3; ++axis)
                for (int side = 0; side < 2; ++side) {
                    // The face's corners counter-clockwise seen from outside the cell.
                    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
                    const int uv[4][2] = {{0, 0}, {side, 1 - side}, {1, 1}, {1 - side, side}};
                    int corner[4];
                    for (int n = 0; n < 4; ++n) corner[n] = side << axis | uv[n][0] << u | uv[n][1] << v;
                    // A segment runs from an exit (inside -> outside along the walk) to the entry before it: it
                    // cuts off the inside corners between them, so the outside corners of an ambiguous face join.
                    // Seen from the neighbouring cell the walk runs backwards: the same pairs, opposite directions.
                    for (int n = 0; n < 4; ++n) {
                        if (!(inside(corner[n]) && !inside(corner[(n + 1) % 4]))) continue;
                        for (int m = 1; m < 4; ++m) {
                            const int a = corner[(n + 3 * m) % 4], b = corner[(n + 3 * m + 1) % 4];
                            if (!inside(a) && inside(b)) {
                                next[std::size_t(edge_of[corner[n]][corner[(n + 1) % 4]])] = edge_of[a][b];
                                break;
                            }
                        }
                    }
                }
            std::array<bool, 12> used{};
            for (int e = 0; e < 12; ++e) {
                if (next[std::size_t(e)] < 0 || used[std::size_t(e)]) continue;
                std::vector<int> loop;
                for (int f = e; !used[std::size_t(f)]; f = next[std::size_t(f)]) used[std::size_t(f)] = true, loop.push_back(f);
                loops[std::size_t(mask)].push_back(std::move(loop));
            }
        }
    }
};

const CellTable& cell_table() {
    static const CellTable table;
    return table;
}

constexpr int kCells = MarchingBlock::kCells;
constexpr int kSide = kCells + 1;                  // corner values per block side
constexpr int kEdgeBits = 3 * kCells * kCells * kCells; // edges a block owns: 3 from each low corner
constexpr int kWords = kEdgeBits / 64;
constexpr std::uint32_t kCentre = 1u << 31;

/// Block (cx, cy, cz) holds the cells whose low corner is voxel 8 c - 1 + l, l in [0, 8), so that the cells
/// straddling the voxmap's border (the voxel past it reads 0) are included; it owns the edges from those low
/// corners along +x, +y and +z. A vertex is referred to as (edge bit) | (neighbour block offset dx + 2 dy +
/// 4 dz) << 11, or as kCentre | n for the block's n-th loop centre.
struct Block {
    std::array<std::uint64_t, kWords> crossing{}; // bit ((axis * 8 + z) * 8 + y) * 8 + x: edge crosses
    std::array<std::uint32_t, kWords> before{};   // crossings in earlier words
    std::uint32_t edges = 0, centres = 0, triangles = 0;
    std::uint64_t first_vertex = 0, first_triangle = 0; // the block's share of the output, in order

    std::uint32_t rank(std::uint32_t bit) const {
        const std::uint64_t below = crossing[bit >> 6] & ((std::uint64_t(1) << (bit & 63)) - 1);
        return before[bit >> 6] + std::uint32_t(std::popcount(below));
    }
};

/// One block's cells: reports its crossings in bit order (`crossing(bit, point)`), each loop centre it needs
/// (`centre(point)`, returning its reference) and its triangles (`triangle(a, b, c)`, references), counter-
/// clockwise seen from outside, each crossing `margin` (edge_margin) off its grid edge's ends. Run twice with the same
/// input, it reports the same things in the same order.
template <class Crossing, class Centre, class Triangle>
void mesh_block(const SparseVoxmap& voxmap, float isovalue, double margin, const std::int64_t* g0, Crossing&& crossing, Centre&& centre, Triangle&& triangle) {
    const CellTable& table = cell_table();
    const double h = voxmap.voxel_size();
    std::array<float, kSide * kSide * kSide> value;
    for (int z = 0; z < kSide; ++z)
        for (int y = 0; y < kSide; ++y)
            for (int x = 0; x < kSide; ++x) value[std::size_t(x + kSide * (y + kSide * z))] = voxmap.at(g0[0] + x, g0[1] + y, g0[2] + z);
    auto at = [&](int x, int y, int z) { return value[std::size_t(x + kSide * (y + kSide * z))]; };
    auto crossing_point = [&](const int* low, int axis) {
        int high[3] = {low[0], low[1], low[2]};
        ++high[axis];
        const float a = at(low[0], low[1], low[2]), b = at(high[0], high[1], high[2]);
        Eigen::Vector3d p = voxmap.world(double(g0[0] + low[0]), double(g0[1] + low[1]), double(g0[2] + low[2]));
        p[axis] += h * std::clamp(double((isovalue - a) / (b - a)), margin, 1 - margin);
        return p;
    };
    static constexpr int step[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int axis = 0; axis < 3; ++axis)
        for (int z = 0; z < kCells; ++z)
            for (int y = 0; y < kCells; ++y)
                for (int x = 0; x < kCells; ++x) {
                    if ((at(x, y, z) >= isovalue) == (at(x + step[axis][0], y + step[axis][1], z + step[axis][2]) >= isovalue)) continue;
                    const int low[3] = {x, y, z};
                    crossing(std::uint32_t(((axis * kCells + z) * kCells + y) * kCells + x), crossing_point(low, axis));
                }
    std::array<std::uint32_t, 12> reference;
    std::array<Eigen::Vector3d, 12> point;
    std::array<int, 12> edge;
    for (int z = 0; z < kCells; ++z)
        for (int y = 0; y < kCells; ++y)
            for (int x = 0; x < kCells; ++x) {
                int mask = 0;
                for (int corner = 0; corner < 8; ++corner) mask |= int(at(x + (corner & 1), y + (corner >> 1 & 1), z + (corner >> 2)) >= isovalue) << corner;
                if (mask == 0 || mask == 255) continue;
                for (const auto& loop : table.loops[std::size_t(mask)]) {
                    for (std::size_t m = 0; m < loop.size(); ++m) {
                        const int e = loop[m], corner = table.edge_corners[std::size_t(e)][0], axis = e / 4;
                        edge[m] = e;
                        int low[3] = {x + (corner & 1), y + (corner >> 1 & 1), z + (corner >> 2)}, neighbour = 0;
                        point[m] = crossing_point(low, axis);
                        for (int d = 0; d < 3; ++d)
                            if (low[d] == kCells) low[d] = 0, neighbour |= 1 << d;
                        reference[m] = std::uint32_t(((axis * kCells + low[2]) * kCells + low[1]) * kCells + low[0]) | std::uint32_t(neighbour) << 11;
                    }
                    // Cut ears off the loop, each time the one whose new edge is shortest (for four corners: the
                    // shorter diagonal); triangles are the loop reversed, counter-clockwise seen from outside. A
                    // new edge between two crossings on one face of the cell is not allowed: the neighbouring cell
                    // may join the same two (an ambiguous face), and the edge would have more than two triangles.
                    // Should no ear be left, the rest is a fan around the loop's centre.
                    std::size_t size = loop.size();
                    while (size > 3) {
                        std::size_t ear = size;
                        double best = std::numeric_limits<double>::infinity();
                        for (std::size_t m = 0; m < size; ++m) {
                            const std::size_t before = (m + size - 1) % size, after = (m + 1) % size;
                            if (table.edge_faces[std::size_t(edge[before])] & table.edge_faces[std::size_t(edge[after])]) continue;
                            const double length = (point[before] - point[after]).squaredNorm();
                            if (length < best) best = length, ear = m;
                        }
                        if (ear == size) break;
                        triangle(reference[(ear + 1) % size], reference[ear], reference[(ear + size - 1) % size]);
                        for (std::size_t m = ear; m + 1 < size; ++m) reference[m] = reference[m + 1], point[m] = point[m + 1], edge[m] = edge[m + 1];
                        --size;
                    }
                    if (size == 3) {
                        triangle(reference[2], reference[1], reference[0]);
                    } else {
                        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
                        for (std::size_t m = 0; m < size; ++m) sum += point[m];
                        const std::uint32_t middle = centre(Eigen::Vector3d(sum / double(size)));
                        for (std::size_t m = 0; m < size; ++m) triangle(middle, reference[(m + 1) % size], reference[m]);
                    }
                }
            }
}

} // namespace

double edge_margin(const SparseVoxmap& voxmap) {
    const Eigen::Vector3d low = voxmap.origin(), high = voxmap.world(double(voxmap.dims()[0]), double(voxmap.dims()[1]), double(voxmap.dims()[2]));
    const double reach = std::max(low.cwiseAbs().maxCoeff(), high.cwiseAbs().maxCoeff());
    return std::clamp(internal::float_gap(reach) / voxmap.voxel_size(), 1e-6, 1e-2);
}

TriangleMesh marching_cubes(const SparseVoxmap& voxmap, float isovalue, Progress& progress, std::vector<MarchingBlock>* runs) {
    const auto& dims = voxmap.dims();
    const double margin = edge_margin(voxmap);
    const std::array<std::int64_t, 3> count{(dims[0] + 1 + kCells - 1) / kCells, (dims[1] + 1 + kCells - 1) / kCells,
                                            (dims[2] + 1 + kCells - 1) / kCells};
    const std::int64_t total = count[0] * count[1] * count[2];
    auto coordinates = [&](std::int64_t c) { return std::array<std::int64_t, 3>{c % count[0], (c / count[0]) % count[1], c / (count[0] * count[1])}; };

    // Blocks whose corners are not all on one side, by the data blocks they overlap (stored ones may cross).
    std::vector<std::int32_t> active(std::size_t(total), -1);
    std::vector<std::int64_t> order;
    for (std::int64_t c = 0; c < total; ++c) {
        const auto at = coordinates(c);
        bool in = false, out = false, stored = false;
        for (int axis = 0; axis < 3; ++axis)
            out |= kCells * at[std::size_t(axis)] - 1 < 0 || kCells * at[std::size_t(axis)] + kCells - 1 >= dims[std::size_t(axis)];
        for (int d = 0; d < 8 && !stored; ++d) {
            const std::int64_t b[3] = {at[0] - 1 + (d & 1), at[1] - 1 + (d >> 1 & 1), at[2] - 1 + (d >> 2)};
            bool exists = true;
            for (int axis = 0; axis < 3; ++axis) exists &= b[axis] >= 0 && b[axis] < voxmap.block_dims()[std::size_t(axis)];
            if (!exists) continue;
            const std::int64_t index = voxmap.block_index(b[0], b[1], b[2]);
            if (voxmap.block_values(index)) stored = true;
            else (voxmap.block_uniform(index) >= isovalue ? in : out) = true;
        }
        if (stored || (in && out)) active[std::size_t(c)] = std::int32_t(order.size()), order.push_back(c);
    }
    std::vector<Block> blocks(order.size());
    auto first_corner = [&](std::size_t n) {
        const auto at = coordinates(order[n]);
        return std::array<std::int64_t, 3>{kCells * at[0] - 1, kCells * at[1] - 1, kCells * at[2] - 1};
    };

    // Pass 1 counts: each block's crossings (as bits, so that a vertex's number is its rank), loop centres and
    // triangles. Pass 2 meshes each block again and writes straight into the output at the block's offsets, so
    // the mesh is never held twice.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, order.size(), 4), [&](const auto& range) {
        for (std::size_t n = range.begin(); n != range.end() && !progress.cancelled(); ++n) {
            Block& block = blocks[n];
            const auto g0 = first_corner(n);
            mesh_block(
                voxmap, isovalue, margin, g0.data(), [&](std::uint32_t bit, const Eigen::Vector3d&) { block.crossing[bit >> 6] |= std::uint64_t(1) << (bit & 63); },
                [&](const Eigen::Vector3d&) { return kCentre | block.centres++; }, [&](std::uint32_t, std::uint32_t, std::uint32_t) { ++block.triangles; });
            for (int w = 0; w < kWords; ++w) {
                block.before[std::size_t(w)] = block.edges;
                block.edges += std::uint32_t(std::popcount(block.crossing[std::size_t(w)]));
            }
        }
    });
    progress.check();
    progress.report(0.5);

    std::uint64_t vertices = 0, triangles = 0;
    for (std::size_t n = 0; n < blocks.size(); ++n) {
        Block& block = blocks[n];
        if (runs) runs->push_back({first_corner(n), std::uint32_t(vertices), std::uint32_t(triangles)});
        block.first_vertex = vertices, vertices += block.edges + block.centres;
        block.first_triangle = triangles, triangles += block.triangles;
    }
    TriangleMesh mesh;
    // Room for the feature mesher's fan centres, split points and their triangles (a few percent), and for the
    // vertices and pieces snapping's refinement adds (15-30 %), so that adding them copies nothing (capacity never
    // written is address space; its pages are never touched).
    mesh.vertices.reserve(std::size_t(vertices + vertices / 2));
    mesh.triangles.reserve(std::size_t(triangles + triangles / 2));
    mesh.vertices.resize(std::size_t(vertices));
    mesh.triangles.resize(std::size_t(triangles));
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size(), 4), [&](const auto& range) {
        for (std::size_t n = range.begin(); n != range.end() && !progress.cancelled(); ++n) {
            const Block& block = blocks[n];
            const auto at = coordinates(order[n]);
            std::array<const Block*, 8> neighbour{};
            for (int d = 0; d < 8; ++d) {
                const std::int64_t b[3] = {at[0] + (d & 1), at[1] + (d >> 1 & 1), at[2] + (d >> 2)};
                if (b[0] < count[0] && b[1] < count[1] && b[2] < count[2]) {
                    const std::int32_t id = active[std::size_t(b[0] + count[0] * (b[1] + count[1] * b[2]))];
                    if (id >= 0) neighbour[std::size_t(d)] = &blocks[std::size_t(id)];
                }
            }
            auto index = [&](std::uint32_t reference) -> std::int32_t {
                if (reference & kCentre) return std::int32_t(block.first_vertex + block.edges + (reference & ~kCentre));
                // A crossing edge's owner has a crossing among its corners, so it is active.
                const Block& owner = *neighbour[reference >> 11];
                return std::int32_t(owner.first_vertex + owner.rank(reference & 2047));
            };
            std::uint64_t next_crossing = block.first_vertex, next_centre = block.first_vertex + block.edges, next_triangle = block.first_triangle;
            const auto g0 = first_corner(n);
            mesh_block(
                voxmap, isovalue, margin, g0.data(), [&](std::uint32_t, const Eigen::Vector3d& p) { mesh.vertices[std::size_t(next_crossing++)] = p; },
                [&](const Eigen::Vector3d& p) {
                    mesh.vertices[std::size_t(next_centre)] = p;
                    return kCentre | std::uint32_t(next_centre++ - block.first_vertex - block.edges);
                },
                [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) { mesh.triangles[std::size_t(next_triangle++)] = {index(a), index(b), index(c)}; });
        }
    });
    progress.check();
    progress.report(1.0);
    return mesh;
}

} // namespace voxwarp::extract_internal
