// Fast readers for the common text formats and binary STL: one pass over the file in memory with
// std::from_chars, validating as they go (the same checks and messages as mesh_validate.cpp). OpenMesh's
// readers, behind a separate validating pass, took seconds on a 1.7 M-triangle OBJ; PLY, ASCII STL and the
// OFF variants still go through OpenMesh. .om has a reader of its own (om_read.cpp).
#include "mesh_validate.h"

#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <string_view>
#include <unordered_map>

namespace voxwarp::mesh_io_internal {

namespace {

bool space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }

/// Walks a file's text line by line, token by token.
class Lines {
public:
    explicit Lines(std::string_view text) : text_(text) {}
    /// The next line (without its '\n'); false at the end.
    bool next(std::string_view& line) {
        if (at_ >= text_.size()) return false;
        const std::size_t end = text_.find('\n', at_);
        line = text_.substr(at_, (end == std::string_view::npos ? text_.size() : end) - at_);
        at_ = end == std::string_view::npos ? text_.size() : end + 1;
        ++number_;
        return true;
    }
    std::size_t number() const { return number_; }

private:
    std::string_view text_;
    std::size_t at_ = 0, number_ = 0;
};

/// The rest of a line without the whitespace around it: a name that may hold spaces (usemtl's, as newmtl's name in
/// the library is read; g's and o's).
std::string rest_of(std::string_view line) {
    while (!line.empty() && space(line.front())) line.remove_prefix(1);
    while (!line.empty() && space(line.back())) line.remove_suffix(1);
    return std::string(line);
}

/// The next whitespace-separated token of `line` (consumed); empty at its end.
std::string_view token(std::string_view& line) {
    std::size_t b = 0;
    while (b < line.size() && space(line[b])) ++b;
    std::size_t e = b;
    while (e < line.size() && !space(line[e])) ++e;
    const std::string_view t = line.substr(b, e - b);
    line.remove_prefix(e);
    return t;
}

/// A whole token as a double (a leading '+' allowed, as strtod allows it).
bool parse_double(std::string_view t, double& x) {
    if (!t.empty() && t[0] == '+') t.remove_prefix(1);
    if (t.empty()) return false;
    const auto r = std::from_chars(t.data(), t.data() + t.size(), x);
    return r.ec == std::errc() || r.ec == std::errc::result_out_of_range ? (r.ec == std::errc() || (x = std::numeric_limits<double>::infinity(), true)) : false;
}

/// The integer a token starts with; `rest` is what follows it.
bool parse_leading_integer(std::string_view t, std::int64_t& x, std::string_view& rest) {
    if (!t.empty() && t[0] == '+') t.remove_prefix(1);
    const auto r = std::from_chars(t.data(), t.data() + t.size(), x);
    if (r.ec != std::errc()) return false;
    rest = t.substr(std::size_t(r.ptr - t.data()));
    return true;
}

std::string read_whole(const std::string& path, std::uintmax_t size) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IOError(path + ": cannot open for reading");
    std::string text(std::size_t(size), '\0');
    in.read(text.data(), std::streamsize(size));
    if (std::uintmax_t(in.gcount()) != size) throw IOError(path + ": read " + std::to_string(in.gcount()) + " of " + std::to_string(size) + " bytes");
    return text;
}

/// Texture coordinate, normal, material and group indices of an OBJ's faces, kept only once a face names one.
struct ObjAttributes {
    std::vector<std::array<std::int32_t, 3>>& triangle_uvs;
    std::vector<std::array<std::int32_t, 3>>& triangle_normals;
    std::vector<std::int32_t>& triangle_materials;
    std::vector<std::int32_t>& triangle_groups;
    void groups_for(std::size_t triangles) {
        if (triangle_groups.size() < triangles) triangle_groups.resize(triangles, -1);
    }
    void uvs_for(std::size_t triangles) {
        if (triangle_uvs.size() < triangles) triangle_uvs.resize(triangles, {-1, -1, -1});
    }
    void normals_for(std::size_t triangles) {
        if (triangle_normals.size() < triangles) triangle_normals.resize(triangles, {-1, -1, -1});
    }
    void materials_for(std::size_t triangles) {
        if (triangle_materials.size() < triangles) triangle_materials.resize(triangles, -1);
    }
};

TriangleMesh read_obj(const std::string& path, std::string_view text, std::vector<std::string>& libraries) {
    TriangleMesh mesh;
    ObjAttributes attributes{mesh.triangle_uvs, mesh.triangle_normals, mesh.triangle_materials, mesh.triangle_groups};
    Lines lines(text);
    std::string_view line;
    std::int64_t max_index = 0, max_uv = 0, max_normal = 0;
    std::size_t max_index_line = 0, max_uv_line = 0, max_normal_line = 0;
    std::int32_t material = -1, group = -1;
    std::unordered_map<std::string, std::int32_t> group_ids;
    std::unordered_map<std::string, std::int32_t> material_ids;
    std::vector<std::int32_t> polygon, polygon_uvs, polygon_normals;
    auto bad = [&](const std::string& what) { throw InvalidInput(path + ": line " + std::to_string(lines.number()) + ": " + what); };
    // An OBJ index (1-based, or negative: counted back from the last one read) as 0-based.
    auto index_of = [&](std::int64_t index, std::int64_t count, const char* what, std::int64_t& max, std::size_t& max_line) {
        if (index == 0) bad(std::string("face ") + what + " index 0 (OBJ indices start at 1)");
        if (index < 0 && index < -count) bad(std::string("face ") + what + " index " + std::to_string(index) + " reaches before the first one");
        if (index > max) max = index, max_line = lines.number();
        if (index > std::int64_t(std::numeric_limits<std::int32_t>::max())) bad(std::string("face ") + what + " index " + std::to_string(index) + " is out of range");
        return std::int32_t(index < 0 ? count + index : index - 1);
    };
    while (lines.next(line)) {
        const std::string_view keyword = token(line);
        if (keyword == "v") {
            Eigen::Vector3d p;
            for (int a = 0; a < 3; ++a) {
                if (!parse_double(token(line), p[a])) bad("vertex " + std::to_string(mesh.vertices.size() + 1) + " needs three numbers");
                if (!std::isfinite(p[a])) bad("vertex " + std::to_string(mesh.vertices.size() + 1) + " has a non-finite coordinate");
            }
            // "v x y z r g b": a vertex colour (a common extension; 0-1, or 0-255 when any is above 1).
            Eigen::Vector3d rgb;
            std::string_view rest = line;
            if (const auto t = token(rest); !t.empty() && parse_double(t, rgb[0]) && parse_double(token(rest), rgb[1]) && parse_double(token(rest), rgb[2])) {
                if (!rgb.allFinite() || rgb.minCoeff() < 0) bad("vertex " + std::to_string(mesh.vertices.size() + 1) + " has a colour outside [0, 1] and [0, 255]");
                if (rgb.maxCoeff() > 1) rgb /= 255.0;
                if (rgb.maxCoeff() > 1) bad("vertex " + std::to_string(mesh.vertices.size() + 1) + " has a colour outside [0, 1] and [0, 255]");
                mesh.colours.resize(mesh.vertices.size(), Eigen::Vector3f::Ones());
                mesh.colours.push_back(rgb.cast<float>());
            }
            mesh.vertices.push_back(p);
        } else if (keyword == "vt") {
            Eigen::Vector2d uv;
            for (int a = 0; a < 2; ++a)
                if (!parse_double(token(line), uv[a]) || !std::isfinite(uv[a])) bad("texture coordinate " + std::to_string(mesh.uvs.size() + 1) + " needs two finite numbers");
            mesh.uvs.push_back(uv);
        } else if (keyword == "vn") {
            Eigen::Vector3d n;
            for (int a = 0; a < 3; ++a)
                if (!parse_double(token(line), n[a]) || !std::isfinite(n[a])) bad("normal " + std::to_string(mesh.normals.size() + 1) + " needs three finite numbers");
            mesh.normals.push_back(n.norm() > 0 ? Eigen::Vector3d(n.normalized()) : n); // OBJ does not promise unit length
        } else if (keyword == "f") {
            polygon.clear();
            polygon_uvs.clear();
            polygon_normals.clear();
            for (std::string_view t = token(line); !t.empty(); t = token(line)) {
                std::int64_t index = 0;
                std::string_view rest;
                if (!parse_leading_integer(t, index, rest) || (!rest.empty() && rest[0] != '/'))
                    bad("face vertex '" + std::string(t.substr(0, 40)) + "' does not start with a vertex index");
                polygon.push_back(index_of(index, std::int64_t(mesh.vertices.size()), "vertex", max_index, max_index_line));
                if (rest.size() > 1 && rest[1] != '/') { // v/vt or v/vt/vn
                    std::string_view after;
                    if (!parse_leading_integer(rest.substr(1), index, after) || (!after.empty() && after[0] != '/'))
                        bad("face vertex '" + std::string(t.substr(0, 40)) + "' has a malformed texture coordinate index");
                    polygon_uvs.push_back(index_of(index, std::int64_t(mesh.uvs.size()), "texture coordinate", max_uv, max_uv_line));
                    rest = after;
                } else if (rest.size() > 1) { // v//vn
                    rest = rest.substr(1);
                }
                if (rest.size() > 1) { // /vn
                    std::string_view after;
                    if (!parse_leading_integer(rest.substr(1), index, after) || !after.empty())
                        bad("face vertex '" + std::string(t.substr(0, 40)) + "' has a malformed normal index");
                    polygon_normals.push_back(index_of(index, std::int64_t(mesh.normals.size()), "normal", max_normal, max_normal_line));
                }
            }
            if (polygon.size() < 3) bad("face has " + std::to_string(polygon.size()) + " vertices, expected at least 3");
            const bool uvs = polygon_uvs.size() == polygon.size(); // a face that names them for some corners only has none
            const bool normals = polygon_normals.size() == polygon.size();
            for (std::size_t c = 1; c + 1 < polygon.size(); ++c) {
                mesh.triangles.push_back({polygon[0], polygon[c], polygon[c + 1]});
                if (uvs) {
                    attributes.uvs_for(mesh.triangles.size());
                    mesh.triangle_uvs.back() = {polygon_uvs[0], polygon_uvs[c], polygon_uvs[c + 1]};
                }
                if (normals) {
                    attributes.normals_for(mesh.triangles.size());
                    mesh.triangle_normals.back() = {polygon_normals[0], polygon_normals[c], polygon_normals[c + 1]};
                }
                if (material >= 0) {
                    attributes.materials_for(mesh.triangles.size());
                    mesh.triangle_materials.back() = material;
                }
                if (group >= 0) {
                    attributes.groups_for(mesh.triangles.size());
                    mesh.triangle_groups.back() = group;
                }
            }
        } else if (keyword == "usemtl") {
            const std::string name = rest_of(line);
            const auto [it, added] = material_ids.try_emplace(name, std::int32_t(mesh.materials.size()));
            if (added) mesh.materials.push_back(Material{name});
            material = it->second;
        } else if (keyword == "g" || keyword == "o") {
            // The faces after it belong to the group (or object) the rest of the line names; "g" alone: to none.
            const std::string name = rest_of(line);
            if (name.empty()) {
                group = -1;
                continue;
            }
            const auto [it, added] = group_ids.try_emplace(name, std::int32_t(mesh.groups.size()));
            if (added) mesh.groups.push_back(name);
            group = it->second;
        } else if (keyword == "mtllib") {
            for (std::string_view t = token(line); !t.empty(); t = token(line)) libraries.emplace_back(t);
        }
    }
    if (std::uint64_t(max_index) > mesh.vertices.size())
        throw InvalidInput(path + ": line " + std::to_string(max_index_line) + ": face refers to vertex " + std::to_string(max_index) + ", file has " +
                           std::to_string(mesh.vertices.size()) + " vertices");
    if (std::uint64_t(max_uv) > mesh.uvs.size())
        throw InvalidInput(path + ": line " + std::to_string(max_uv_line) + ": face refers to texture coordinate " + std::to_string(max_uv) + ", file has " +
                           std::to_string(mesh.uvs.size()));
    if (std::uint64_t(max_normal) > mesh.normals.size())
        throw InvalidInput(path + ": line " + std::to_string(max_normal_line) + ": face refers to normal " + std::to_string(max_normal) + ", file has " +
                           std::to_string(mesh.normals.size()));
    if (!mesh.colours.empty()) mesh.colours.resize(mesh.vertices.size(), Eigen::Vector3f::Ones());
    if (!mesh.triangle_uvs.empty()) attributes.uvs_for(mesh.triangles.size());
    if (!mesh.triangle_normals.empty()) attributes.normals_for(mesh.triangles.size());
    if (!mesh.triangle_materials.empty()) attributes.materials_for(mesh.triangles.size());
    if (!mesh.triangle_groups.empty()) attributes.groups_for(mesh.triangles.size());
    else mesh.groups.clear(); // named, but no face after it
    if (mesh.triangle_uvs.empty()) mesh.uvs.clear();
    if (mesh.triangle_normals.empty()) mesh.normals.clear();
    return mesh;
}

/// Plain ASCII "OFF" (no colour, normal or texture variants): header, vertices, faces.
TriangleMesh read_off(const std::string& path, std::string_view text) {
    TriangleMesh mesh;
    Lines lines(text);
    std::string_view line;
    std::int64_t nv = -1, nf = -1, faces = 0;
    int header = 0; // 0: keyword next, 1: counts next, 2: body
    std::vector<std::int32_t> polygon;
    auto bad = [&](const std::string& what) { throw InvalidInput(path + ": line " + std::to_string(lines.number()) + ": " + what); };
    while ((header < 2 || std::int64_t(mesh.vertices.size()) < nv || faces < nf) && lines.next(line)) {
        std::string_view rest = line;
        std::string_view first = token(rest);
        if (first.empty() || first[0] == '#') continue;
        if (header == 0) { // validate_off has checked the keyword
            header = 1;
            first = token(rest);
            if (first.empty()) continue;
        }
        if (header == 1) {
            std::string_view after;
            if (!parse_leading_integer(first, nv, after) || !after.empty() || !parse_leading_integer(token(rest), nf, after) || !after.empty() || nv < 0 || nf < 0)
                throw InvalidInput(path + ": OFF header: expected the vertex and face counts, got '" + std::string(line.substr(0, 40)) + "'");
            mesh.vertices.reserve(std::size_t(nv));
            header = 2;
            continue;
        }
        rest = line;
        if (std::int64_t(mesh.vertices.size()) < nv) {
            Eigen::Vector3d p;
            for (int a = 0; a < 3; ++a)
                if (!parse_double(token(rest), p[a]) || !std::isfinite(p[a])) bad("vertex " + std::to_string(mesh.vertices.size() + 1) + " needs three finite numbers");
            mesh.vertices.push_back(p);
            continue;
        }
        std::int64_t corners = 0;
        std::string_view after;
        if (!parse_leading_integer(token(rest), corners, after) || !after.empty() || corners < 3 || corners > 1000000)
            bad("face " + std::to_string(faces + 1) + " has a vertex count outside [3, 10^6]");
        polygon.clear();
        for (std::int64_t q = 0; q < corners; ++q) {
            std::int64_t index = -1;
            if (!parse_leading_integer(token(rest), index, after) || !after.empty() || index < 0 || index >= nv)
                bad("face " + std::to_string(faces + 1) + " refers to a vertex outside [0, " + std::to_string(nv) + ")");
            polygon.push_back(std::int32_t(index));
        }
        for (std::size_t c = 1; c + 1 < polygon.size(); ++c) mesh.triangles.push_back({polygon[0], polygon[c], polygon[c + 1]});
        ++faces;
    }
    if (std::int64_t(mesh.vertices.size()) < nv || faces < nf)
        throw InvalidInput(path + ": ends after " + std::to_string(mesh.vertices.size()) + " of " + std::to_string(nv) + " vertices and " + std::to_string(faces) +
                           " of " + std::to_string(nf) + " faces");
    return mesh;
}

/// Binary STL (validate_stl has checked its size): corners at the same float position become one vertex.
TriangleMesh read_binary_stl(const std::string& path, std::string_view bytes) {
    TriangleMesh mesh;
    std::uint32_t count = 0;
    std::memcpy(&count, bytes.data() + 80, 4);
    struct Key {
        float x, y, z;
        bool operator==(const Key& o) const { return std::memcmp(this, &o, sizeof(Key)) == 0; }
    };
    struct Hash {
        std::size_t operator()(const Key& k) const {
            std::uint32_t u[3];
            std::memcpy(u, &k, sizeof u);
            return (std::size_t(u[0]) * 73856093u) ^ (std::size_t(u[1]) * 19349663u) ^ (std::size_t(u[2]) * 83492791u);
        }
    };
    std::unordered_map<Key, std::int32_t, Hash> ids;
    ids.reserve(std::size_t(count) / 2 + 16);
    mesh.triangles.reserve(count);
    for (std::uint32_t t = 0; t < count; ++t) {
        const char* at = bytes.data() + 84 + 50 * std::size_t(t) + 12; // past the normal
        std::array<std::int32_t, 3> face{};
        for (int c = 0; c < 3; ++c) {
            Key k;
            std::memcpy(&k, at + 12 * c, sizeof k);
            if (!(std::isfinite(k.x) && std::isfinite(k.y) && std::isfinite(k.z)))
                throw InvalidInput(path + ": triangle " + std::to_string(t + 1) + " has a non-finite coordinate");
            const auto [it, inserted] = ids.try_emplace(k, std::int32_t(mesh.vertices.size()));
            if (inserted) mesh.vertices.emplace_back(k.x, k.y, k.z);
            face[std::size_t(c)] = it->second;
        }
        mesh.triangles.push_back(face);
    }
    return mesh;
}

} // namespace

bool read_mesh_directly(const std::string& path, const std::string& ext, std::uintmax_t file_size, TriangleMesh& mesh, std::vector<std::string>& warnings) {
    if (ext == ".om") {
        mesh = read_om(path, read_whole(path, file_size));
        return true;
    }
    if (ext == ".obj") {
        std::vector<std::string> libraries;
        mesh = read_obj(path, read_whole(path, file_size), libraries);
        if (!mesh.materials.empty()) fill_materials(path, libraries, mesh.materials, warnings);
        return true;
    }
    if (ext == ".stl" || ext == ".off") {
        const std::string head = read_head(path, file_size);
        if (ext == ".stl") {
            validate_stl(path, head, file_size);
            if (head.rfind("solid", 0) == 0 && head.find("facet") != std::string::npos) return false; // ASCII: OpenMesh
            mesh = read_binary_stl(path, read_whole(path, file_size));
            return true;
        }
        std::string_view first(head);
        if (token(first) != "OFF") return false; // the variants, and BINARY, through validate_off and OpenMesh
        std::string_view word = first;
        if (token(word) == "BINARY") return false;
        validate_off(path, head, file_size, false); // the header's counts against the file's size
        mesh = read_off(path, read_whole(path, file_size));
        return true;
    }
    return false;
}

} // namespace voxwarp::mesh_io_internal
