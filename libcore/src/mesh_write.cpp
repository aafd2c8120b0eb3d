// Mesh writers straight from the arrays: binary PLY and STL, OBJ and OFF with std::to_chars (the shortest text
// that reads back as the same double), encoded in parallel chunks that are written in order. OpenMesh's writers
// build a halfedge mesh first and print through iostreams: for a 1.7 M-triangle output that took longer than
// extracting it.
#include "mesh_validate.h"

#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <functional>

namespace voxwarp {

namespace mesh_io_internal {

SeamSplit split_at_seams(const TriangleMesh& mesh) {
    SeamSplit split;
    split.vertex_of.resize(mesh.vertices.size());
    split.uv_of.assign(mesh.vertices.size(), -1);
    split.normal_of.assign(mesh.vertices.size(), -1);
    for (std::size_t v = 0; v < mesh.vertices.size(); ++v) split.vertex_of[v] = std::int32_t(v);
    struct Copy {
        std::int32_t uv, normal, written;
    };
    std::vector<std::vector<Copy>> copies(mesh.vertices.size()); // beyond the first (uv, normal) pair seen at a vertex
    std::vector<bool> seen(mesh.vertices.size(), false);
    split.triangles = mesh.triangles;
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
        for (std::size_t c = 0; c < 3; ++c) {
            const std::int32_t v = mesh.triangles[f][c], uv = mesh.triangle_uvs.empty() ? -1 : mesh.triangle_uvs[f][c],
                               normal = mesh.triangle_normals.empty() ? -1 : mesh.triangle_normals[f][c];
            if (uv < 0 && normal < 0) continue;
            const auto i = std::size_t(v);
            if (!seen[i] || (split.uv_of[i] == uv && split.normal_of[i] == normal)) {
                seen[i] = true, split.uv_of[i] = uv, split.normal_of[i] = normal;
                continue;
            }
            std::int32_t written = -1;
            for (const auto& copy : copies[i])
                if (copy.uv == uv && copy.normal == normal) written = copy.written;
            if (written < 0) {
                written = std::int32_t(split.vertex_of.size());
                split.vertex_of.push_back(v);
                split.uv_of.push_back(uv);
                split.normal_of.push_back(normal);
                copies[i].push_back({uv, normal, written});
            }
            split.triangles[f][c] = written;
        }
    return split;
}

} // namespace mesh_io_internal

namespace mesh_write_internal {

using mesh_io_internal::SeamSplit;
using mesh_io_internal::split_at_seams;

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

Chunks obj(const TriangleMesh& mesh, const std::string& material_library) {
    Chunks chunks{"# voxwarp\n" + (mesh.materials.empty() || material_library.empty() ? std::string() : "mtllib " + material_library + "\n")};
    if (mesh.colours.empty()) {
        vertices_text(mesh, "v ", chunks);
    } else {
        encode_chunks(mesh.vertices.size(), chunks, [&](std::size_t b, std::size_t e, std::string& s) {
            TextChunk t(s, (e - b) * (2 + 6 * 25 + 6));
            for (std::size_t i = b; i < e; ++i) {
                const auto& v = mesh.vertices[i];
                const auto& c = mesh.colours[i];
                t.text("v ");
                t.number(v.x()), t.put(' '), t.number(v.y()), t.put(' '), t.number(v.z()), t.put(' ');
                t.number(c.x()), t.put(' '), t.number(c.y()), t.put(' '), t.number(c.z()), t.put('\n');
            }
        });
    }
    if (mesh.triangle_uvs.empty() && mesh.triangle_normals.empty() && mesh.triangle_materials.empty() && mesh.triangle_groups.empty()) {
        faces_text(mesh.triangles, "f ", 1, chunks);
    } else {
        encode_chunks(mesh.uvs.size(), chunks, [&](std::size_t b, std::size_t e, std::string& s) {
            TextChunk t(s, (e - b) * (3 + 2 * 25 + 2));
            for (std::size_t i = b; i < e; ++i) {
                t.text("vt "), t.number(mesh.uvs[i].x()), t.put(' '), t.number(mesh.uvs[i].y()), t.put('\n');
            }
        });
        encode_chunks(mesh.normals.size(), chunks, [&](std::size_t b, std::size_t e, std::string& s) {
            TextChunk t(s, (e - b) * (3 + 3 * 25 + 3));
            for (std::size_t i = b; i < e; ++i) {
                const auto& n = mesh.normals[i];
                t.text("vn "), t.number(n.x()), t.put(' '), t.number(n.y()), t.put(' '), t.number(n.z()), t.put('\n');
            }
        });
        auto material = [&](std::size_t f) { return mesh.triangle_materials.empty() ? -1 : mesh.triangle_materials[f]; };
        auto group = [&](std::size_t f) { return mesh.triangle_groups.empty() ? -1 : mesh.triangle_groups[f]; };
        std::size_t longest_name = 0;
        for (const auto& m : mesh.materials) longest_name = std::max(longest_name, m.name.size());
        for (const auto& g : mesh.groups) longest_name = std::max(longest_name, g.size());
        encode_chunks(mesh.triangles.size(), chunks, [&](std::size_t b, std::size_t e, std::string& s) {
            TextChunk t(s, (e - b) * (2 + 3 * 36 + 2 * (8 + longest_name + 1)));
            for (std::size_t f = b; f < e; ++f) {
                // A group statement where the group changes ("g" alone where a face has none after one that had).
                if (f == 0 ? group(f) >= 0 : group(f) != group(f - 1)) {
                    t.text("g");
                    if (group(f) >= 0) t.put(' '), t.text(mesh.groups[std::size_t(group(f))]);
                    t.put('\n');
                }
                // A material statement where the material changes, and before the first face that has one.
                if (material(f) >= 0 && (f == 0 || material(f) != material(f - 1)))
                    t.text("usemtl "), t.text(mesh.materials[std::size_t(material(f))].name), t.put('\n');
                auto all = [f](const std::vector<std::array<std::int32_t, 3>>& of_corner) {
                    return !of_corner.empty() && of_corner[f][0] >= 0 && of_corner[f][1] >= 0 && of_corner[f][2] >= 0;
                };
                const bool uvs = all(mesh.triangle_uvs), normals = all(mesh.triangle_normals);
                t.text("f ");
                for (std::size_t c = 0; c < 3; ++c) {
                    t.integer(std::int64_t(mesh.triangles[f][c]) + 1);
                    if (uvs || normals) t.put('/');
                    if (uvs) t.integer(std::int64_t(mesh.triangle_uvs[f][c]) + 1);
                    if (normals) t.put('/'), t.integer(std::int64_t(mesh.triangle_normals[f][c]) + 1);
                    t.put(c < 2 ? ' ' : '\n');
                }
            }
        });
    }
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

Chunks ply(const TriangleMesh& mesh, bool attributes) {
    const bool uvs = attributes && !mesh.triangle_uvs.empty(), normals = attributes && !mesh.triangle_normals.empty(),
               colours = attributes && !mesh.colours.empty(), split_any = uvs || normals;
    SeamSplit split;
    if (split_any) split = split_at_seams(mesh);
    const std::size_t nv = split_any ? split.vertex_of.size() : mesh.vertices.size();
    Chunks chunks{"ply\nformat binary_little_endian 1.0\ncomment voxwarp\nelement vertex " + std::to_string(nv) +
                  "\nproperty float x\nproperty float y\nproperty float z\n" + (uvs ? "property float s\nproperty float t\n" : "") +
                  (normals ? "property float nx\nproperty float ny\nproperty float nz\n" : "") +
                  (colours ? "property uchar red\nproperty uchar green\nproperty uchar blue\n" : "") + "element face " + std::to_string(mesh.face_count()) +
                  "\nproperty list uchar int vertex_indices\nend_header\n"};
    const std::size_t stride = 12 + (uvs ? 8 : 0) + (normals ? 12 : 0) + (colours ? 3 : 0);
    encode_chunks(nv, chunks, [&](std::size_t b, std::size_t e, std::string& s) {
        s.resize((e - b) * stride);
        char* at = s.data();
        for (std::size_t i = b; i < e; ++i) {
            const std::size_t v = split_any ? std::size_t(split.vertex_of[i]) : i;
            at = put(put(put(at, float(mesh.vertices[v].x())), float(mesh.vertices[v].y())), float(mesh.vertices[v].z()));
            if (uvs) {
                const Eigen::Vector2d uv = split.uv_of[i] >= 0 ? mesh.uvs[std::size_t(split.uv_of[i])] : Eigen::Vector2d::Zero();
                at = put(put(at, float(uv.x())), float(uv.y()));
            }
            if (normals) {
                const Eigen::Vector3d n = split.normal_of[i] >= 0 ? mesh.normals[std::size_t(split.normal_of[i])] : Eigen::Vector3d::Zero();
                at = put(put(put(at, float(n.x())), float(n.y())), float(n.z()));
            }
            if (colours)
                for (int a = 0; a < 3; ++a) at = put(at, std::uint8_t(std::lround(std::clamp(mesh.colours[v][a], 0.0f, 1.0f) * 255.0f)));
        }
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
    faces(split_any ? split.triangles : mesh.triangles, 3);
    faces(mesh.quads, 4);
    return chunks;
}

} // namespace mesh_write_internal

std::vector<std::string> encode_mesh_chunks(const TriangleMesh& mesh, const std::string& extension, const std::string& material_library) {
    using namespace mesh_write_internal;
    if (extension == ".ply") return ply(mesh, true);
    if (extension == ".stl") return stl(mesh);
    if (extension == ".obj") return obj(mesh, material_library);
    if (extension == ".off") return off(mesh);
    throw InvalidInput("no direct encoder for '" + extension + "' meshes");
}

std::string encode_mesh(const TriangleMesh& mesh, const std::string& extension, const std::string& material_library) {
    const auto chunks = encode_mesh_chunks(mesh, extension, material_library);
    std::size_t size = 0;
    for (const auto& c : chunks) size += c.size();
    std::string out;
    out.reserve(size);
    for (const auto& c : chunks) out += c;
    return out;
}

std::string encode_ply(const TriangleMesh& mesh) {
    const auto chunks = mesh_write_internal::ply(mesh, false);
    std::string out;
    for (const auto& c : chunks) out += c;
    return out;
}

} // namespace voxwarp
