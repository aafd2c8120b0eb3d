// The parts of a model the voxmap loses. A closed mesh is voxelized by a flood fill, which keeps a part only
// where a voxel centre lies inside it, so a plate or spike thinner than a voxel can vanish; the winding-number
// path drops closed crumbs under three voxels; and the warp's box filter averages a part squeezed below a voxel
// into density under 0.5. Each leaves the same trace: input surface with no material near where the space took it.
#include "thin_parts.h"

#include <voxwarp/errors.h>
#include <voxwarp/warp.h>
#include <voxwarp_internal/geometry.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <unordered_map>

namespace voxwarp::deform_internal {

namespace {

constexpr std::size_t kMaxSamples = 1 << 17;
constexpr double kAreaPerSample = 2;  // voxels^2 of surface per sample; parts of less area are not reported
constexpr double kRayReach = 16;  // voxels: thicker than this is not thin, whatever the warp did
constexpr double kThin = 1.5;     // voxels: thicker than this where it was lost, something else lost it
constexpr std::size_t kMaxParts = 16;
constexpr std::size_t kRays = 32; // per part

/// Whether a voxel of density >= 0.5 lies among the 4^3 around the point (the cell it lies in first).
bool holds_material(const SparseVoxmap& v, const Eigen::Vector3d& p) {
    const Eigen::Vector3d x = v.index_of(p);
    if (!x.allFinite()) return false;
    const std::int64_t i = std::int64_t(std::floor(x.x())), j = std::int64_t(std::floor(x.y())), k = std::int64_t(std::floor(x.z()));
    for (int dz = 0; dz <= 1; ++dz)
        for (int dy = 0; dy <= 1; ++dy)
            for (int dx = 0; dx <= 1; ++dx)
                if (v.at(i + dx, j + dy, k + dz) >= 0.5f) return true;
    for (int dz = -1; dz <= 2; ++dz)
        for (int dy = -1; dy <= 2; ++dy)
            for (int dx = -1; dx <= 2; ++dx)
                if (v.at(i + dx, j + dy, k + dz) >= 0.5f) return true;
    return false;
}

struct KeyHash {
    std::size_t operator()(const std::array<std::int64_t, 3>& k) const { return std::size_t(k[0] * 73856093 ^ k[1] * 19349663 ^ k[2] * 83492791); }
};

double median(std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
    return v[v.size() / 2];
}

} // namespace

SurfaceProbe::SurfaceProbe(const TriangleMesh& mesh, double voxel_size)
    : mesh_(mesh), triangles_(all_triangles(mesh, storage_)), h_(voxel_size) {
    const auto& V = mesh_.vertices;
    const std::size_t faces = triangles_.size();
    std::vector<Eigen::Vector3d> normals(faces);
    std::vector<double> areas(faces);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, faces, 4096), [&](const auto& r) {
        for (std::size_t f = r.begin(); f != r.end(); ++f) {
            const auto& t = triangles_[f];
            const Eigen::Vector3d n = (V[std::size_t(t[1])] - V[std::size_t(t[0])]).cross(V[std::size_t(t[2])] - V[std::size_t(t[0])]);
            const double a = 0.5 * n.norm();
            const bool usable = a > 0 && std::isfinite(a) && n.allFinite();
            areas[f] = usable ? a : 0.0, normals[f] = usable ? Eigen::Vector3d(n / (2 * a)) : Eigen::Vector3d::Zero();
        }
    });
    double total = 0;
    for (double a : areas) total += a;
    // A sample per kAreaPerSample voxels of area (fewer past kMaxSamples): a face larger than that is cut into
    // k^2 similar triangles, a sample at each one's centroid; smaller faces, in their order (which keeps
    // neighbours together in meshes as they come), take a sample at their centroid each time the running sum of
    // their areas passes a multiple of that.
    const double per_sample = std::max(kAreaPerSample * h_ * h_, total / double(kMaxSamples));
    std::vector<std::uint32_t> first(faces + 1, 0); // samples of faces before f
    std::vector<int> cut(faces, 0);                 // k, or 0 for a small face
    double small = 0;
    for (std::size_t f = 0; f < faces; ++f) {
        const double a = areas[f];
        std::uint32_t count = 0;
        if (a >= per_sample) {
            cut[f] = int(std::clamp(std::ceil(std::sqrt(a / per_sample)), 1.0, 1024.0));
            count = std::uint32_t(cut[f] * cut[f]);
        } else if (a > 0) {
            count = std::uint32_t(std::floor((small + a) / per_sample) - std::floor(small / per_sample));
            small += a;
        }
        first[f + 1] = first[f] + count;
    }
    const std::size_t n = first[faces];
    rest_.resize(n), normal_.resize(n), face_.resize(n), area_.resize(n);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, faces, 4096), [&](const auto& r) {
        for (std::size_t f = r.begin(); f != r.end(); ++f) {
            std::size_t s = first[f];
            if (s == first[f + 1]) continue;
            const auto& t = triangles_[f];
            const Eigen::Vector3d &p0 = V[std::size_t(t[0])], &p1 = V[std::size_t(t[1])], &p2 = V[std::size_t(t[2])];
            auto add = [&](double u, double v, double share) {
                rest_[s] = p0 + u * (p1 - p0) + v * (p2 - p0), normal_[s] = normals[f], face_[s] = std::int32_t(f), area_[s] = share;
                ++s;
            };
            const int k = cut[f];
            if (k == 0) { // a small face: the area it closed the count with
                for (std::size_t i = first[f]; i < first[f + 1]; ++i) add(1.0 / 3, 1.0 / 3, per_sample);
                continue;
            }
            const double share = areas[f] / double(k * k);
            for (int i = 0; i < k; ++i)
                for (int j = 0; i + j < k; ++j) { // the centroids of the face cut into k^2 similar triangles
                    add((i + 1.0 / 3) / k, (j + 1.0 / 3) / k, share);
                    if (i + j + 1 < k) add((i + 2.0 / 3) / k, (j + 2.0 / 3) / k, share);
                }
        }
    });
    at_ = rest_;
    lost_.assign(n, kHeld);
}

void SurfaceProbe::push(const Lattice& rest, const Lattice& moved, int edit) {
    push_points(rest, moved, at_);
    steps_.emplace_back(edit, rest, moved);
}

void SurfaceProbe::check(const SparseVoxmap& voxmap, int stage) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, at_.size(), 4096), [&](const auto& r) {
        for (std::size_t s = r.begin(); s != r.end(); ++s)
            if (lost_[s] == kHeld && !holds_material(voxmap, at_[s])) lost_[s] = stage;
    });
}

Eigen::Vector3d SurfaceProbe::carry(Eigen::Vector3d p, int stage) const {
    for (const auto& [edit, rest, moved] : steps_) {
        if (edit > stage) break;
        p = moved.evaluate(rest.parameter_of(p));
    }
    return p;
}

std::vector<ThinPart> SurfaceProbe::parts(double longest_side) const {
    std::vector<ThinPart> out;
    const double h = h_;
    std::vector<int> stages;
    for (int s : lost_)
        if (s != kHeld && std::find(stages.begin(), stages.end(), s) == stages.end()) stages.push_back(s);
    std::sort(stages.begin(), stages.end());
    for (const int stage : stages) {
        // Group the stage's lost samples by 2-voxel cells touching one another.
        std::vector<std::size_t> lost;
        for (std::size_t s = 0; s < lost_.size(); ++s)
            if (lost_[s] == stage) lost.push_back(s);
        std::unordered_map<std::array<std::int64_t, 3>, std::size_t, KeyHash> cells;
        std::vector<std::size_t> cell_of(lost.size());
        for (std::size_t i = 0; i < lost.size(); ++i) {
            const Eigen::Vector3d c = at_[lost[i]] / (2 * h);
            const std::array<std::int64_t, 3> key{std::int64_t(std::floor(c.x())), std::int64_t(std::floor(c.y())), std::int64_t(std::floor(c.z()))};
            cell_of[i] = cells.emplace(key, cells.size()).first->second;
        }
        internal::DisjointSets groups(cells.size());
        for (const auto& [key, id] : cells)
            for (int dz = -1; dz <= 1; ++dz)
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const auto it = cells.find({key[0] + dx, key[1] + dy, key[2] + dz});
                        if (it != cells.end()) groups.join(id, it->second);
                    }
        // Groups in the order of their first sample, largest area first, at most 2 kMaxParts measured.
        std::unordered_map<std::size_t, std::size_t> ordinal;
        std::vector<std::vector<std::size_t>> members;
        std::vector<double> group_area;
        for (std::size_t i = 0; i < lost.size(); ++i) {
            const auto [it, fresh] = ordinal.emplace(groups.find(cell_of[i]), members.size());
            if (fresh) members.emplace_back(), group_area.push_back(0);
            members[it->second].push_back(lost[i]);
            group_area[it->second] += area_[lost[i]];
        }
        std::vector<std::size_t> order(members.size());
        std::iota(order.begin(), order.end(), std::size_t(0));
        std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return group_area[a] > group_area[b]; });
        if (order.size() > 2 * kMaxParts) order.resize(2 * kMaxParts);
        for (const std::size_t g : order) {
            const std::vector<std::size_t>& samples = members[g];
            ThinPart part;
            part.stage = stage == kVoxelize ? "voxelize" : "edits[" + std::to_string(stage) + "]";
            double area = 0;
            Eigen::Vector3d centre = Eigen::Vector3d::Zero(), lo = at_[samples[0]], hi = lo;
            Eigen::Vector3d rest_lo = rest_[samples[0]], rest_hi = rest_lo;
            for (std::size_t s : samples) {
                area += area_[s];
                centre += area_[s] * at_[s];
                lo = lo.cwiseMin(at_[s]), hi = hi.cwiseMax(at_[s]);
                rest_lo = rest_lo.cwiseMin(rest_[s]), rest_hi = rest_hi.cwiseMax(rest_[s]);
            }
            part.area_voxels = area / (h * h);
            if (part.area_voxels < kAreaPerSample) continue; // a sample's area at least: less is noise
            part.centre = centre / area, part.lo = lo, part.hi = hi;
            // How thick it was: rays into the input from some of its samples, to the far side of the material.
            std::vector<std::size_t> near;
            const Eigen::Vector3d reach = Eigen::Vector3d::Constant(kRayReach * h);
            for (std::size_t f = 0; f < triangles_.size(); ++f) {
                const auto& t = triangles_[f];
                const Eigen::Vector3d &a = mesh_.vertices[std::size_t(t[0])], &b = mesh_.vertices[std::size_t(t[1])], &c = mesh_.vertices[std::size_t(t[2])];
                const Eigen::Vector3d flo = a.cwiseMin(b).cwiseMin(c), fhi = a.cwiseMax(b).cwiseMax(c);
                if ((flo.array() <= (rest_hi + reach).array()).all() && (fhi.array() >= (rest_lo - reach).array()).all()) near.push_back(f);
            }
            // The candidates by 4-voxel cells (a ray reaches 16 voxels: at most 5 cells per axis); the few faces
            // larger than 8 cells are tried by every ray.
            const double cell = 4 * h;
            auto cell_of = [&](const Eigen::Vector3d& p) {
                return std::array<std::int64_t, 3>{std::int64_t(std::floor(p.x() / cell)), std::int64_t(std::floor(p.y() / cell)), std::int64_t(std::floor(p.z() / cell))};
            };
            std::unordered_map<std::array<std::int64_t, 3>, std::vector<std::uint32_t>, KeyHash> by_cell;
            std::vector<std::uint32_t> large;
            for (std::uint32_t i = 0; i < near.size(); ++i) {
                const auto& t = triangles_[near[i]];
                const Eigen::Vector3d &a = mesh_.vertices[std::size_t(t[0])], &b = mesh_.vertices[std::size_t(t[1])], &c = mesh_.vertices[std::size_t(t[2])];
                const auto lo_cell = cell_of(a.cwiseMin(b).cwiseMin(c)), hi_cell = cell_of(a.cwiseMax(b).cwiseMax(c));
                if (hi_cell[0] - lo_cell[0] > 8 || hi_cell[1] - lo_cell[1] > 8 || hi_cell[2] - lo_cell[2] > 8) {
                    large.push_back(i);
                    continue;
                }
                for (auto z = lo_cell[2]; z <= hi_cell[2]; ++z)
                    for (auto y = lo_cell[1]; y <= hi_cell[1]; ++y)
                        for (auto x = lo_cell[0]; x <= hi_cell[0]; ++x) by_cell[{x, y, z}].push_back(i);
            }
            std::vector<std::size_t> tried(near.size(), std::size_t(-1)); // the ray that last tried each candidate
            std::vector<double> after, before;
            const std::size_t rays = std::min(kRays, samples.size());
            for (std::size_t r = 0; r < rays; ++r) {
                const std::size_t s = samples[r * samples.size() / rays];
                const Eigen::Vector3d d = -normal_[s];
                double best = std::numeric_limits<double>::infinity();
                auto try_face = [&](std::uint32_t i) {
                    if (tried[i] == r || std::int32_t(near[i]) == face_[s]) return;
                    tried[i] = r;
                    const auto& t = triangles_[near[i]];
                    const double hit = internal::line_meets_triangle(rest_[s], d, mesh_.vertices[std::size_t(t[0])], mesh_.vertices[std::size_t(t[1])],
                                                                     mesh_.vertices[std::size_t(t[2])]);
                    if (hit > 0) best = std::min(best, hit);
                };
                for (std::uint32_t i : large) try_face(i);
                const Eigen::Vector3d end = rest_[s] + kRayReach * h * d;
                const auto lo_cell = cell_of(rest_[s].cwiseMin(end)), hi_cell = cell_of(rest_[s].cwiseMax(end));
                for (auto z = lo_cell[2]; z <= hi_cell[2]; ++z)
                    for (auto y = lo_cell[1]; y <= hi_cell[1]; ++y)
                        for (auto x = lo_cell[0]; x <= hi_cell[0]; ++x) {
                            const auto it = by_cell.find({x, y, z});
                            if (it != by_cell.end())
                                for (std::uint32_t i : it->second) try_face(i);
                        }
                if (!(best <= kRayReach * h)) continue;
                try {
                    after.push_back((carry(rest_[s] + best * d, stage) - at_[s]).norm() / h);
                    before.push_back(best / h);
                } catch (const SolverFailure&) {
                    // the far side lies where a clamped lattice's map cannot be inverted: this ray tells nothing
                }
            }
            // Most rays find no far side: an open sheet or a stray piece, which encloses nothing to keep.
            if (2 * after.size() < rays) continue;
            part.thickness_voxels = median(after);
            part.thickness_before_voxels = median(before);
            if (part.thickness_voxels > kThin) continue;
            // Two voxels across keep it (a voxel centre inside it, whatever its orientation; density over 0.5
            // after the warp's box filter).
            part.voxel_size_to_keep = std::max(part.thickness_voxels, 1e-3) * h / 2;
            const double resolution = std::ceil(longest_side / part.voxel_size_to_keep);
            part.resolution_to_keep = resolution <= 8192 ? std::int64_t(resolution) : 0;
            out.push_back(std::move(part));
        }
    }
    std::stable_sort(out.begin(), out.end(), [](const ThinPart& a, const ThinPart& b) { return a.area_voxels > b.area_voxels; });
    if (out.size() > kMaxParts) out.resize(kMaxParts);
    return out;
}

} // namespace voxwarp::deform_internal
