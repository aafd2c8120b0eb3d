#include <voxwarp/decimate.h>
#include <voxwarp/deform.h>
#include <voxwarp/errors.h>
#include <voxwarp/foldover.h>
#include <voxwarp/resources.h>
#include <voxwarp/rigid.h>
#include <voxwarp/snap.h>
#include <voxwarp/transfer.h>
#include <voxwarp/surface_distance.h>

#include "thin_parts.h"

#include <Eigen/Geometry>

#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <tuple>
#include <unordered_map>
#include <unordered_set>

namespace voxwarp {

namespace deform_internal {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::string kind_name(ConstraintKind k) {
    switch (k) {
    case ConstraintKind::move: return "move";
    case ConstraintKind::pin: return "pin";
    case ConstraintKind::control_point: return "control_point";
    case ConstraintKind::turn: return "turn";
    case ConstraintKind::join: return "connect";
    case ConstraintKind::region: return "region";
    case ConstraintKind::normal: return "normal";
    case ConstraintKind::slide: return "slide";
    case ConstraintKind::plate: return "plate";
    case ConstraintKind::bend: return "bend";
    }
    return "?";
}

constexpr int kRegionPoints = 32; // material points a region's rigid motion is imposed on
constexpr double kPlateReach = 1.5; // voxels: a frame this near the model's surface grips it as a plate

/// The model's surface near a point: its nearest point and the outward normal there; {point, zero} when there is
/// no surface within reach.
using NearestSurface = std::function<std::pair<Eigen::Vector3d, Eigen::Vector3d>(const Eigen::Vector3d&)>;

/// The rows the solve takes for an edit's constraints, where an entry needs the model: each region becomes moves
/// of up to kRegionPoints points of the material inside it (`material(shape)` lists candidates), spread by
/// farthest-point sampling from the one nearest its middle, each carried by the region's rigid motion (or held, if
/// it has none); a normal becomes two turns of the surface's tangents there by the least rotation from its normal
/// to the asked direction; a slide a move of the surface point nearest to it; a frame's plate three bends along the
/// surface's tangent plane, when the surface passes within `plate_reach` (world units) of the frame's point.
/// owner[r]: the constraint row r comes from.
std::vector<Constraint> expand_entries(const std::vector<Constraint>& constraints, const std::function<std::vector<Eigen::Vector3d>(const RegionShape&)>& material,
                                       const NearestSurface& nearest, double plate_reach, std::vector<int>& owner) {
    std::vector<Constraint> rows;
    owner.clear();
    for (std::size_t c = 0; c < constraints.size(); ++c) {
        const Constraint& k = constraints[c];
        if (k.kind == ConstraintKind::normal || k.kind == ConstraintKind::slide) {
            const auto [on, normal] = nearest(k.point);
            if (normal.isZero()) throw InvalidInput(k.name + ": no surface of the model within 16 voxels of the point");
            if (k.kind == ConstraintKind::slide) {
                Constraint m = k;
                m.kind = ConstraintKind::move, m.point = on, m.to = k.to;
                rows.push_back(m), owner.push_back(int(c));
                continue;
            }
            const Eigen::Matrix3d turn = Eigen::Quaterniond::FromTwoVectors(normal, k.direction).toRotationMatrix();
            const Eigen::Vector3d t1 = normal.unitOrthogonal(), t2 = normal.cross(t1);
            for (const Eigen::Vector3d& t : {t1, t2}) {
                Constraint r = k;
                r.kind = ConstraintKind::turn, r.point = r.to = k.point, r.direction = t, r.rotation = turn;
                rows.push_back(r), owner.push_back(int(c));
            }
            continue;
        }
        if (k.kind == ConstraintKind::plate) {
            // Flat and unstretched along the surface's tangent plane: the second derivatives there, (t1, t1),
            // (t1, t2) and (t2, t2), turned with the frame. Only where the frame grips the surface.
            const auto [on, normal] = nearest(k.point);
            if (normal.isZero() || (on - k.point).norm() > plate_reach) continue;
            const Eigen::Vector3d t1 = normal.unitOrthogonal(), t2 = normal.cross(t1);
            for (const auto& [a, b] : {std::pair{t1, t1}, std::pair{t1, t2}, std::pair{t2, t2}}) {
                Constraint r = k;
                r.kind = ConstraintKind::bend, r.direction = a, r.across = b;
                rows.push_back(r), owner.push_back(int(c));
            }
            continue;
        }
        if (k.kind != ConstraintKind::region) {
            rows.push_back(k), owner.push_back(int(c));
            continue;
        }
        const std::vector<Eigen::Vector3d> inside = material(k.region);
        if (inside.empty()) throw InvalidInput(k.name + ".region: holds none of the model's material");
        const Eigen::Vector3d middle = k.region.sphere ? k.region.centre : Eigen::Vector3d((k.region.lo + k.region.hi) / 2);
        std::vector<double> distance(inside.size(), std::numeric_limits<double>::infinity());
        std::size_t next = 0;
        for (std::size_t i = 0; i < inside.size(); ++i)
            if ((inside[i] - middle).squaredNorm() < (inside[next] - middle).squaredNorm()) next = i;
        for (int n = 0; n < kRegionPoints && distance[next] > 0; ++n) {
            Constraint m = k; // its name and entry ("region") with it
            m.kind = ConstraintKind::move;
            m.point = inside[next];
            m.to = k.rotation * (m.point - k.pivot) + k.pivot + k.offset;
            rows.push_back(m), owner.push_back(int(c));
            for (std::size_t i = 0; i < inside.size(); ++i) distance[i] = std::min(distance[i], (inside[i] - inside[next]).squaredNorm());
            next = std::size_t(std::max_element(distance.begin(), distance.end()) - distance.begin());
        }
    }
    return rows;
}

/// The nearest point of a mesh to `point` within `reach`, and the surface's normal there (zero: none): the
/// area-weighted normal of the faces of its sheet around it (reached from the nearest face through vertices within
/// `around` of the point), not the nearest face's alone. A point on a voxel centre that the isosurface passes
/// through is ringed by slivers a millionth of a voxel wide (marching cubes' crossings kept off the grid edges'
/// ends), and the nearest of them can have any normal: a sphere's normal turned 20 degrees there came out turned 6.
/// At a mesh's vertex or edge, the nearest face is one of several as well. The far side of a thin part, however
/// near, is another sheet and does not count.
std::pair<Eigen::Vector3d, Eigen::Vector3d> nearest_on(const SourceSurface& surface, const Eigen::Vector3d& point, double reach, double around) {
    const SourcePoint s = surface.nearest(point, Eigen::Vector3d::Zero(), reach);
    if (s.face < 0) return {point, Eigen::Vector3d::Zero()};
    const TriangleMesh& m = surface.mesh();
    const auto& V = m.vertices;
    TriangleMesh storage;
    const auto& T = all_triangles(m, storage); // what the face index counts
    const auto& t = T[std::size_t(s.face)];
    const Eigen::Vector3d on = s.barycentric[0] * V[std::size_t(t[0])] + s.barycentric[1] * V[std::size_t(t[1])] + s.barycentric[2] * V[std::size_t(t[2])];
    // The faces around each vertex near the point (the rest are never visited).
    std::vector<char> near(V.size(), 0);
    for (std::size_t v = 0; v < V.size(); ++v) near[v] = (V[v] - on).norm() <= around;
    std::unordered_map<std::int32_t, std::vector<std::int32_t>> faces_at;
    for (std::size_t f = 0; f < T.size(); ++f)
        for (const auto v : T[f])
            if (near[std::size_t(v)]) faces_at[v].push_back(std::int32_t(f));
    std::vector<std::int32_t> queue{s.face};
    std::unordered_set<std::int32_t> seen{s.face};
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    while (!queue.empty()) {
        const auto& f = T[std::size_t(queue.back())];
        queue.pop_back();
        sum += (V[std::size_t(f[1])] - V[std::size_t(f[0])]).cross(V[std::size_t(f[2])] - V[std::size_t(f[0])]);
        for (const auto v : f)
            if (near[std::size_t(v)])
                for (const auto g : faces_at[v])
                    if (seen.insert(g).second) queue.push_back(g);
    }
    if (!(sum.norm() > 0)) sum = (V[std::size_t(t[1])] - V[std::size_t(t[0])]).cross(V[std::size_t(t[2])] - V[std::size_t(t[0])]);
    return {on, sum.norm() > 0 ? Eigen::Vector3d(sum.normalized()) : Eigen::Vector3d::Zero()};
}

/// Candidates for a region's points in a voxmap: the centres of the voxels inside it at or over density 0.5.
std::function<std::vector<Eigen::Vector3d>(const RegionShape&)> material_of(const SparseVoxmap& voxmap) {
    return [&voxmap](const RegionShape& shape) {
        const Eigen::Vector3d lo = shape.sphere ? Eigen::Vector3d(shape.centre.array() - shape.radius) : shape.lo;
        const Eigen::Vector3d hi = shape.sphere ? Eigen::Vector3d(shape.centre.array() + shape.radius) : shape.hi;
        const Eigen::Vector3d a = voxmap.index_of(lo), b = voxmap.index_of(hi);
        std::array<std::int64_t, 3> from{}, to{};
        for (int d = 0; d < 3; ++d) {
            from[std::size_t(d)] = std::max<std::int64_t>(0, std::int64_t(std::ceil(a[d])));
            to[std::size_t(d)] = std::min<std::int64_t>(voxmap.dims()[std::size_t(d)] - 1, std::int64_t(std::floor(b[d])));
        }
        std::vector<Eigen::Vector3d> out;
        for (std::int64_t k = from[2]; k <= to[2]; ++k)
            for (std::int64_t j = from[1]; j <= to[1]; ++j)
                for (std::int64_t i = from[0]; i <= to[0]; ++i) {
                    const Eigen::Vector3d p = voxmap.world(double(i), double(j), double(k));
                    if (voxmap.at(i, j, k) >= 0.5f && shape.contains(p)) out.push_back(p);
                }
        return out;
    };
}

/// Candidates for a region's points on a mesh (vertex mode): its vertices and triangle centroids inside it.
std::function<std::vector<Eigen::Vector3d>(const RegionShape&)> material_of(const TriangleMesh& mesh) {
    return [&mesh](const RegionShape& shape) {
        std::vector<Eigen::Vector3d> out;
        for (const auto& v : mesh.vertices)
            if (shape.contains(v)) out.push_back(v);
        for (const auto& t : mesh.triangles) {
            const Eigen::Vector3d c = (mesh.vertices[std::size_t(t[0])] + mesh.vertices[std::size_t(t[1])] + mesh.vertices[std::size_t(t[2])]) / 3;
            if (shape.contains(c)) out.push_back(c);
        }
        return out;
    };
}

/// Refuse constraint points far from the model: the data box grown by far_fraction of its size; and targets more
/// than the model's size (its longest side) outside it, which would stretch it past anything the lattice spans.
void check_near(const std::vector<Constraint>& constraints, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double fraction) {
    const Eigen::Vector3d margin = fraction * (hi - lo);
    const double reach = (hi - lo).maxCoeff();
    auto text = [](const Eigen::Vector3d& p) { return std::to_string(p.x()) + ", " + std::to_string(p.y()) + ", " + std::to_string(p.z()); };
    const std::string bounds = std::to_string(lo.x()) + ".." + std::to_string(hi.x()) + ", " + std::to_string(lo.y()) + ".." +
                               std::to_string(hi.y()) + ", " + std::to_string(lo.z()) + ".." + std::to_string(hi.z());
    for (const auto& c : constraints) {
        if (c.kind == ConstraintKind::control_point || c.kind == ConstraintKind::region) continue; // a region's points are the model's
        for (const Eigen::Vector3d& p : {c.point, c.kind == ConstraintKind::join ? c.to : c.point})
            if ((p.array() < (lo - margin).array()).any() || (p.array() > (hi + margin).array()).any())
                throw InvalidInput(c.name + ": point (" + text(p) + ") lies far outside the model (bounds " + bounds + ")");
        if (c.kind == ConstraintKind::move && ((c.to.array() < lo.array() - reach).any() || (c.to.array() > hi.array() + reach).any()))
            throw InvalidInput(c.name + ".to: target (" + text(c.to) + ") lies more than the model's size (" + std::to_string(reach) + ") outside its bounds (" + bounds + ")");
    }
}

/// The constraints of step `s` of `steps`: moves advance by 1/steps of their way, offsets likewise.
std::vector<Constraint> step_constraints(const std::vector<Constraint>& constraints, int s, int steps) {
    std::vector<Constraint> out = constraints;
    for (auto& c : out) {
        if (c.kind == ConstraintKind::move || c.kind == ConstraintKind::turn || c.kind == ConstraintKind::bend) { // a frame's rows go with its point
            const Eigen::Vector3d d = c.to - c.point;
            c.point = c.point + d * (double(s) / steps);
            c.to = c.point + d / steps;
            if (c.kind != ConstraintKind::move) {
                Eigen::AngleAxisd turn(c.rotation);
                if (c.kind == ConstraintKind::bend) { // the plate, as the steps before this one have turned it
                    Eigen::AngleAxisd before = turn;
                    before.angle() *= double(s) / steps;
                    c.direction = before * c.direction, c.across = before * c.across;
                }
                turn.angle() /= steps;
                c.rotation = turn.toRotationMatrix();
            }
        } else if (c.kind == ConstraintKind::join) { // each point a step of its way to their middle, the gap shrinking
            const Eigen::Vector3d middle = (c.point + c.to) / 2;
            const Eigen::Vector3d a = c.point + (middle - c.point) * (double(s) / steps), b = c.to + (middle - c.to) * (double(s) / steps);
            c.point = a, c.to = a + (b - a) / double(steps - s);
        } else if (c.kind == ConstraintKind::control_point) {
            c.offset /= steps;
        }
    }
    return out;
}

/// One step's lattice: the min-norm answer, or, with preserve_volume, least motion that keeps the volume.
ConstraintSolution solve_min_norm(const WarpDomain& domain, const std::vector<Constraint>& constraints, bool preserve_volume, const ProgressCallback& progress,
                                  int& iterations) {
    if (!preserve_volume) return solve_constraints(domain.lattice, constraints);
    RigidSolution s = solve_rigid(domain.lattice, constraints, lattice_material(domain), {.rigid = false, .preserve_volume = true, .progress = progress});
    iterations += s.iterations;
    return s;
}

/// Solve one min-norm edit on `domain`, splitting it into as many steps (up to max_steps) as keep the map
/// injective. Returns the step count; the solution is that of the first step.
int plan_steps(const WarpDomain& domain, const std::vector<Constraint>& rows, bool preserve_volume, const DeformOptions& options, ConstraintSolution& first,
               bool& folds_remain, int& iterations) {
    for (int steps = 1;; steps *= 2) {
        first = solve_min_norm(domain, step_constraints(rows, 0, steps), preserve_volume, options.progress, iterations);
        folds_remain = !find_folds(first.lattice).empty();
        if (!folds_remain || steps * 2 > options.max_steps) return steps;
    }
}

/// The report's entry per constraint row of the edit (`owner` maps the solved rows, regions expanded, to them), and
/// the edit's lattice: `rest`, and as solved.
void record(EditReport& er, const Lattice& rest, const ConstraintSolution& solution, const std::vector<Constraint>& constraints, const std::vector<int>& owner,
            int steps, double h) {
    er.lattice_size = solution.lattice.size();
    er.lattice_rest = rest.points();
    er.lattice_solved = solution.lattice.points();
    er.least_squares = solution.least_squares;
    er.rank = solution.rank;
    er.unknowns = solution.unknowns;
    // How much further the lattice moves than the user asked: the largest control-point motion over the largest
    // move's (this step's share of it). Near 1 for an ordinary edit; far above where targets close together go
    // different ways, and the map then stretches space steeply between them.
    double asked = 0, moved = 0;
    for (const Constraint& c : constraints)
        if (c.kind == ConstraintKind::move) asked = std::max(asked, (c.to - c.point).norm() / steps);
    for (std::size_t i = 0; i < er.lattice_rest.size() && i < er.lattice_solved.size(); ++i) moved = std::max(moved, (er.lattice_solved[i] - er.lattice_rest[i]).norm());
    er.control_motion_ratio = asked > 0 ? moved / asked : 0;
    std::vector<double> worst(constraints.size(), 0.0);
    for (std::size_t r = 0; r < owner.size(); ++r) worst[std::size_t(owner[r])] = std::max(worst[std::size_t(owner[r])], solution.residuals[r]);
    const double length = solution.lattice.spacing().mean(); // a turn row's scale (constraint_rows)
    for (std::size_t c = 0; c < constraints.size(); ++c) {
        // A step's residual recurs in every step of the edit: report the edit's total.
        const double r = worst[c] * steps;
        ConstraintReport cr;
        cr.name = constraints[c].name, cr.kind = kind_name(constraints[c].kind), cr.entry = constraints[c].entry, cr.residual = r, cr.residual_voxels = r / h;
        if (constraints[c].kind == ConstraintKind::turn || constraints[c].kind == ConstraintKind::normal) // |J d - R d|: the chord of the angle
            cr.residual_degrees = 2 * std::asin(std::min(1.0, worst[c] / length / 2)) * 180 / M_PI * steps;
        er.constraints.push_back(std::move(cr));
    }
}

/// The 0.5 isosurface of `voxmap` within about `reach` voxels of a world point. Marching cubes is local to each
/// cell, so meshing a window around the point gives the very faces the whole voxmap's extraction has there; faces
/// the window's own border closes are left out.
TriangleMesh isosurface_near(const SparseVoxmap& voxmap, const Eigen::Vector3d& point, double reach) {
    const double h = voxmap.voxel_size();
    const Eigen::Vector3d centre = voxmap.index_of(point);
    const std::int64_t half = std::int64_t(std::ceil(reach)) + 2;
    std::array<std::int64_t, 3> lo{}, dims{};
    for (int a = 0; a < 3; ++a) {
        lo[std::size_t(a)] = std::int64_t(std::floor(centre[a])) - half;
        dims[std::size_t(a)] = 2 * half + 2;
    }
    Voxmap window;
    window.dims = dims;
    window.voxel_size = h;
    window.origin = voxmap.world(double(lo[0]), double(lo[1]), double(lo[2]));
    window.density.resize(std::size_t(dims[0] * dims[1] * dims[2]));
    for (std::int64_t k = 0; k < dims[2]; ++k)
        for (std::int64_t j = 0; j < dims[1]; ++j)
            for (std::int64_t i = 0; i < dims[0]; ++i)
                window.density[std::size_t(i + dims[0] * (j + dims[1] * k))] = voxmap.at(lo[0] + i, lo[1] + j, lo[2] + k);
    TriangleMesh mesh = extract(window, {.mesher = Mesher::marching_cubes}); // where the voxmap's own 0.5 level lies
    // Keep faces whose vertices all lie inside the window's grid: the others close the surface at its border.
    TriangleMesh inner;
    inner.vertices = mesh.vertices;
    const Eigen::Vector3d first = window.origin, last = window.world(double(dims[0] - 1), double(dims[1] - 1), double(dims[2] - 1));
    auto inside = [&](std::int32_t v) {
        const Eigen::Vector3d& p = mesh.vertices[std::size_t(v)];
        return (p.array() >= first.array()).all() && (p.array() <= last.array()).all();
    };
    for (const auto& t : mesh.triangles)
        if (inside(t[0]) && inside(t[1]) && inside(t[2])) inner.triangles.push_back(t);
    return inner;
}

/// Distance from a world point to the 0.5 isosurface of `voxmap`, voxels, looking no farther than `reach` voxels
/// (+infinity beyond).
double distance_to_isosurface(const SparseVoxmap& voxmap, const Eigen::Vector3d& point, double reach) {
    const TriangleMesh inner = isosurface_near(voxmap, point, reach);
    if (inner.triangles.empty()) return std::numeric_limits<double>::infinity();
    return distances_to_surface_within({point}, inner, reach * voxmap.voxel_size())[0] / voxmap.voxel_size();
}

constexpr double kMissReach = 16; // voxels: misses beyond this are reported as "more than 16"

/// The voxmap's surface nearest to a point (its isosurface near it).
NearestSurface nearest_of(const SparseVoxmap& voxmap) {
    return [&voxmap](const Eigen::Vector3d& point) -> std::pair<Eigen::Vector3d, Eigen::Vector3d> {
        const TriangleMesh near = isosurface_near(voxmap, point, kMissReach);
        if (near.triangles.empty()) return {point, Eigen::Vector3d::Zero()};
        return nearest_on(SourceSurface(near), point, kMissReach * voxmap.voxel_size(), voxmap.voxel_size());
    };
}

/// Where the moves start, measured on the voxmap an edit starts from (before the warp consumes it): how far each
/// point lies from its surface, and whether the feature under it is missing from the voxmap (no voxel within a
/// voxel of the point reaches 0.5). Per constraint: {distance in voxels (-1 for other kinds), thin}.
std::vector<std::pair<double, bool>> measure_sources(const std::vector<Constraint>& constraints, const SparseVoxmap& before) {
    std::vector<std::pair<double, bool>> out(constraints.size(), {-1.0, false});
    for (std::size_t c = 0; c < constraints.size(); ++c) {
        if (constraints[c].kind != ConstraintKind::move) continue;
        const Eigen::Vector3d centre = before.index_of(constraints[c].point);
        float densest = 0;
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) densest = std::max(densest, before.sample(centre + Eigen::Vector3d(dx, dy, dz)));
        out[c] = {distance_to_isosurface(before, constraints[c].point, kMissReach), densest < 0.5f};
    }
    return out;
}

/// The part of `parts` lost by `stage` whose bounds, grown by `margin`, hold the point, or null.
const ThinPart* lost_under(const Eigen::Vector3d& point, const std::vector<ThinPart>& parts, const std::string& stage, double margin) {
    for (const auto& p : parts)
        if (p.stage == stage && (point.array() >= p.lo.array() - margin).all() && (point.array() <= p.hi.array() + margin).all()) return &p;
    return nullptr;
}

/// "0.73 voxels", or "more than 16 voxels" for a distance measured as none within kMissReach (infinite).
std::string voxels_off(double voxels) {
    char text[64];
    if (std::isfinite(voxels)) std::snprintf(text, sizeof text, "%.2f voxels", voxels);
    else std::snprintf(text, sizeof text, "more than %g voxels", kMissReach);
    return text;
}

/// Why the surface misses a move's target by more than half a voxel, where the measures tell; `parts` are the
/// thin parts lost, once known, `stage` this edit's name among them, `h` the voxel size.
void explain_misses(EditReport& er, const std::vector<Constraint>& constraints, double h, const std::vector<ThinPart>& parts = {},
                    const std::string& stage = {}) {
    for (std::size_t c = 0; c < er.constraints.size(); ++c) {
        ConstraintReport& cr = er.constraints[c];
        cr.miss_cause.clear();
        if (cr.kind != "move" || !(cr.surface_miss_voxels > 0.5)) continue;
        char text[240];
        const bool on_model = cr.model_miss_voxels >= 0 && cr.model_miss_voxels <= 0.5;
        if (cr.residual_voxels > 0.5) {
            std::snprintf(text, sizeof text, "the constraints conflict: the lattice map itself misses by %.2f voxels (least squares)", cr.residual_voxels);
        } else if (cr.model_miss_voxels > 0.5) {
            std::snprintf(text, sizeof text, "the point lies %s off the model's surface: the edit takes the point, not the surface, to the target",
                          voxels_off(cr.model_miss_voxels).c_str());
        } else if (on_model && cr.source_thin) {
            std::snprintf(text, sizeof text, "the point lies on a feature thinner than a voxel, which the voxmap does not hold; raise the resolution");
        } else if (on_model && cr.source_miss_voxels > 0.25) {
            std::snprintf(text, sizeof text,
                          "the point lies %.2f voxels off the voxelized surface (a sharp tip or edge the voxmap rounds off), and the edit carries that offset along",
                          cr.source_miss_voxels);
        } else if (const ThinPart* part = lost_under(constraints[c].to, parts, stage, 1.5 * h)) {
            std::snprintf(text, sizeof text, "the edit squeezes the part there to %.2f voxel, and the voxmap loses it (see thin parts)", part->thickness_voxels);
        } else if (cr.source_miss_voxels > 0.5) {
            std::snprintf(text, sizeof text, "the point lies %s off the surface the edit starts from", voxels_off(cr.source_miss_voxels).c_str());
        } else {
            continue;
        }
        cr.miss_cause = text;
    }
}

/// Surface misses of one edit's move constraints against the voxmap it produced.
void measure_targets(EditReport& er, const std::vector<Constraint>& constraints, const SparseVoxmap& after) {
    for (std::size_t c = 0; c < constraints.size(); ++c)
        if (constraints[c].kind == ConstraintKind::move) er.constraints[c].surface_miss_voxels = distance_to_isosurface(after, constraints[c].to, kMissReach);
}

/// The edits of deform_voxmap; `model` (the input mesh, or null) tells how far the first edit's points lie from it.
/// `probe`, when given, goes with the space through every step and is checked after each edit.
SparseVoxmap run_edits(SparseVoxmap voxmap, const EditScript& script, const DeformOptions& options, DeformReport& report, const TriangleMesh* model,
                       FeatureSurface* features = nullptr, SurfaceProbe* probe = nullptr, std::vector<WarpStep>* steps = nullptr) {
    Progress progress(options.progress, "deform");
    // This run's edits only: a report passed in again (a second deform into one report) held the last run's, and
    // explaining misses read past this script's edits.
    report.edits.clear();
    report.seconds_solve = report.seconds_warp = 0;
    report.voxel_size = voxmap.voxel_size();
    report.dims = voxmap.dims();
    report.volume_before = enclosed_volume(voxmap);
    // The warp's sums (8 bytes a voxel, in blocks over the band's image) take about three times the voxmap's own.
    require_memory(3 * voxmap.bytes(), options.voxelize.max_memory_bytes, "warping a voxmap of " + std::to_string(voxmap.bytes() >> 20) + " MiB");
    const double h = voxmap.voxel_size();
    for (std::size_t e = 0; e < script.edits.size(); ++e) {
        const Edit& edit = script.edits[e];
        const auto& constraints = edit.constraints;
        const auto& n = voxmap.dims();
        const Eigen::Vector3d lo = voxmap.origin(), hi = voxmap.world(double(n[0] - 1), double(n[1] - 1), double(n[2] - 1));
        check_near(constraints, lo, hi, options.far_fraction);
        std::vector<int> owner;
        const std::vector<Constraint> rows = expand_entries(constraints, material_of(voxmap), nearest_of(voxmap), kPlateReach * h, owner);
        EditReport er;
        er.solver = to_string(edit.solver);
        er.preserve_volume = edit.preserve_volume;
        er.volume_before = enclosed_volume(voxmap);
        const auto sources = measure_sources(constraints, voxmap);
        auto t = Clock::now();
        WarpDomain domain = make_domain(std::move(voxmap), script.lattice, options.voxelize.max_memory_bytes); // refilled by the warp below
        ConstraintSolution solution;
        if (edit.solver == Solver::rigid) {
            // One solve, one warp: the rigid answer holds for the whole edit (steps along straight lines would
            // shorten a bend's chord), and its own energy keeps the map from folding; what folds remains is reported.
            RigidSolution rs = solve_rigid(domain.lattice, rows, lattice_material(domain),
                                           {.rigid = true, .preserve_volume = edit.preserve_volume, .progress = options.progress});
            er.iterations = rs.iterations;
            solution = std::move(rs);
            er.steps = 1;
        } else {
            er.steps = plan_steps(domain, rows, edit.preserve_volume, options, solution, er.folds_remain, er.iterations);
        }
        record(er, domain.lattice, solution, constraints, owner, er.steps, h);
        er.seconds_solve += seconds_since(t);
        for (std::size_t c = 0; c < constraints.size(); ++c) {
            std::tie(er.constraints[c].source_miss_voxels, er.constraints[c].source_thin) = sources[c];
            if (model && e == 0 && constraints[c].kind == ConstraintKind::move)
                er.constraints[c].model_miss_voxels = distances_to_surface_within({constraints[c].point}, *model, kMissReach * h)[0] / h;
        }
        for (int s = 0; s < er.steps; ++s) {
            if (s > 0) {
                t = Clock::now();
                domain = make_domain(std::move(voxmap), script.lattice, options.voxelize.max_memory_bytes);
                solution = solve_min_norm(domain, step_constraints(rows, s, er.steps), edit.preserve_volume, options.progress, er.iterations);
                er.seconds_solve += seconds_since(t);
            }
            if (s + 1 == er.steps) {
                const auto folds = find_folds(solution.lattice);
                er.folded_regions = int(folds.size());
                er.folds_remain = !folds.empty();
            }
            t = Clock::now();
            progress.stage("warp edit " + std::to_string(e + 1) + "/" + std::to_string(script.edits.size()) +
                           (er.steps > 1 ? " step " + std::to_string(s + 1) + "/" + std::to_string(er.steps) : ""));
            if (features) push_feature_surface(domain.lattice, solution.lattice, *features); // the sharp parts go with the space
            if (probe) probe->push(domain.lattice, solution.lattice, int(e));
            if (steps) steps->push_back({domain.lattice, solution.lattice});
            voxmap = warp(std::move(domain), solution.lattice,
                          {.preview = options.preview, .max_memory_bytes = options.voxelize.max_memory_bytes, .progress = options.progress});
            report.seconds_warp += seconds_since(t);
            progress.report(double(s + 1) / er.steps);
        }
        report.seconds_solve += er.seconds_solve;
        er.volume_after = enclosed_volume(voxmap);
        if (probe) probe->check(voxmap, int(e));
        measure_targets(er, constraints, voxmap);
        explain_misses(er, constraints, h);
        report.edits.push_back(std::move(er));
    }
    report.volume_after = enclosed_volume(voxmap);
    return voxmap;
}

} // namespace deform_internal

using namespace deform_internal;

SparseVoxmap deform_voxmap(SparseVoxmap voxmap, const EditScript& script, const DeformOptions& options, DeformReport& report) {
    return run_edits(std::move(voxmap), script, options, report, nullptr);
}

namespace deform_internal {

std::uint64_t snapping_estimate(const TriangleMesh& mesh, const DeformOptions& options, double area, double feature_bytes);

// Both halves of deform_mesh, also used by DeformSession (session.cpp), which keeps the voxelization. `estimate`:
// deform_memory_estimate's, refused up front when above the limit.
SparseVoxmap voxelize_for_deform(const TriangleMesh& mesh, const VoxelizeOptions& options, const ProgressCallback& progress, VoxelizeReport* report,
                                 std::uint64_t estimate) {
    VoxelizeOptions vo = options;
    vo.progress = progress;
    vo.report = report;
    const Voxmap frame = voxelize_frame(mesh, vo);
    require_memory(estimate, vo.max_memory_bytes,
                   "deforming at " + std::to_string(frame.dims[0]) + "x" + std::to_string(frame.dims[1]) + "x" + std::to_string(frame.dims[2]));
    return voxelize_sparse(mesh, vo);
}

TriangleMesh deform_voxelized(const TriangleMesh& mesh, SparseVoxmap voxmap, const EditScript& script, const DeformOptions& options, DeformReport& report,
                              const SourceSurface* surface = nullptr) {
    report.mode = "volume";
    // The feature mesher's Hermite data: the input around its sharp edges, carried through every warp.
    FeatureSurface features;
    const bool sharpen = options.extract.mesher == Mesher::features && options.extract.adaptivity == 0 && !options.extract.quads;
    if (sharpen) features = sharp_feature_surface(mesh, voxmap.voxel_size(), options.extract.feature_angle);
    if (sharpen && report.memory_estimate_bytes > 0) {
        // What the feature mesher adds depends on the input's sharp edges, known only now: its share goes to the
        // snapping phase of the estimate made up front, checked before the warp and extraction against the memory
        // still to come (a session's later calls, on a voxmap it kept, were checked on their first).
        const double bytes = 24.0 * double(features.faces.vertices.size()) + 12.0 * double(features.faces.triangles.size()) + 48.0 * double(features.edges.size());
        report.memory_estimate_bytes = std::max(report.memory_estimate_bytes, snapping_estimate(mesh, options, surface_voxels(mesh, options.voxelize), bytes));
        const std::uint64_t now = resident_bytes(), held = now > report.resident_bytes_at_start ? now - report.resident_bytes_at_start : 0;
        const std::uint64_t limit = options.voxelize.max_memory_bytes;
        require_memory(limit ? report.memory_estimate_bytes : report.memory_estimate_bytes - std::min(held, report.memory_estimate_bytes), limit,
                       "the feature mesher at " + std::to_string(voxmap.dims()[0]) + "x" + std::to_string(voxmap.dims()[1]) + "x" + std::to_string(voxmap.dims()[2]));
    }
    // Surface the voxmap loses, on voxelizing and in each edit.
    SurfaceProbe probe(mesh, voxmap.voxel_size());
    probe.check(voxmap, SurfaceProbe::kVoxelize);
    std::vector<WarpStep> steps;
    voxmap = run_edits(std::move(voxmap), script, options, report, &mesh, sharpen && !features.empty() ? &features : nullptr, &probe, &steps);
    report.thin_parts = probe.parts(options.voxelize.voxel_size > 0 ? bounds(mesh).size().maxCoeff() : options.voxelize.resolution * report.voxel_size);
    auto t = Clock::now();
    ExtractOptions eo = options.extract;
    eo.progress = options.progress;
    if (sharpen && !features.empty()) eo.feature_surface = &features;
    // A smooth warp makes no sharp part the input lacks: without sharp edges in the input there is nothing to put
    // back (and the density's own corners, where a model is thinner than a voxel, are not the model's).
    if (sharpen && features.empty()) eo.mesher = Mesher::marching_cubes;
    TriangleMesh out = extract(voxmap, eo);
    SnapOptions so{.voxel_size = voxmap.voxel_size()};
    std::unique_ptr<SourceSurface> own_surface; // the input indexed once for snapping and transfer both
    auto input_surface = [&]() -> const SourceSurface& {
        if (!surface && !own_surface) own_surface = std::make_unique<SourceSurface>(mesh);
        return surface ? *surface : *own_surface;
    };
    // Move targets whose points lie on the input's surface: the output passes through their images (a target is
    // the exact image of its point after its edit, so this is the snap's own answer there, where no source falls).
    // Edit e's target goes back through the steps up to its own, and forward through all.
    if (options.snap)
        for (std::size_t e = 0, done = 0; e < script.edits.size() && e < report.edits.size(); ++e) {
            done += std::size_t(std::max(0, report.edits[e].steps));
            const std::vector<WarpStep> upto(steps.begin(), steps.begin() + std::ptrdiff_t(std::min(done, steps.size())));
            for (const auto& c : script.edits[e].constraints) {
                if (c.kind != ConstraintKind::move) continue;
                const auto at_input = pull_back(upto, c.to, nullptr);
                if (at_input && input_surface().nearest(*at_input, Eigen::Vector3d::Zero(), 0.1 * so.voxel_size).face >= 0) so.anchors.push_back(*at_input);
            }
        }
    auto find = [&](const TriangleMesh& m) { return find_sources(m, input_surface(), steps, so); };
    std::vector<SourcePoint> sources;
    if (options.snap && out.face_count() > 0) {
        const auto ts = Clock::now();
        RefineOptions ro{.steep_crossings = eo.mesher == Mesher::features, .put_back_crossings = eo.mesher == Mesher::features};
        // No triangle of marching cubes' was seen crossing another after snapping: the search looks near the
        // feature mesher's own vertices (at 256 on the bunny ear edit, about 120 ms over the whole output).
        if (ro.put_back_crossings) ro.crossings_near = off_grid_vertices(out, voxmap);
        const SnapReport sr = snap_and_refine(out, input_surface(), steps, sources, so, ro); // finds the sources too
        report.snap = true;
        report.refined_vertices = sr.refined;
        report.put_back_vertices = sr.put_back;
        report.snapped_vertices = sr.snapped;
        report.unsnapped_vertices = sr.unsnapped;
        report.partly_snapped_vertices = sr.partly_snapped;
        report.seconds_snap = seconds_since(ts);
    }
    if (options.target_faces > 0) out = decimate(out, options.target_faces), sources.clear();
    if (options.attributes && mesh.has_attributes() && out.face_count() > 0) {
        const auto tt = Clock::now();
        if (!out.quads.empty()) out = out.triangulated(), sources.clear();
        if (sources.empty()) sources = find(out);
        report.triangles_across_charts = transfer_attributes(out, input_surface(), sources, steps).triangles_across_charts;
        report.attributes = true;
        report.seconds_transfer = seconds_since(tt);
    }
    report.seconds_extract = seconds_since(t);
    if (out.face_count() == 0) {
        const auto warnings = deform_warnings(report); // the thin parts' come last
        throw InvalidInput("deform: the deformed volume has no surface left" +
                           (report.thin_parts.empty() ? std::string(" (was the model thinner than a voxel?)") : ": " + warnings.back()));
    }
    // The last edit's misses against the surface the user gets (decimated or quads included).
    if (!report.edits.empty()) {
        EditReport& last = report.edits.back();
        const auto& constraints = script.edits.back().constraints;
        const double h = report.voxel_size;
        for (std::size_t c = 0; c < constraints.size(); ++c)
            if (constraints[c].kind == ConstraintKind::move) {
                const double d = distances_to_surface_within({constraints[c].to}, out, kMissReach * h)[0] / h;
                last.constraints[c].surface_miss_voxels = d;
            }
    }
    for (std::size_t e = 0; e < report.edits.size(); ++e)
        explain_misses(report.edits[e], script.edits[e].constraints, report.voxel_size, report.thin_parts, "edits[" + std::to_string(e) + "]");
    report.volume_before = enclosed_volume(mesh.quads.empty() ? mesh : mesh.triangulated());
    report.volume_after = enclosed_volume(out.quads.empty() ? out : out.triangulated());
    report.output_vertices = out.vertices.size();
    report.output_faces = out.face_count();
    return out;
}

} // namespace deform_internal

namespace {

/// Whether deform_mesh builds the input's tree (SourceSurface) for snapping or carrying attributes.
bool wants_source_surface(const TriangleMesh& mesh, const DeformOptions& options) {
    return (options.snap || (options.attributes && mesh.has_attributes())) && mesh.face_count() > 0;
}

// Measured peaks over the resident memory at the start (docs/benchmarks.md, Memory): the snapping tree peaks at
// 392-396 bytes a face while CGAL builds it (276-360 once built); the warp and extraction at about 16 MiB
// (allocator arenas and thread stacks; 20 counted, room for other machines' allocators) and 500-560 bytes per voxel
// of the input's area (the voxmap's blocks in and out, the warp's 8-byte sums, the output mesh); snapping at up to
// 853 per voxel of area (the scan at 128: two sheets, refinement), 520-600 on the bunny. Voxelizing's temporaries
// are gone before the warp begins, the warp's before snapping, so the phases' largest counts, the tree beside each.
constexpr double kArenas = 20.0 * 1024 * 1024, kTreePerFace = 400, kWarpPerVoxel = 560, kSnapPerVoxel = 950;

double tree_bytes(const TriangleMesh& mesh, const DeformOptions& options) {
    return wants_source_surface(mesh, options) ? kTreePerFace * double(mesh.face_count()) : 0.0;
}

} // namespace

namespace deform_internal {

/// deform_memory_estimate's last phase, extracting and snapping with the tree beside it, for an input of `area`
/// voxels of area (surface_voxels); with the feature mesher's Hermite data once known (`feature_bytes`, its
/// vertices, triangles and edges), six times that more (the bundled scan at 128 / 256: 48 / 63 MiB over marching
/// cubes' peak for 9.7 / 19.0 MiB of it).
std::uint64_t snapping_estimate(const TriangleMesh& mesh, const DeformOptions& options, double area, double feature_bytes) {
    return std::uint64_t((wants_source_surface(mesh, options) ? kArenas + kSnapPerVoxel * area : 0.0) + 6 * feature_bytes + tree_bytes(mesh, options));
}

} // namespace deform_internal

std::uint64_t deform_memory_estimate(const TriangleMesh& mesh, const DeformOptions& options) {
    const double area = surface_voxels(mesh, options.voxelize);
    const double voxelizing = double(voxelize_memory_estimate(mesh, options.voxelize, true)), warping = kArenas + kWarpPerVoxel * area;
    return std::max(std::uint64_t(std::max(voxelizing, warping) + tree_bytes(mesh, options)), snapping_estimate(mesh, options, area, 0));
}

TriangleMesh deform_mesh(const TriangleMesh& mesh, const EditScript& script, const DeformOptions& options, DeformReport& report) {
    const auto t = Clock::now();
    // The input's tree for snapping and transfer, built beside voxelizing: CGAL builds it on one core, 1.2 s for
    // a scan of 600,000 faces (0.05 s for the bundled one of 37,600), while voxelizing leaves a core idle at times.
    // That scan's deform at 256 took 15.2 s, now 12.8-13.6; the tree now adds to voxelizing's peak memory (405 ->
    // 466 MiB there), where it was built after, and the estimate counts it beside every phase.
    std::unique_ptr<SourceSurface> surface;
    tbb::task_group beside;
    report.resident_bytes_at_start = resident_bytes();
    report.memory_estimate_bytes = deform_memory_estimate(mesh, options);
    if (wants_source_surface(mesh, options))
        beside.run([&] {
            try {
                surface = std::make_unique<SourceSurface>(mesh);
            } catch (const std::exception&) { // (a mesh without a face with area: the error comes where snapping begins, as before)
                surface.reset();
            }
        });
    VoxelizeReport voxelized;
    SparseVoxmap voxmap;
    try {
        voxmap = voxelize_for_deform(mesh, options.voxelize, options.progress, &voxelized, report.memory_estimate_bytes);
    } catch (...) {
        beside.wait();
        throw;
    }
    report.seconds_voxelize = seconds_since(t);
    beside.wait();
    report.sign = to_string(voxelized.sign);
    report.sign_note = voxelized.note;
    return deform_voxelized(mesh, std::move(voxmap), script, options, report, surface.get());
}

namespace {

/// Vertex mode's normals: each corner's carried through `step` at its vertex (before the vertex moves). Corners of one
/// vertex that shared a normal share it still; one normal shared by several vertices (a flat face's) becomes one
/// per vertex, since the map turns it differently at each.
void push_corner_normals(TriangleMesh& mesh, const std::vector<WarpStep>& step) {
    if (mesh.triangle_normals.empty()) return;
    std::unordered_map<std::uint64_t, std::int32_t> index;
    std::vector<std::pair<std::int32_t, std::int32_t>> pairs; // (vertex, old normal) of each new normal
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
        for (std::size_t c = 0; c < 3; ++c) {
            std::int32_t& n = mesh.triangle_normals[f][c];
            if (n < 0) continue;
            const std::int32_t v = mesh.triangles[f][c];
            const auto [it, added] = index.try_emplace((std::uint64_t(std::uint32_t(v)) << 32) | std::uint32_t(n), std::int32_t(pairs.size()));
            if (added) pairs.emplace_back(v, n);
            n = it->second;
        }
    std::vector<Eigen::Vector3d> normals(pairs.size());
    tbb::parallel_for(std::size_t(0), pairs.size(), [&](std::size_t i) {
        normals[i] = push_normal(step, mesh.vertices[std::size_t(pairs[i].first)], mesh.normals[std::size_t(pairs[i].second)]);
    });
    mesh.normals = std::move(normals);
}

} // namespace

TriangleMesh deform_vertices(const TriangleMesh& mesh, const EditScript& script, const DeformOptions& options, DeformReport& report) {
    TriangleMesh out = mesh;
    report.mode = "vertex";
    report.edits.clear(); // this run's edits only, as run_edits
    report.seconds_solve = 0;
    for (std::size_t e = 0; e < script.edits.size(); ++e) {
        const Edit& edit = script.edits[e];
        const auto& constraints = edit.constraints;
        // The same lattice the volume mode builds: over the voxel frame the mesh would be voxelized into.
        Voxmap frame = voxelize_frame(out, options.voxelize);
        if (e == 0) report.voxel_size = frame.voxel_size, report.dims = frame.dims, report.volume_before = enclosed_volume(out);
        const Eigen::Vector3d lo = frame.origin, hi = frame.world(double(frame.dims[0] - 1), double(frame.dims[1] - 1), double(frame.dims[2] - 1));
        check_near(constraints, lo, hi, options.far_fraction);
        std::vector<int> owner;
        std::unique_ptr<SourceSurface> surface; // indexed only when an entry asks for the surface
        const std::vector<Constraint> rows = expand_entries(constraints, material_of(out), [&](const Eigen::Vector3d& p) {
            if (!surface) surface = std::make_unique<SourceSurface>(out);
            return nearest_on(*surface, p, kMissReach * frame.voxel_size, frame.voxel_size);
        }, kPlateReach * frame.voxel_size, owner);
        EditReport er;
        er.solver = to_string(edit.solver);
        er.preserve_volume = edit.preserve_volume;
        const auto t = Clock::now();
        ConstraintSolution solution;
        Lattice rest;
        if (edit.solver == Solver::rigid || edit.preserve_volume) {
            // Both need the material: voxelize the current shape into its frame.
            VoxelizeOptions vo = options.voxelize;
            vo.progress = options.progress;
            const WarpDomain domain = make_domain(voxelize_sparse(out, vo), script.lattice, options.voxelize.max_memory_bytes);
            RigidSolution rs = solve_rigid(domain.lattice, rows, lattice_material(domain),
                                           {.rigid = edit.solver == Solver::rigid, .preserve_volume = edit.preserve_volume, .progress = options.progress});
            er.iterations = rs.iterations;
            solution = std::move(rs);
            rest = domain.lattice;
        } else {
            const WarpDomain domain = make_domain(SparseVoxmap(frame.dims, frame.origin, frame.voxel_size), script.lattice, options.voxelize.max_memory_bytes);
            // Vertex mode applies the whole edit as one map: moving vertices needs no injective steps.
            solution = solve_constraints(domain.lattice, rows);
            rest = domain.lattice;
        }
        er.seconds_solve = seconds_since(t);
        report.seconds_solve += er.seconds_solve;
        const auto folds = find_folds(solution.lattice);
        er.folds_remain = !folds.empty();
        er.folded_regions = int(folds.size());
        record(er, rest, solution, constraints, owner, 1, frame.voxel_size);
        er.volume_before = enclosed_volume(out);
        push_corner_normals(out, {{rest, solution.lattice}});
        for (auto& v : out.vertices) v = solution.lattice.evaluate(rest.parameter_of(v));
        er.volume_after = enclosed_volume(out);
        report.edits.push_back(std::move(er));
    }
    report.volume_after = enclosed_volume(out);
    report.output_vertices = out.vertices.size();
    report.output_faces = out.face_count();
    return out;
}

} // namespace voxwarp
