// OpenMesh's binary .om format, read by voxwarp itself. OpenMesh's reader follows the file's counts and halfedge
// indices without checking them: of 72 copies of a box's .om with a few bytes damaged, 36 crashed it or hung it.
// Here every count is checked against the bytes left before anything is read or allocated, every index against
// its range before it is followed, and each halfedge is visited once while the faces are rebuilt.
//
// The layout, as OpenMesh 9 writes and reads it (OMFormat.hh): a 16-byte header ("OM", mesh kind T/Q/P, version
// byte major << 5 | minor, then the vertex, face and edge counts as uint32), then chunks until a sentinel. A chunk
// is a uint16 bit field (name flag, entity, type, signed, float, dimension, size code), a property name if
// flagged (a length byte, then that many bytes), then one value per element of its entity. From version 2.0 faces
// are stored as halfedge connectivity (next, to-vertex, face per halfedge; a halfedge per face), before 2.0 as
// vertex lists. Every number is little-endian.
#include "mesh_validate.h"

#include <voxwarp/errors.h>

#include <cmath>
#include <cstring>
#include <string>

namespace voxwarp::mesh_io_internal {

namespace {

enum Entity { kVertex = 0, kMesh = 1, kFace = 2, kEdge = 4, kHalfedge = 6, kSentinel = 7 };
enum Type { kPosition = 0, kNormal = 1, kTexcoord = 2, kStatus = 3, kColour = 4, kCustom = 6, kTopology = 7 };

constexpr int om_version(int major, int minor) { return major << 5 | minor; }
constexpr int kNewestVersion = om_version(2, 2); // what Debian's OpenMesh 9 writes and reads

struct ChunkHeader {
    bool named;
    int entity, type;
    bool is_float;
    int dimensions; ///< 1 to 8
    int size_code;  ///< integers: 1, 2, 4, 8 bytes for 0..3; floats: 4, 8, 16 bytes for 0..2
};

ChunkHeader decode(std::uint16_t bits) {
    return {bool(bits >> 1 & 1u), int(bits >> 2 & 7u), int(bits >> 5 & 15u), bool(bits >> 10 & 1u), int(bits >> 11 & 7u) + 1, int(bits >> 14 & 3u)};
}

const char* entity_name(int entity) {
    switch (entity) {
    case kVertex: return "vertex";
    case kMesh: return "mesh";
    case kFace: return "face";
    case kEdge: return "edge";
    case kHalfedge: return "halfedge";
    default: return "unknown";
    }
}

/// The file's bytes, read front to back; every read is checked against what is left.
class Reader {
public:
    Reader(const std::string& path, std::string_view bytes) : path_(path), bytes_(bytes) {}

    std::size_t at() const { return at_; }
    std::size_t left() const { return bytes_.size() - at_; }
    bool done() const { return at_ == bytes_.size(); }

    [[noreturn]] void refuse(const std::string& what) const { throw InvalidInput(path_ + ": corrupt .om file: " + what); }

    /// Room for `count` values of `size` bytes each, or a message naming what needed it.
    void need(std::uint64_t count, std::uint64_t size, const std::string& what) const {
        if (size != 0 && count > left() / size)
            refuse(what + " needs " + std::to_string(count) + " x " + std::to_string(size) + " bytes at byte " + std::to_string(at_) + ", the file has " +
                   std::to_string(left()) + " left");
    }
    std::uint64_t unsigned_int(int size) {
        need(1, std::uint64_t(size), "a number");
        std::uint64_t v = 0;
        for (int b = size - 1; b >= 0; --b) v = v << 8 | std::uint8_t(bytes_[at_ + std::size_t(b)]);
        at_ += std::size_t(size);
        return v;
    }
    std::int64_t signed_int(int size) {
        const std::uint64_t v = unsigned_int(size);
        const int shift = 64 - 8 * size;
        return std::int64_t(v << shift) >> shift;
    }
    double real(int size) {
        const std::uint64_t v = unsigned_int(size);
        if (size == 4) {
            const std::uint32_t u = std::uint32_t(v);
            float f;
            std::memcpy(&f, &u, 4);
            return f;
        }
        double d;
        std::memcpy(&d, &v, 8);
        return d;
    }
    std::string text() {
        const std::size_t length = std::size_t(unsigned_int(1));
        need(length, 1, "a property name");
        std::string s(bytes_.substr(at_, length));
        at_ += length;
        return s;
    }
    void skip(std::uint64_t count, std::uint64_t size, const std::string& what) {
        need(count, size, what);
        at_ += std::size_t(count * size);
    }

private:
    const std::string& path_;
    std::string_view bytes_;
    std::size_t at_ = 0;
};

struct OmContents {
    int version = 0;
    char kind = 'P';
    std::uint32_t vertices = 0, faces = 0, edges = 0;
    bool has_positions = false;
    std::vector<Eigen::Vector3d> positions, vertex_normals;
    std::vector<Eigen::Vector3f> colours;
    std::vector<Eigen::Vector2d> vertex_uvs, halfedge_uvs;
    // Version 2: a halfedge per face, and per halfedge as stored (the two of an edge after each other) its next
    // halfedge, to-vertex and face. Before 2: each face's vertices, one list after another.
    std::vector<std::int64_t> face_halfedge, halfedges;
    std::vector<std::uint32_t> polygon_sizes;
    std::vector<std::int64_t> polygon_corners;
};

int float_bytes(const ChunkHeader& h) { return h.size_code == 0 ? 4 : h.size_code == 1 ? 8 : 0; }

void read_chunk(Reader& in, OmContents& om, const ChunkHeader& h, std::uint64_t count) {
    const std::string what = std::string(entity_name(h.entity)) + " ";
    auto unsupported = [&](const std::string& stored) {
        in.refuse(what + "chunk of type " + std::to_string(h.type) + " (" + stored + ") at byte " + std::to_string(in.at()) + ", which OpenMesh does not read either");
    };
    auto vectors3 = [&](std::vector<Eigen::Vector3d>* out, const char* name) { // null: skipped
        const int size = float_bytes(h);
        if (!h.is_float || size == 0 || h.dimensions != 3) unsupported(std::string(name) + " stored as other than 3 floats or doubles");
        if (!out) return in.skip(count, 3u * std::uint64_t(size), what + name);
        in.need(count, 3u * std::uint64_t(size), what + name);
        out->resize(std::size_t(count));
        for (auto& v : *out)
            for (int a = 0; a < 3; ++a) v[a] = in.real(size);
    };
    auto uvs = [&](std::vector<Eigen::Vector2d>& out) {
        if (!h.is_float || h.size_code != 0 || h.dimensions != 2) unsupported("texture coordinates stored as other than 2 floats");
        in.need(count, 8, what + "texture coordinates");
        out.resize(std::size_t(count));
        for (auto& v : out)
            for (int a = 0; a < 2; ++a) v[a] = in.real(4);
    };
    auto indices = [&](std::vector<std::int64_t>& out, std::uint64_t per_element) {
        const int size = 1 << h.size_code;
        in.need(count * per_element, std::uint64_t(size), what + "connectivity");
        out.resize(std::size_t(count * per_element));
        for (auto& i : out) i = in.signed_int(size);
    };
    switch (h.type) {
    case kPosition:
        if (h.entity != kVertex) unsupported("positions");
        if (om.has_positions) in.refuse("a second chunk of vertex positions at byte " + std::to_string(in.at()));
        vectors3(&om.positions, "positions");
        om.has_positions = true;
        return;
    case kNormal:
        if (h.entity != kVertex && h.entity != kFace) unsupported("normals");
        return vectors3(h.entity == kVertex ? &om.vertex_normals : nullptr, "normals"); // a face's: voxwarp's normals are per corner
    case kTexcoord:
        if (h.entity == kVertex) return uvs(om.vertex_uvs);
        if (h.entity == kHalfedge) return uvs(om.halfedge_uvs);
        return unsupported("texture coordinates");
    case kColour:
        if (h.entity != kVertex && h.entity != kFace) unsupported("colours");
        if (h.is_float || h.size_code != 0 || h.dimensions != 3) unsupported("colours stored as other than 3 bytes");
        if (h.entity == kFace) return in.skip(count, 3, what + "colours");
        in.need(count, 3, what + "colours");
        om.colours.resize(std::size_t(count));
        for (auto& c : om.colours)
            for (int a = 0; a < 3; ++a) c[a] = float(in.unsigned_int(1)) / 255.0f;
        return;
    case kStatus:
        if (h.entity == kMesh) unsupported("status");
        return in.skip(count, 4, what + "status flags");
    case kCustom: {
        if (om.version > om_version(2, 1)) in.text(); // the property's type name
        const std::uint64_t block = in.unsigned_int(4);
        return in.skip(block, 1, what + "property");
    }
    case kTopology:
        if (h.entity == kVertex) return in.skip(count, std::uint64_t(1) << h.size_code, what + "connectivity"); // rebuilt from the faces
        if (h.entity == kHalfedge && om.version >= om_version(2, 0)) {
            if (!om.halfedges.empty()) in.refuse("a second chunk of halfedge connectivity at byte " + std::to_string(in.at()));
            return indices(om.halfedges, 3);
        }
        if (h.entity != kFace) unsupported("connectivity");
        if (!om.face_halfedge.empty() || !om.polygon_sizes.empty()) in.refuse("a second chunk of faces at byte " + std::to_string(in.at()));
        if (om.version >= om_version(2, 0)) return indices(om.face_halfedge, 1);
        in.need(count, om.kind == 'P' ? 2 : 1, what + "connectivity"); // before the lists are reserved
        om.polygon_sizes.reserve(std::size_t(count));
        for (std::uint64_t f = 0; f < count; ++f) {
            const std::uint32_t n = om.kind == 'T' ? 3 : om.kind == 'Q' ? 4 : std::uint32_t(in.unsigned_int(2));
            in.need(n, std::uint64_t(1) << h.size_code, "face " + std::to_string(f) + "'s vertices");
            om.polygon_sizes.push_back(n);
            for (std::uint32_t c = 0; c < n; ++c) om.polygon_corners.push_back(std::int64_t(in.unsigned_int(1 << h.size_code)));
        }
        return;
    default: unsupported("unknown");
    }
}

} // namespace

TriangleMesh read_om(const std::string& path, std::string_view bytes) {
    Reader in(path, bytes);
    OmContents om;
    in.need(1, 16, "the header");
    if (bytes[0] != 'O' || bytes[1] != 'M') in.refuse("it does not start with 'OM'");
    om.kind = bytes[2];
    if (om.kind != 'T' && om.kind != 'Q' && om.kind != 'P') in.refuse("mesh kind '" + std::string(1, om.kind) + "' where T, Q or P was expected");
    om.version = std::uint8_t(bytes[3]);
    if (om.version > kNewestVersion)
        throw InvalidInput(path + ": .om version " + std::to_string(om.version >> 5) + "." + std::to_string(om.version & 31) +
                           " is newer than the 2.2 this reader (and Debian's OpenMesh 9) knows");
    in.skip(1, 4, "the header");
    om.vertices = std::uint32_t(in.unsigned_int(4));
    om.faces = std::uint32_t(in.unsigned_int(4));
    om.edges = std::uint32_t(in.unsigned_int(4));

    // Chunks until the sentinel; a file may also simply end after a whole chunk.
    while (!in.done()) {
        const ChunkHeader h = decode(std::uint16_t(in.unsigned_int(2)));
        if (h.named) in.text();
        if (h.entity == kSentinel) break;
        std::uint64_t count = 0;
        switch (h.entity) {
        case kVertex: count = om.vertices; break;
        case kFace: count = om.faces; break;
        case kEdge: count = om.edges; break;
        case kHalfedge: count = 2 * std::uint64_t(om.edges); break;
        case kMesh: count = 1; break;
        default: in.refuse("a chunk for entity " + std::to_string(h.entity) + " at byte " + std::to_string(in.at() - 2) + ", which is none of OpenMesh's");
        }
        read_chunk(in, om, h, count);
    }

    TriangleMesh mesh;
    if (!om.has_positions || om.vertices == 0) throw InvalidInput(path + ": no vertices");
    mesh.vertices = std::move(om.positions);
    for (std::size_t v = 0; v < mesh.vertices.size(); ++v)
        if (!mesh.vertices[v].allFinite()) throw InvalidInput(path + ": vertex " + std::to_string(v) + " has a non-finite coordinate");

    // Each face's corners (vertex, and the halfedge whose texture coordinate the corner takes), fanned into triangles.
    std::vector<std::array<std::int32_t, 3>> corner_uvs;
    std::vector<std::int64_t> polygon, polygon_halfedges;
    auto add_polygon = [&](std::uint64_t f) {
        if (polygon.size() < 3) in.refuse("face " + std::to_string(f) + " has " + std::to_string(polygon.size()) + " corners");
        for (const std::int64_t v : polygon)
            if (v < 0 || v >= std::int64_t(om.vertices))
                in.refuse("face " + std::to_string(f) + " refers to vertex " + std::to_string(v) + ", the file has " + std::to_string(om.vertices));
        for (std::size_t c = 1; c + 1 < polygon.size(); ++c) {
            mesh.triangles.push_back({std::int32_t(polygon[0]), std::int32_t(polygon[c]), std::int32_t(polygon[c + 1])});
            if (!polygon_halfedges.empty())
                corner_uvs.push_back({std::int32_t(polygon_halfedges[0]), std::int32_t(polygon_halfedges[c]), std::int32_t(polygon_halfedges[c + 1])});
        }
    };
    if (om.version >= om_version(2, 0)) {
        if (om.faces > 0 && om.face_halfedge.empty()) in.refuse("it has " + std::to_string(om.faces) + " faces but no chunk of them");
        if (om.faces > 0 && om.halfedges.empty()) in.refuse("it has " + std::to_string(om.faces) + " faces but no halfedge connectivity");
        const std::int64_t halfedges = std::int64_t(om.halfedges.size() / 3);
        auto next = [&](std::int64_t h) { return om.halfedges[3 * std::size_t(h)]; };
        auto to_vertex = [&](std::int64_t h) { return om.halfedges[3 * std::size_t(h) + 1]; };
        auto face_of = [&](std::int64_t h) { return om.halfedges[3 * std::size_t(h) + 2]; };
        const bool keep_halfedges = !om.halfedge_uvs.empty();
        std::vector<std::uint8_t> visited(std::size_t(halfedges), 0);
        for (std::uint64_t f = 0; f < om.face_halfedge.size(); ++f) {
            polygon.clear();
            polygon_halfedges.clear();
            const std::int64_t first = om.face_halfedge[f];
            std::int64_t h = first;
            do {
                if (h < 0 || h >= halfedges)
                    in.refuse("face " + std::to_string(f) + " reaches halfedge " + std::to_string(h) + ", the file has " + std::to_string(halfedges));
                if (visited[std::size_t(h)]) in.refuse("face " + std::to_string(f) + "'s loop of halfedges does not close (halfedge " + std::to_string(h) + " is met twice)");
                if (face_of(h) != std::int64_t(f))
                    in.refuse("face " + std::to_string(f) + "'s loop of halfedges reaches halfedge " + std::to_string(h) + ", which belongs to face " + std::to_string(face_of(h)));
                visited[std::size_t(h)] = 1;
                polygon.push_back(to_vertex(h));
                if (keep_halfedges) polygon_halfedges.push_back(h);
                h = next(h);
            } while (h != first);
            add_polygon(f);
        }
    } else {
        std::size_t at = 0;
        for (std::uint64_t f = 0; f < om.polygon_sizes.size(); ++f) {
            polygon.assign(om.polygon_corners.begin() + std::ptrdiff_t(at), om.polygon_corners.begin() + std::ptrdiff_t(at + om.polygon_sizes[f]));
            at += om.polygon_sizes[f];
            add_polygon(f);
        }
    }
    if (mesh.triangles.empty()) throw InvalidInput(path + ": no faces");

    if (!om.halfedge_uvs.empty()) {
        mesh.uvs = std::move(om.halfedge_uvs);
        mesh.triangle_uvs = std::move(corner_uvs);
    } else if (!om.vertex_uvs.empty()) {
        mesh.uvs = std::move(om.vertex_uvs);
        mesh.triangle_uvs = mesh.triangles;
    }
    if (!om.vertex_normals.empty()) {
        mesh.normals = std::move(om.vertex_normals);
        for (auto& n : mesh.normals)
            if (n.norm() > 0) n.normalize();
        mesh.triangle_normals = mesh.triangles;
    }
    mesh.colours = std::move(om.colours);
    check_attributes(mesh, path);
    return mesh;
}

} // namespace voxwarp::mesh_io_internal
