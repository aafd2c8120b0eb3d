// The deform report as JSON (README "Reports") and the warnings a user should read.
#include <algorithm>
#include <voxwarp/deform.h>
#include <voxwarp/resources.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>

namespace voxwarp {

namespace {

/// volume_change_percent, null where there is none (it read as "+0.00 %").
nlohmann::json change_percent(double before, double after) {
    const auto percent = volume_change_percent(before, after);
    return percent ? nlohmann::json(*percent) : nlohmann::json(nullptr);
}

/// A distance for JSON: null when unmeasured (< 0) or beyond the measured reach (infinite).
nlohmann::json distance(double d) { return d >= 0 && std::isfinite(d) ? nlohmann::json(d) : nlohmann::json(nullptr); }

std::string method(const EditReport& e) {
    if (e.solver == "rigid") return "rigid: ARAP local/global iterations (Anderson-accelerated)";
    if (e.preserve_volume) return "least motion keeping the volume: local/global iterations (Anderson-accelerated)";
    return e.least_squares ? "weighted least squares (Ceres)" : "minimum-norm pseudoinverse";
}

} // namespace

std::optional<double> volume_change_percent(double before, double after) {
    if (!(before > 0)) return std::nullopt;
    return 100.0 * (after / before - 1.0);
}

std::string report_json(const DeformReport& r, const std::map<std::string, std::string>& fields) {
    nlohmann::json j;
    for (const auto& [key, value] : fields) j[key] = value;
    j["mode"] = r.mode;
    if (!r.sign.empty()) j["sign"] = r.sign;
    if (!r.sign_note.empty()) j["sign_note"] = r.sign_note;
    j["voxel_size"] = r.voxel_size;
    j["dims"] = {r.dims[0], r.dims[1], r.dims[2]};
    j["volume_before"] = r.volume_before;
    j["volume_after"] = r.volume_after;
    j["volume_change_percent"] = change_percent(r.volume_before, r.volume_after);
    j["seconds"] = {{"total", r.seconds_total}, {"read", r.seconds_read},       {"voxelize", r.seconds_voxelize}, {"solve", r.seconds_solve},
                    {"warp", r.seconds_warp},   {"extract", r.seconds_extract}, {"snap", r.seconds_snap},
                    {"transfer", r.seconds_transfer}, {"write", r.seconds_write}};
    j["peak_resident_bytes"] = peak_resident_bytes();
    if (r.memory_estimate_bytes) j["memory_estimate_bytes"] = r.memory_estimate_bytes;
    if (r.resident_bytes_at_start) j["resident_bytes_at_start"] = r.resident_bytes_at_start;
    j["output_vertices"] = r.output_vertices;
    j["output_faces"] = r.output_faces;
    if (r.mode == "volume") {
        j["snap"] = r.snap;
        j["snapped_vertices"] = r.snapped_vertices;
        j["unsnapped_vertices"] = r.unsnapped_vertices;
        j["partly_snapped_vertices"] = r.partly_snapped_vertices;
        j["refined_vertices"] = r.refined_vertices;
        j["put_back_vertices"] = r.put_back_vertices;
        j["attributes"] = r.attributes;
        if (r.attributes) j["triangles_across_charts"] = r.triangles_across_charts;
    }
    j["edits"] = nlohmann::json::array();
    for (const auto& e : r.edits) {
        nlohmann::json je;
        je["solver"] = e.solver;
        je["method"] = method(e);
        je["preserve_volume"] = e.preserve_volume;
        je["steps"] = e.steps;
        je["folds_remain"] = e.folds_remain;
        je["folded_regions"] = e.folded_regions;
        je["control_motion_ratio"] = e.control_motion_ratio;
        je["rank"] = e.rank;
        je["unknowns"] = e.unknowns;
        je["iterations"] = e.iterations;
        je["seconds_solve"] = e.seconds_solve;
        je["volume_before"] = e.volume_before;
        je["volume_after"] = e.volume_after;
        je["volume_change_percent"] = change_percent(e.volume_before, e.volume_after);
        je["constraints"] = nlohmann::json::array();
        // One entry per entry of the edit file: a frame's move and turns, a connect's two moves, as one.
        for (std::size_t i = 0; i < e.constraints.size();) {
            const ConstraintReport& c = e.constraints[i];
            std::size_t end = i + 1;
            if (!c.entry.empty())
                while (end < e.constraints.size() && e.constraints[end].name == c.name) ++end;
            nlohmann::json jc = {{"name", c.name}, {"kind", c.entry.empty() ? c.kind : c.entry}};
            double residual = 0, voxels = 0, degrees = -1;
            for (std::size_t k = i; k < end; ++k) {
                const ConstraintReport& row = e.constraints[k];
                if (row.kind == "turn") {
                    degrees = std::max(degrees, row.residual_degrees);
                    continue;
                }
                residual = std::max(residual, row.residual), voxels = std::max(voxels, row.residual_voxels);
            }
            jc["residual"] = residual, jc["residual_voxels"] = voxels;
            if (degrees >= 0) jc["residual_degrees"] = degrees;
            if (c.kind == "move") { // a frame's point, the first of a connect's
                jc["surface_miss_voxels"] = distance(c.surface_miss_voxels);
                jc["source_miss_voxels"] = distance(c.source_miss_voxels);
                if (c.model_miss_voxels >= 0) jc["model_miss_voxels"] = distance(c.model_miss_voxels);
                if (!c.miss_cause.empty()) jc["miss_cause"] = c.miss_cause;
            }
            je["constraints"].push_back(jc);
            i = end;
        }
        j["edits"].push_back(je);
    }
    j["thin_parts"] = nlohmann::json::array();
    for (const auto& p : r.thin_parts) {
        j["thin_parts"].push_back({{"stage", p.stage},
                                   {"centre", {p.centre.x(), p.centre.y(), p.centre.z()}},
                                   {"bounds", {{p.lo.x(), p.lo.y(), p.lo.z()}, {p.hi.x(), p.hi.y(), p.hi.z()}}},
                                   {"area_voxels", p.area_voxels},
                                   {"thickness_voxels", p.thickness_voxels},
                                   {"thickness_before_voxels", p.thickness_before_voxels},
                                   {"voxel_size_to_keep", p.voxel_size_to_keep},
                                   {"resolution_to_keep", p.resolution_to_keep > 0 ? nlohmann::json(p.resolution_to_keep) : nlohmann::json(nullptr)}});
    }
    return j.dump(2) + "\n";
}

/// EditReport::control_motion_ratio past which an edit is reported as stretching space steeply. The bundled
/// examples read 2-5 (a twist moves the lattice's far corners most); two targets a thousandth apart pulled half a
/// unit either way, 11,000, and the bunny came out 39 times its volume without a word.
constexpr double kSteepRatio = 50;

std::vector<std::string> deform_warnings(const DeformReport& r) {
    std::vector<std::string> out;
    char line[512];
    if (!r.sign_note.empty()) out.push_back("voxelize: " + r.sign_note);
    for (const auto& e : r.edits) {
        for (const auto& c : e.constraints) {
            if (c.kind == "turn" && c.residual_degrees > 1) {
                std::snprintf(line, sizeof line, "%s: the lattice map turns %.2f degrees away from the frame's rotation", c.name.c_str(), c.residual_degrees);
                out.emplace_back(line);
            } else if (c.kind != "turn" && c.residual_voxels > 0.5) {
                std::snprintf(line, sizeof line, "%s: the lattice map misses its target by %.3g (%.2f voxels)", c.name.c_str(), c.residual, c.residual_voxels);
                out.emplace_back(line);
            }
            if (c.kind == "move" && c.surface_miss_voxels > 0.5) {
                if (std::isfinite(c.surface_miss_voxels))
                    std::snprintf(line, sizeof line, "%s: the surface misses the target by %.2f voxels%s%s", c.name.c_str(), c.surface_miss_voxels,
                                  c.miss_cause.empty() ? "" : ": ", c.miss_cause.c_str());
                else
                    std::snprintf(line, sizeof line, "%s: no surface within 16 voxels of the target%s%s", c.name.c_str(), c.miss_cause.empty() ? "" : ": ",
                                  c.miss_cause.c_str());
                out.emplace_back(line);
            }
        }
        if (e.control_motion_ratio > kSteepRatio) {
            std::snprintf(line, sizeof line,
                          "edits[%zu] moves control points up to %.0f times as far as its farthest target moves: targets close together go "
                          "different ways, and the space between them stretches that steeply; move them apart or drop one",
                          std::size_t(&e - r.edits.data()), e.control_motion_ratio);
            out.emplace_back(line);
        }
        if (e.folds_remain && r.mode == "vertex")
            out.emplace_back("an edit folds the lattice map in " + std::to_string(e.folded_regions) + " region(s); vertex mode applies it as it is (surfaces may cross)");
        else if (e.folds_remain && e.solver == "rigid")
            out.emplace_back("a rigid edit folds the lattice map in " + std::to_string(e.folded_regions) +
                             " region(s) (det J <= 0): the constraints ask for more than a fold-free map gives; move them apart or add pins");
        else if (e.folds_remain)
            out.emplace_back("an edit still folds the lattice map after " + std::to_string(e.steps) + " steps; raise --max-steps");
    }
    for (const auto& p : r.thin_parts) {
        char keep[160];
        if (p.resolution_to_keep > 0)
            std::snprintf(keep, sizeof keep, "--resolution %lld (voxel size %.3g) would keep it", (long long)p.resolution_to_keep, p.voxel_size_to_keep);
        else
            std::snprintf(keep, sizeof keep, "a voxel size of %.3g would keep it, finer than any resolution voxwarp takes", p.voxel_size_to_keep);
        if (p.stage == "voxelize")
            std::snprintf(line, sizeof line, "a part %.2f voxel thick near (%.4g, %.4g, %.4g), %.0f voxels^2 of surface, is missing from the voxmap: %s",
                          p.thickness_voxels, p.centre.x(), p.centre.y(), p.centre.z(), p.area_voxels, keep);
        else
            std::snprintf(line, sizeof line, "%s thins a part near (%.4g, %.4g, %.4g) from %.2f to %.2f voxel and loses it (%.0f voxels^2 of surface): %s",
                          p.stage.c_str(), p.centre.x(), p.centre.y(), p.centre.z(), p.thickness_before_voxels, p.thickness_voxels, p.area_voxels, keep);
        out.emplace_back(line);
    }
    return out;
}

} // namespace voxwarp
