// sharp_feature_surface (voxelize.h): the Hermite data the feature mesher needs where the mesh has sharp edges.
#include <voxwarp/errors.h>
#include <voxwarp/voxelize.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_map>

namespace voxwarp {

namespace {

double distance_to_segment(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    const Eigen::Vector3d ab = b - a;
    const double t = std::clamp(ab.dot(p - a) / std::max(ab.squaredNorm(), 1e-300), 0.0, 1.0);
    return (a + t * ab - p).norm();
}

} // namespace

FeatureSurface sharp_feature_surface(const TriangleMesh& mesh, double voxel_size, double angle_degrees) {
    if (!(voxel_size > 0)) throw InvalidInput("sharp_feature_surface: voxel size must be > 0");
    TriangleMesh storage;
    const auto& faces = all_triangles(mesh, storage);
    std::vector<Eigen::Vector3d> normal(faces.size());
    for (std::size_t f = 0; f < faces.size(); ++f) {
        const auto& t = faces[f];
        const Eigen::Vector3d n = (mesh.vertices[std::size_t(t[1])] - mesh.vertices[std::size_t(t[0])]).cross(mesh.vertices[std::size_t(t[2])] - mesh.vertices[std::size_t(t[0])]);
        normal[f] = n.norm() > 0 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d::Zero();
    }
    // Sharp edges: exactly two faces, their normals apart by more than the angle.
    std::unordered_map<std::uint64_t, std::array<std::int64_t, 3>> edge_faces; // edge -> (count, face, face)
    edge_faces.reserve(faces.size() * 2);
    for (std::size_t f = 0; f < faces.size(); ++f)
        for (int c = 0; c < 3; ++c) {
            const auto [a, b] = std::minmax(faces[f][std::size_t(c)], faces[f][std::size_t((c + 1) % 3)]);
            auto& e = edge_faces.try_emplace(std::uint64_t(std::uint32_t(a)) << 32 | std::uint32_t(b), std::array<std::int64_t, 3>{0, -1, -1}).first->second;
            if (e[0] < 2) e[std::size_t(1 + e[0])] = std::int64_t(f);
            ++e[0];
        }
    const double cos_sharp = std::cos(angle_degrees * M_PI / 180.0);
    std::vector<std::pair<std::uint64_t, std::pair<Eigen::Vector3d, Eigen::Vector3d>>> keyed;
    for (const auto& [key, e] : edge_faces) {
        if (e[0] != 2) continue;
        const Eigen::Vector3d &n0 = normal[std::size_t(e[1])], &n1 = normal[std::size_t(e[2])];
        if (!n0.isZero() && !n1.isZero() && n0.dot(n1) < cos_sharp)
            keyed.push_back({key, {mesh.vertices[std::size_t(key >> 32)], mesh.vertices[std::size_t(key & 0xffffffffu)]}});
    }
    std::sort(keyed.begin(), keyed.end(), [](const auto& x, const auto& y) { return x.first < y.first; }); // independent of hashing
    std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> sharp;
    for (auto& [key, segment] : keyed) sharp.push_back(segment);
    FeatureSurface out;
    if (sharp.empty()) return out;
    // Sharp segments hashed by the cells (of `reach` each side) their bounding boxes touch.
    const double reach = 3 * voxel_size, cell = 4 * voxel_size;
    auto key = [&](std::int64_t x, std::int64_t y, std::int64_t z) { return (std::uint64_t(x) & 0x1fffff) | (std::uint64_t(y) & 0x1fffff) << 21 | (std::uint64_t(z) & 0x1fffff) << 42; };
    auto cell_of = [&](double v) { return std::int64_t(std::floor(v / cell)); };
    std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> grid;
    for (std::size_t s = 0; s < sharp.size(); ++s) {
        const Eigen::Vector3d lo = sharp[s].first.cwiseMin(sharp[s].second).array() - reach, hi = sharp[s].first.cwiseMax(sharp[s].second).array() + reach;
        if (((hi - lo) / cell).maxCoeff() > 4096) throw InvalidInput("sharp_feature_surface: an edge spans more than 4096 x 4 voxels");
        for (std::int64_t z = cell_of(lo.z()); z <= cell_of(hi.z()); ++z)
            for (std::int64_t y = cell_of(lo.y()); y <= cell_of(hi.y()); ++y)
                for (std::int64_t x = cell_of(lo.x()); x <= cell_of(hi.x()); ++x) grid[key(x, y, z)].push_back(std::uint32_t(s));
    }
    auto near_sharp = [&](const Eigen::Vector3d& p) {
        const auto it = grid.find(key(cell_of(p.x()), cell_of(p.y()), cell_of(p.z())));
        if (it == grid.end()) return false;
        for (std::uint32_t s : it->second)
            if (distance_to_segment(p, sharp[s].first, sharp[s].second) <= reach) return true;
        return false;
    };
    // Each face cut into n^2 triangles at most a voxel across; those whose centre lies near a sharp edge kept.
    // Fixed blocks of faces, each block's pieces in a list of its own, joined in face order (a TriangleMesh per
    // face, as before, held 288 bytes for every face of the input: 173 MB of a 602,064-face scan).
    constexpr std::size_t kBlock = 256;
    const std::size_t blocks = (faces.size() + kBlock - 1) / kBlock;
    std::vector<TriangleMesh> per_block(blocks);
    tbb::parallel_for(std::size_t(0), blocks, [&](std::size_t block) {
        TriangleMesh& m = per_block[block];
        std::vector<std::int32_t> index;
        for (std::size_t f = block * kBlock; f != std::min(faces.size(), (block + 1) * kBlock); ++f) {
            if (normal[f].isZero()) continue;
            const Eigen::Vector3d &a = mesh.vertices[std::size_t(faces[f][0])], &b = mesh.vertices[std::size_t(faces[f][1])], &c = mesh.vertices[std::size_t(faces[f][2])];
            const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
            const Eigen::Vector3d lo = a.cwiseMin(b).cwiseMin(c), hi = a.cwiseMax(b).cwiseMax(c);
            // A face wholly farther than reach from every sharp edge's box is skipped without cutting it.
            bool any = false;
            for (std::int64_t z = cell_of(lo.z()); z <= cell_of(hi.z()) && !any; ++z)
                for (std::int64_t y = cell_of(lo.y()); y <= cell_of(hi.y()) && !any; ++y)
                    for (std::int64_t x = cell_of(lo.x()); x <= cell_of(hi.x()) && !any; ++x) any = grid.count(key(x, y, z)) > 0;
            if (!any) continue;
            const int n = std::clamp(int(std::ceil(longest / voxel_size)), 1, 4096);
            auto at = [&](int i, int j) { return Eigen::Vector3d(a + (b - a) * (double(i) / n) + (c - a) * (double(j) / n)); };
            // The pieces share their corners (a warp carries each point once, not once per piece around it).
            index.assign(std::size_t(n + 1) * std::size_t(n + 2) / 2, -1);
            auto vertex = [&](int i, int j) {
                std::int32_t& v = index[std::size_t(j) * std::size_t(2 * n + 3 - j) / 2 + std::size_t(i)]; // row j holds n + 1 - j points
                if (v < 0) v = std::int32_t(m.vertices.size()), m.vertices.push_back(at(i, j));
                return v;
            };
            auto emit = [&](std::array<int, 2> p, std::array<int, 2> q, std::array<int, 2> r) {
                if (!near_sharp((at(p[0], p[1]) + at(q[0], q[1]) + at(r[0], r[1])) / 3)) return;
                m.triangles.push_back({vertex(p[0], p[1]), vertex(q[0], q[1]), vertex(r[0], r[1])});
            };
            for (int i = 0; i < n; ++i)
                for (int j = 0; i + j < n; ++j) {
                    emit({i, j}, {i + 1, j}, {i, j + 1});
                    if (i + j + 1 < n) emit({i + 1, j}, {i + 1, j + 1}, {i, j + 1});
                }
        }
    });
    std::size_t vertices = 0, triangles = 0;
    for (const auto& m : per_block) vertices += m.vertices.size(), triangles += m.triangles.size();
    out.faces.vertices.reserve(vertices);
    out.faces.triangles.reserve(triangles);
    for (auto& m : per_block) {
        const auto base = std::int32_t(out.faces.vertices.size());
        out.faces.vertices.insert(out.faces.vertices.end(), m.vertices.begin(), m.vertices.end());
        for (auto t : m.triangles) out.faces.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
        m = TriangleMesh{};
    }
    for (const auto& [a, b] : sharp) {
        const int n = std::clamp(int(std::ceil((b - a).norm() / (0.5 * voxel_size))), 1, 1 << 20);
        for (int i = 0; i < n; ++i) out.edges.emplace_back(a + (b - a) * (double(i) / n), a + (b - a) * (double(i + 1) / n));
    }
    return out;
}

} // namespace voxwarp
