#include "pipeline.h"

#include <voxwarp/decimate.h>
#include <voxwarp/errors.h>
#include <voxwarp/foldover.h>
#include <voxwarp/resources.h>

#include <chrono>
#include <cmath>

namespace voxwarp {

namespace pipeline_internal {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::string kind_name(ConstraintKind k) { return k == ConstraintKind::move ? "move" : k == ConstraintKind::pin ? "pin" : "control_point"; }

/// Refuse constraint points far from the model: the data box grown by far_fraction of its size.
void check_near(const std::vector<Constraint>& constraints, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double fraction) {
    const Eigen::Vector3d margin = fraction * (hi - lo);
    for (const auto& c : constraints) {
        if (c.kind == ConstraintKind::control_point) continue;
        if ((c.point.array() < (lo - margin).array()).any() || (c.point.array() > (hi + margin).array()).any())
            throw InvalidInput(c.name + ": point (" + std::to_string(c.point.x()) + ", " + std::to_string(c.point.y()) + ", " +
                               std::to_string(c.point.z()) + ") lies far outside the model (bounds " + std::to_string(lo.x()) + ".." +
                               std::to_string(hi.x()) + ", " + std::to_string(lo.y()) + ".." + std::to_string(hi.y()) + ", " +
                               std::to_string(lo.z()) + ".." + std::to_string(hi.z()) + ")");
    }
}

/// The constraints of step `s` of `steps`: moves advance by 1/steps of their way, offsets likewise.
std::vector<Constraint> step_constraints(const std::vector<Constraint>& constraints, int s, int steps) {
    std::vector<Constraint> out = constraints;
    for (auto& c : out) {
        if (c.kind == ConstraintKind::move) {
            const Eigen::Vector3d d = c.to - c.point;
            c.point = c.point + d * (double(s) / steps);
            c.to = c.point + d / steps;
        } else if (c.kind == ConstraintKind::control_point) {
            c.offset /= steps;
        }
    }
    return out;
}

/// Solve one edit on `rest`, splitting it into as many steps (up to max_steps) as keep the map injective.
/// Returns the step count; the solution is that of the first step.
int plan_steps(const Lattice& rest, const std::vector<Constraint>& constraints, int max_steps, ConstraintSolution& first, bool& folds_remain) {
    for (int steps = 1;; steps *= 2) {
        first = solve_constraints(rest, step_constraints(constraints, 0, steps));
        folds_remain = !find_folds(first.lattice).empty();
        if (!folds_remain || steps * 2 > max_steps) return steps;
    }
}

void record(EditReport& er, const ConstraintSolution& solution, const std::vector<Constraint>& constraints, int steps, double h) {
    er.least_squares = solution.least_squares;
    er.rank = solution.rank;
    er.unknowns = solution.unknowns;
    for (std::size_t c = 0; c < constraints.size(); ++c) {
        // A step's residual recurs in every step of the edit: report the edit's total.
        const double r = solution.residuals[c] * steps;
        er.constraints.push_back({constraints[c].name, kind_name(constraints[c].kind), r, r / h});
    }
}

} // namespace pipeline_internal

using namespace pipeline_internal;

SparseVoxmap deform_voxmap(SparseVoxmap voxmap, const EditScript& script, const DeformOptions& options, DeformReport& report) {
    Progress progress(options.progress, "deform");
    report.voxel_size = voxmap.voxel_size();
    report.dims = voxmap.dims();
    report.volume_before = enclosed_volume(voxmap);
    // The warp's sums (8 bytes a voxel, in blocks over the band's image) take about three times the voxmap's own.
    require_memory(3 * voxmap.bytes(), options.voxelize.max_memory_bytes, "warping a voxmap of " + std::to_string(voxmap.bytes() >> 20) + " MiB");
    const double h = voxmap.voxel_size();
    for (std::size_t e = 0; e < script.edits.size(); ++e) {
        const auto& constraints = script.edits[e].constraints;
        const auto& n = voxmap.dims();
        const Eigen::Vector3d lo = voxmap.origin(), hi = voxmap.world(double(n[0] - 1), double(n[1] - 1), double(n[2] - 1));
        check_near(constraints, lo, hi, options.far_fraction);
        EditReport er;
        auto t = Clock::now();
        WarpDomain domain = make_domain(std::move(voxmap), script.lattice, options.voxelize.max_memory_bytes); // refilled by the warp below
        ConstraintSolution solution;
        er.steps = plan_steps(domain.lattice, constraints, options.max_steps, solution, er.folds_remain);
        record(er, solution, constraints, er.steps, h);
        report.seconds_solve += seconds_since(t);
        for (int s = 0; s < er.steps; ++s) {
            if (s > 0) {
                t = Clock::now();
                domain = make_domain(std::move(voxmap), script.lattice, options.voxelize.max_memory_bytes);
                solution = solve_constraints(domain.lattice, step_constraints(constraints, s, er.steps));
                report.seconds_solve += seconds_since(t);
            }
            t = Clock::now();
            progress.stage("warp edit " + std::to_string(e + 1) + "/" + std::to_string(script.edits.size()) +
                           (er.steps > 1 ? " step " + std::to_string(s + 1) + "/" + std::to_string(er.steps) : ""));
            voxmap = warp(std::move(domain), solution.lattice, {.preview = options.preview, .progress = options.progress});
            report.seconds_warp += seconds_since(t);
            progress.report(double(s + 1) / er.steps);
        }
        report.edits.push_back(std::move(er));
    }
    report.volume_after = enclosed_volume(voxmap);
    return voxmap;
}

TriangleMesh deform_mesh(const TriangleMesh& mesh, const EditScript& script, const DeformOptions& options, DeformReport& report) {
    auto t = Clock::now();
    VoxelizeOptions vo = options.voxelize;
    vo.progress = options.progress;
    // Beside the voxmap, the warp keeps 8-byte sums in 8^3 blocks over the band's image (about 300 bytes per
    // voxel of surface area, measured on the bunny); the extracted mesh takes less than that.
    const Voxmap frame = voxelize_frame(mesh, vo);
    require_memory(voxelize_memory_estimate(mesh, vo, true) + std::uint64_t(300.0 * surface_voxels(mesh, vo)), vo.max_memory_bytes,
                   "deforming at " + std::to_string(frame.dims[0]) + "x" + std::to_string(frame.dims[1]) + "x" + std::to_string(frame.dims[2]));
    SparseVoxmap voxmap = voxelize_sparse(mesh, vo);
    report.seconds_voxelize = seconds_since(t);
    voxmap = deform_voxmap(std::move(voxmap), script, options, report);
    t = Clock::now();
    ExtractOptions eo = options.extract;
    eo.progress = options.progress;
    TriangleMesh out = extract(voxmap, eo);
    if (options.target_faces > 0) out = decimate(out, options.target_faces);
    report.seconds_extract = seconds_since(t);
    if (out.face_count() == 0) throw InvalidInput("deform: the deformed volume has no surface left (was the model thinner than a voxel?)");
    return out;
}

TriangleMesh deform_vertices(const TriangleMesh& mesh, const EditScript& script, const DeformOptions& options, DeformReport& report) {
    TriangleMesh out = mesh;
    for (std::size_t e = 0; e < script.edits.size(); ++e) {
        const auto& constraints = script.edits[e].constraints;
        // The same lattice the volume mode builds: over the voxel frame the mesh would be voxelized into.
        Voxmap frame = voxelize_frame(out, options.voxelize);
        if (e == 0) report.voxel_size = frame.voxel_size, report.dims = frame.dims, report.volume_before = enclosed_volume(out);
        const Eigen::Vector3d lo = frame.origin, hi = frame.world(double(frame.dims[0] - 1), double(frame.dims[1] - 1), double(frame.dims[2] - 1));
        check_near(constraints, lo, hi, options.far_fraction);
        const WarpDomain domain = make_domain(SparseVoxmap(frame.dims, frame.origin, frame.voxel_size), script.lattice, options.voxelize.max_memory_bytes);
        // Vertex mode applies the whole edit as one map: moving vertices needs no injective steps.
        EditReport er;
        const ConstraintSolution solution = solve_constraints(domain.lattice, constraints);
        er.folds_remain = !find_folds(solution.lattice).empty();
        record(er, solution, constraints, 1, frame.voxel_size);
        for (auto& v : out.vertices) v = solution.lattice.evaluate(domain.lattice.parameter_of(v));
        report.edits.push_back(std::move(er));
    }
    report.volume_after = enclosed_volume(out);
    return out;
}

} // namespace voxwarp
