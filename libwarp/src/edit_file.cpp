#include <voxwarp/edit_file.h>
#include <voxwarp/errors.h>

#include <nlohmann/json.hpp>

#include <Eigen/Geometry>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace voxwarp {

namespace edit_file_internal {

using json = nlohmann::json;

struct Context {
    std::string source;
    [[noreturn]] void fail(const std::string& path, const std::string& what) const {
        throw InvalidInput(source + ": " + (path.empty() ? "" : path + ": ") + what);
    }
};

std::string describe(const json& v) {
    std::string s = v.dump();
    if (s.size() > 40) s = s.substr(0, 37) + "...";
    return s;
}

void only_keys(const Context& ctx, const json& object, const std::string& path, const std::set<std::string>& allowed) {
    for (const auto& [key, value] : object.items())
        if (!allowed.count(key)) {
            std::string list;
            for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
            ctx.fail(path.empty() ? key : path + "." + key, "unknown field; expected one of: " + list);
        }
}

const json& require(const Context& ctx, const json& object, const std::string& path, const std::string& key) {
    if (!object.contains(key)) ctx.fail(path, "missing field \"" + key + "\"");
    return object.at(key);
}

double finite_number(const Context& ctx, const json& v, const std::string& path) {
    if (!v.is_number()) ctx.fail(path, "expected a number, got " + describe(v));
    const double d = v.get<double>();
    if (!std::isfinite(d)) ctx.fail(path, "expected a finite number, got " + describe(v));
    return d;
}

Eigen::Vector3d point3(const Context& ctx, const json& v, const std::string& path) {
    if (!v.is_array() || v.size() != 3) ctx.fail(path, "expected an array of three finite numbers, got " + describe(v));
    Eigen::Vector3d p;
    for (int a = 0; a < 3; ++a) p[a] = finite_number(ctx, v[std::size_t(a)], path + "[" + std::to_string(a) + "]");
    return p;
}

int integer(const Context& ctx, const json& v, const std::string& path) {
    if (!v.is_number_integer()) ctx.fail(path, "expected an integer, got " + describe(v));
    const auto i = v.get<std::int64_t>();
    if (i < -(1 << 30) || i > (1 << 30)) ctx.fail(path, "integer " + describe(v) + " is out of range");
    return int(i);
}

LatticeSpec parse_lattice(const Context& ctx, const json& v) {
    const std::string path = "lattice";
    if (!v.is_object()) ctx.fail(path, "expected an object, got " + describe(v));
    only_keys(ctx, v, path, {"size", "placement", "padding"});
    LatticeSpec spec;
    if (v.contains("placement")) {
        const json& p = v["placement"];
        if (!p.is_string() || (p != "uniform" && p != "clamped")) ctx.fail(path + ".placement", "expected \"uniform\" or \"clamped\", got " + describe(p));
        spec.placement = placement_from_string(p.get<std::string>());
    }
    const int minimum = spec.placement == Placement::clamped ? 6 : 4;
    if (v.contains("size")) {
        const json& s = v["size"];
        if (s.is_number_integer()) {
            const int n = integer(ctx, s, path + ".size");
            spec.size = {n, n, n};
        } else if (s.is_array() && s.size() == 3) {
            for (int a = 0; a < 3; ++a) spec.size[std::size_t(a)] = integer(ctx, s[std::size_t(a)], path + ".size[" + std::to_string(a) + "]");
        } else {
            ctx.fail(path + ".size", "expected an integer or an array of three integers, got " + describe(s));
        }
        for (int a = 0; a < 3; ++a)
            if (spec.size[std::size_t(a)] < minimum || spec.size[std::size_t(a)] > 64)
                ctx.fail(path + ".size", "control points per axis must be in [" + std::to_string(minimum) + ", 64] for the " +
                                             to_string(spec.placement) + " placement, got " + describe(s));
    }
    if (v.contains("padding")) {
        spec.padding = finite_number(ctx, v["padding"], path + ".padding");
        if (spec.padding < 0 || spec.padding > 4) ctx.fail(path + ".padding", "expected a fraction of the model's size in [0, 4], got " + describe(v["padding"]));
    }
    return spec;
}

/// A rotation: {"axis": [x, y, z], "degrees": a} (and, where `pivot` is given, "pivot": p, default `pivot`).
Eigen::Matrix3d parse_rotation(const Context& ctx, const json& v, const std::string& path, Eigen::Vector3d* pivot = nullptr) {
    if (!v.is_object()) ctx.fail(path, "expected an object with \"axis\" and \"degrees\", got " + describe(v));
    if (pivot) only_keys(ctx, v, path, {"axis", "degrees", "pivot"});
    else only_keys(ctx, v, path, {"axis", "degrees"});
    const Eigen::Vector3d axis = point3(ctx, require(ctx, v, path, "axis"), path + ".axis");
    const double degrees = finite_number(ctx, require(ctx, v, path, "degrees"), path + ".degrees");
    if (!(axis.norm() > 1e-12)) ctx.fail(path + ".axis", "expected a non-zero vector, got " + describe(v["axis"]));
    if (std::abs(degrees) > 360) ctx.fail(path + ".degrees", "expected an angle in [-360, 360], got " + describe(v["degrees"]));
    if (pivot && v.contains("pivot")) *pivot = point3(ctx, v["pivot"], path + ".pivot");
    return Eigen::AngleAxisd(degrees * M_PI / 180, axis.normalized()).toRotationMatrix();
}

/// One entry of an edit's constraints, as the rows the solve takes (a frame is five, a connect with "at" two).
void parse_constraint(const Context& ctx, const json& v, const std::string& path, std::vector<Constraint>& out) {
    if (!v.is_object()) ctx.fail(path, "expected an object, got " + describe(v));
    Constraint c;
    c.name = path;
    static const char* kinds[] = {"move", "pin", "control_point", "frame", "region", "connect", "normal", "slide"};
    int count = 0;
    std::string names;
    for (const char* k : kinds) {
        count += int(v.contains(k));
        names += std::string(names.empty() ? "" : ", ") + "\"" + k + "\"";
    }
    if (count != 1) ctx.fail(path, "expected exactly one of " + names);
    std::vector<Constraint> rows;
    if (v.contains("move")) {
        only_keys(ctx, v, path, {"move", "to", "weight"});
        c.kind = ConstraintKind::move;
        c.point = point3(ctx, v["move"], path + ".move");
        c.to = point3(ctx, require(ctx, v, path, "to"), path + ".to");
    } else if (v.contains("pin")) {
        only_keys(ctx, v, path, {"pin", "weight"});
        c.kind = ConstraintKind::pin;
        c.point = c.to = point3(ctx, v["pin"], path + ".pin");
    } else if (v.contains("control_point")) {
        only_keys(ctx, v, path, {"control_point", "offset", "weight"});
        c.kind = ConstraintKind::control_point;
        const json& idx = v["control_point"];
        if (!idx.is_array() || idx.size() != 3) ctx.fail(path + ".control_point", "expected an array of three integers, got " + describe(idx));
        for (int a = 0; a < 3; ++a) c.control_point[std::size_t(a)] = integer(ctx, idx[std::size_t(a)], path + ".control_point[" + std::to_string(a) + "]");
        c.offset = point3(ctx, require(ctx, v, path, "offset"), path + ".offset");
    } else if (v.contains("frame")) {
        // P goes to Q (default: stays) and the map's Jacobian at P becomes the rotation (default: none): a move,
        // the derivative along each axis, and the plate.
        only_keys(ctx, v, path, {"frame", "to", "rotate", "weight"});
        c.kind = ConstraintKind::move;
        c.entry = "frame";
        c.point = point3(ctx, v["frame"], path + ".frame");
        c.to = v.contains("to") ? point3(ctx, v["to"], path + ".to") : c.point;
        const Eigen::Matrix3d rotation = v.contains("rotate") ? parse_rotation(ctx, v["rotate"], path + ".rotate") : Eigen::Matrix3d::Identity();
        for (int a = 0; a < 3; ++a) {
            Constraint t = c;
            t.kind = ConstraintKind::turn;
            t.direction = Eigen::Vector3d::Unit(a);
            t.rotation = rotation;
            rows.push_back(t);
        }
        // And the surface it grips turns with it as a plate (the deform finds the surface).
        Constraint plate = c;
        plate.kind = ConstraintKind::plate;
        plate.rotation = rotation;
        rows.push_back(plate);
    } else if (v.contains("region")) {
        only_keys(ctx, v, path, {"region", "translate", "rotate", "weight"});
        c.kind = ConstraintKind::region;
        c.entry = "region";
        const json& r = v["region"];
        const std::string rp = path + ".region";
        if (!r.is_object() || r.size() != 1 || !(r.contains("sphere") || r.contains("box")))
            ctx.fail(rp, "expected {\"sphere\": [[x, y, z], r]} or {\"box\": [[x, y, z], [x, y, z]]}, got " + describe(r));
        if (r.contains("sphere")) {
            const json& sph = r["sphere"];
            if (!sph.is_array() || sph.size() != 2) ctx.fail(rp + ".sphere", "expected [[x, y, z], radius], got " + describe(sph));
            c.region.sphere = true;
            c.region.centre = point3(ctx, sph[0], rp + ".sphere[0]");
            c.region.radius = finite_number(ctx, sph[1], rp + ".sphere[1]");
            if (!(c.region.radius > 0)) ctx.fail(rp + ".sphere[1]", "expected a radius > 0, got " + describe(sph[1]));
            c.pivot = c.region.centre;
        } else {
            const json& box = r["box"];
            if (!box.is_array() || box.size() != 2) ctx.fail(rp + ".box", "expected [[x, y, z], [x, y, z]] (low and high corners), got " + describe(box));
            c.region.sphere = false;
            c.region.lo = point3(ctx, box[0], rp + ".box[0]");
            c.region.hi = point3(ctx, box[1], rp + ".box[1]");
            if (!(c.region.lo.array() < c.region.hi.array()).all()) ctx.fail(rp + ".box", "expected the low corner below the high one on every axis");
            c.pivot = (c.region.lo + c.region.hi) / 2;
        }
        if (v.contains("translate")) c.offset = point3(ctx, v["translate"], path + ".translate");
        if (v.contains("rotate")) c.rotation = parse_rotation(ctx, v["rotate"], path + ".rotate", &c.pivot);
    } else if (v.contains("normal")) {
        only_keys(ctx, v, path, {"normal", "direction", "weight"});
        c.kind = ConstraintKind::normal;
        c.entry = "normal";
        c.point = c.to = point3(ctx, v["normal"], path + ".normal");
        const Eigen::Vector3d n = point3(ctx, require(ctx, v, path, "direction"), path + ".direction");
        if (!(n.norm() > 1e-12)) ctx.fail(path + ".direction", "expected a non-zero vector, got " + describe(v["direction"]));
        c.direction = n.normalized();
    } else if (v.contains("slide")) {
        only_keys(ctx, v, path, {"slide", "weight"});
        c.kind = ConstraintKind::slide;
        c.entry = "slide";
        c.point = c.to = point3(ctx, v["slide"], path + ".slide");
    } else {
        only_keys(ctx, v, path, {"connect", "at", "weight"});
        const json& pair = v["connect"];
        if (!pair.is_array() || pair.size() != 2) ctx.fail(path + ".connect", "expected two points [[x, y, z], [x, y, z]], got " + describe(pair));
        c.point = point3(ctx, pair[0], path + ".connect[0]");
        c.to = point3(ctx, pair[1], path + ".connect[1]");
        c.kind = ConstraintKind::join;
        if (v.contains("at")) { // both go there: two moves
            const Eigen::Vector3d at = point3(ctx, v["at"], path + ".at");
            Constraint second = c;
            c.kind = second.kind = ConstraintKind::move;
            c.entry = second.entry = "connect";
            second.point = c.to;
            c.to = second.to = at;
            rows.push_back(second);
        }
    }
    if (v.contains("weight")) {
        const double w = finite_number(ctx, v["weight"], path + ".weight");
        if (!(w > 0)) ctx.fail(path + ".weight", "expected a number > 0, got " + describe(v["weight"]));
        c.weight = w;
        for (auto& r : rows) r.weight = w;
    }
    out.push_back(c);
    out.insert(out.end(), rows.begin(), rows.end());
}

} // namespace edit_file_internal

using namespace edit_file_internal;

std::string to_string(Solver solver) { return solver == Solver::rigid ? "rigid" : "min-norm"; }

EditScript parse_edit_script(const std::string& text, const std::string& source) {
    const Context ctx{source};
    json root;
    try {
        root = json::parse(text);
    } catch (const json::exception& e) { // parse_error, and out_of_range for numbers such as 1e999
        ctx.fail("", std::string("not valid JSON: ") + e.what());
    }
    if (!root.is_object()) ctx.fail("", "expected a JSON object with \"edits\", got " + describe(root));
    only_keys(ctx, root, "", {"lattice", "edits"});
    EditScript script;
    if (root.contains("lattice")) script.lattice = parse_lattice(ctx, root["lattice"]);
    const json& edits = require(ctx, root, "", "edits");
    if (!edits.is_array() || edits.empty()) ctx.fail("edits", "expected a non-empty array of edits, got " + describe(edits));
    for (std::size_t e = 0; e < edits.size(); ++e) {
        const std::string path = "edits[" + std::to_string(e) + "]";
        const json& edit = edits[e];
        if (!edit.is_object()) ctx.fail(path, "expected an object with \"constraints\", got " + describe(edit));
        only_keys(ctx, edit, path, {"constraints", "solver", "preserve_volume"});
        const json& list = require(ctx, edit, path, "constraints");
        if (!list.is_array() || list.empty()) ctx.fail(path + ".constraints", "expected a non-empty array, got " + describe(list));
        Edit out;
        if (edit.contains("solver")) {
            const json& s = edit["solver"];
            if (!s.is_string() || (s != "min-norm" && s != "rigid")) ctx.fail(path + ".solver", "expected \"min-norm\" or \"rigid\", got " + describe(s));
            out.solver = s == "rigid" ? Solver::rigid : Solver::min_norm;
        }
        if (edit.contains("preserve_volume")) {
            const json& p = edit["preserve_volume"];
            if (!p.is_boolean()) ctx.fail(path + ".preserve_volume", "expected true or false, got " + describe(p));
            out.preserve_volume = p.get<bool>();
        }
        for (std::size_t c = 0; c < list.size(); ++c) parse_constraint(ctx, list[c], path + ".constraints[" + std::to_string(c) + "]", out.constraints);
        script.edits.push_back(std::move(out));
    }
    return script;
}

EditScript read_edit_file(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw IOError(path + ": no such file");
    if (std::filesystem::file_size(path, ec) > (16u << 20)) throw InvalidInput(path + ": larger than 16 MiB; an edit file is a short JSON script");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IOError(path + ": cannot open for reading");
    std::stringstream text;
    text << in.rdbuf();
    if (text.str().empty()) throw InvalidInput(path + ": file is empty");
    return parse_edit_script(text.str(), path);
}

} // namespace voxwarp
