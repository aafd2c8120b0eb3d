// Mesh writers straight from the arrays: binary PLY and STL, OBJ and OFF with std::to_chars (the shortest text
// that reads back as the same double), encoded in parallel chunks that are written in order. OpenMesh's writers
// build a halfedge mesh first and print through iostreams: for a 1.7 M-triangle output that took longer than
// extracting it.
#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include <tbb/parallel_for.h>

#include <charconv>
#include <cstring>
#include <functional>

namespace voxwarp {

namespace mesh_write_internal {

constexpr std::size_t kChunk = 1 << 16; // elements per chunk

/// Chunks of the output, each produced independently (in parallel) and concatenated in order.
using Chunks = std::vector<std::string>;

/// Run `encode(begin, end, out)` over [0, n) in chunks of kChunk, appending to `chunks` in order.
void encode_chunks(std::size_t n, Chunks& chunks, const std::function<void(std::size_t, std::size_t, std::string&)>& encode) {
    const std::size_t count = (n + kChunk - 1) / kChunk, first = chunks.size();
    chunks.resize(first + count);
    tbb::parallel_for(std::size_t(0), count, [&](std::size_t c) { encode(c * kChunk, std::min(n, (c + 1) * kChunk), chunks[first + c]); });
}

template <class T>
char* put(char* at, T value) {
    static_assert(std::is_trivially_copyable_v<T>);
    std::memcpy(at, &value, sizeof(T)); // little-endian: the machine's order on the x86 and ARM machines voxwarp builds for
    return at + sizeof(T);
}

/// Text written straight into a chunk sized for the worst case, then trimmed.
class TextChunk {
public:
    TextChunk(std::string& s, std::size_t capacity) : s_(s) {
        s_.resize(capacity);
        at_ = s_.data();
        end_ = at_ + capacity;
    }
    ~TextChunk() { s_.resize(std::size_t(at_ - s_.data())); }
    void text(std::string_view t) {
        std::memcpy(at_, t.data(), t.size());
        at_ += t.size();
    }
    void put(char c) { *at_++ = c; }
    void number(double x) { at_ = std::to_chars(at_, end_, x).ptr; }
    void integer(std::int64_t x) { at_ = std::to_chars(at_, end_, x).ptr; }

private:
    std::string& s_;
    char *at_, *end_;
};

void vertices_text(const TriangleMesh& mesh, std::string_view prefix, Chunks& chunks) {
    encode_chunks(mesh.vertices.size(), chunks, [&](std::size_t b, std::size_t e, std::string& s) {
        TextChunk t(s, (e - b) * (prefix.size() + 3 * 25 + 3)); // 24 characters hold any double
        for (std::size_t i = b; i < e; ++i) {
            const auto& v = mesh.vertices[i];
            t.text(prefix);
            t.number(v.x()), t.put(' '), t.number(v.y()), t.put(' '), t.number(v.z()), t.put('\n');
        }
    });
}

template <std::size_t N>
void faces_text(const std::vector<std::array<std::int32_t, N>>& faces, std::string_view prefix, std::int32_t base, Chunks& chunks) {
    encode_chunks(faces.size(), chunks, [&](std::size_t b, std::size_t e, std::string& s) {
        TextChunk t(s, (e - b) * (prefix.size() + 12 * N));
        for (std::size_t i = b; i < e; ++i) {
            t.text(prefix);
            for (std::size_t c = 0; c < N; ++c) {
                t.integer(std::int64_t(faces[i][c]) + base);
                t.put(c + 1 < N ? ' ' : '\n');
            }
        }
    });
}

Chunks obj(const TriangleMesh& mesh) {
    Chunks chunks{"# voxwarp\n"};
    vertices_text(mesh, "v ", chunks);
    faces_text(mesh.triangles, "f ", 1, chunks);
    faces_text(mesh.quads, "f ", 1, chunks);
    return chunks;
}

Chunks off(const TriangleMesh& mesh) {
    Chunks chunks{"OFF\n" + std::to_string(mesh.vertices.size()) + " " + std::to_string(mesh.face_count()) + " 0\n"};
    vertices_text(mesh, "", chunks);
    faces_text(mesh.triangles, "3 ", 0, chunks);
    faces_text(mesh.quads, "4 ", 0, chunks);
    return chunks;
}

Chunks stl(const TriangleMesh& mesh) {
    TriangleMesh storage;
    const auto& faces = all_triangles(mesh, storage);
    if (faces.size() > 0xffffffffu) throw InvalidInput("STL: more than 2^32 triangles");
    std::string header = "voxwarp binary STL";
    header.resize(80, ' ');
    header.resize(84);
    put(header.data() + 80, std::uint32_t(faces.size()));
    Chunks chunks{header};
    encode_chunks(faces.size(), chunks, [&](std::size_t b, std::size_t e, std::string& s) {
        s.resize((e - b) * 50);
        char* at = s.data();
        for (std::size_t i = b; i < e; ++i) {
            const auto& f = faces[i];
            const Eigen::Vector3d &p = mesh.vertices[std::size_t(f[0])], &q = mesh.vertices[std::size_t(f[1])], &r = mesh.vertices[std::size_t(f[2])];
            Eigen::Vector3d n = (q - p).cross(r - p);
            if (n.norm() > 0) n.normalize();
            for (const Eigen::Vector3d* v : {static_cast<const Eigen::Vector3d*>(&n), &p, &q, &r})
                for (int a = 0; a < 3; ++a) at = put(at, float((*v)[a]));
            at = put(at, std::uint16_t(0));
        }
    });
    return chunks;
}

Chunks ply(const TriangleMesh& mesh) {
    Chunks chunks{"ply\nformat binary_little_endian 1.0\ncomment voxwarp\nelement vertex " + std::to_string(mesh.vertices.size()) +
                  "\nproperty float x\nproperty float y\nproperty float z\nelement face " + std::to_string(mesh.face_count()) +
                  "\nproperty list uchar int vertex_indices\nend_header\n"};
    encode_chunks(mesh.vertices.size(), chunks, [&](std::size_t b, std::size_t e, std::string& s) {
        s.resize((e - b) * 12);
        char* at = s.data();
        for (std::size_t i = b; i < e; ++i) at = put(put(put(at, float(mesh.vertices[i].x())), float(mesh.vertices[i].y())), float(mesh.vertices[i].z()));
    });
    auto faces = [&](const auto& list, std::uint8_t corners) {
        encode_chunks(list.size(), chunks, [&, corners](std::size_t b, std::size_t e, std::string& s) {
            s.resize((e - b) * (1 + 4 * std::size_t(corners)));
            char* at = s.data();
            for (std::size_t i = b; i < e; ++i) {
                at = put(at, corners);
                for (auto v : list[i]) at = put(at, std::int32_t(v));
            }
        });
    };
    faces(mesh.triangles, 3);
    faces(mesh.quads, 4);
    return chunks;
}

} // namespace mesh_write_internal

std::vector<std::string> encode_mesh_chunks(const TriangleMesh& mesh, const std::string& extension) {
    using namespace mesh_write_internal;
    if (extension == ".ply") return ply(mesh);
    if (extension == ".stl") return stl(mesh);
    if (extension == ".obj") return obj(mesh);
    if (extension == ".off") return off(mesh);
    throw InvalidInput("no direct encoder for '" + extension + "' meshes");
}

std::string encode_mesh(const TriangleMesh& mesh, const std::string& extension) {
    const auto chunks = encode_mesh_chunks(mesh, extension);
    std::size_t size = 0;
    for (const auto& c : chunks) size += c.size();
    std::string out;
    out.reserve(size);
    for (const auto& c : chunks) out += c;
    return out;
}

std::string encode_ply(const TriangleMesh& mesh) { return encode_mesh(mesh, ".ply"); }

} // namespace voxwarp
