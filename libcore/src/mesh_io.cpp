#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include "gltf_io.h"
#include "mesh_validate.h"
#include "weld.h"

#include <OpenMesh/Core/IO/IOManager.hh>
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/IO/importer/BaseImporter.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <unordered_map>

namespace voxwarp {

namespace mesh_io_internal {

using namespace OpenMesh;

/// Receives what OpenMesh's readers parse as a plain polygon list. Unlike ImporterT on a halfedge mesh it
/// refuses nothing, so faces at non-manifold edges and vertices survive; problems are recorded, not printed.
class SoupImporter final : public IO::BaseImporter {
public:
    TriangleMesh mesh;
    std::string first_problem;
    std::size_t polygon_count = 0;

    VertexHandle add_vertex(const Vec3f& p) override { return add_vertex(Vec3d(p)); }
    VertexHandle add_vertex(const Vec3d& p) override {
        if (first_problem.empty() && !(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])))
            first_problem = "vertex " + std::to_string(mesh.vertices.size() + 1) + " has a non-finite coordinate";
        mesh.vertices.emplace_back(p[0], p[1], p[2]);
        return VertexHandle(int(mesh.vertices.size() - 1));
    }
    VertexHandle add_vertex() override { return add_vertex(Vec3d(0, 0, 0)); }
    FaceHandle add_face(const VHandles& ids) override {
        ++polygon_count;
        const auto face_no = std::to_string(polygon_count);
        if (ids.size() < 3) {
            note("face " + face_no + " has " + std::to_string(ids.size()) + " vertices, expected at least 3");
            return FaceHandle();
        }
        for (const auto& vh : ids)
            if (!vh.is_valid() || vh.idx() >= int(mesh.vertices.size())) {
                note("face " + face_no + " refers to vertex " + std::to_string(vh.idx() + 1) + ", file has " +
                     std::to_string(mesh.vertices.size()) + " vertices");
                return FaceHandle();
            }
        for (std::size_t c = 1; c + 1 < ids.size(); ++c)
            mesh.triangles.push_back({ids[0].idx(), ids[c].idx(), ids[c + 1].idx()});
        return FaceHandle(int(polygon_count - 1));
    }
    void note(std::string problem) {
        if (first_problem.empty()) first_problem = std::move(problem);
    }

    // What a plain polygon list has no use for.
    HalfedgeHandle add_edge(VertexHandle, VertexHandle) override { return HalfedgeHandle(); }
    FaceHandle add_face(HalfedgeHandle) override { return FaceHandle(); }
    void add_face_texcoords(FaceHandle, VertexHandle, const std::vector<Vec2f>&) override {}
    void add_face_texcoords(FaceHandle, VertexHandle, const std::vector<Vec3f>&) override {}
    void set_face_texindex(FaceHandle, int) override {}
    void set_point(VertexHandle vh, const Vec3f& p) override {
        if (vh.is_valid() && vh.idx() < int(mesh.vertices.size())) mesh.vertices[vh.idx()] = Eigen::Vector3d(p[0], p[1], p[2]);
    }
    void set_halfedge(VertexHandle, HalfedgeHandle) override {}
    void set_normal(VertexHandle vh, const Vec3f& n) override { set_normal(vh, Vec3d(n[0], n[1], n[2])); }
    /// Per-vertex normals (PLY's nx ny nz): the vertex's own index into normals.
    void set_normal(VertexHandle vh, const Vec3d& n) override {
        if (!vh.is_valid() || vh.idx() >= int(mesh.vertices.size())) return;
        mesh.normals.resize(mesh.vertices.size(), Eigen::Vector3d::Zero());
        const Eigen::Vector3d v(n[0], n[1], n[2]);
        mesh.normals[std::size_t(vh.idx())] = v.norm() > 0 ? Eigen::Vector3d(v.normalized()) : v;
    }
    void set_color(VertexHandle vh, const Vec3uc& c) override { set_color(vh, Vec3f(c[0], c[1], c[2]) / 255.0f); }
    void set_color(VertexHandle vh, const Vec4uc& c) override { set_color(vh, Vec3f(c[0], c[1], c[2]) / 255.0f); }
    void set_color(VertexHandle vh, const Vec4f& c) override { set_color(vh, Vec3f(c[0], c[1], c[2])); }
    void set_color(VertexHandle vh, const Vec3f& c) override {
        if (!vh.is_valid() || vh.idx() >= int(mesh.vertices.size())) return;
        mesh.colours.resize(mesh.vertices.size(), Eigen::Vector3f::Ones());
        mesh.colours[std::size_t(vh.idx())] = Eigen::Vector3f(c[0], c[1], c[2]).cwiseMax(0.0f).cwiseMin(1.0f);
    }
    /// Per-vertex texture coordinates (PLY's s t): the vertex's own index into uvs.
    void set_texcoord(VertexHandle vh, const Vec2f& t) override {
        if (!vh.is_valid() || vh.idx() >= int(mesh.vertices.size())) return;
        mesh.uvs.resize(mesh.vertices.size(), Eigen::Vector2d::Zero());
        mesh.uvs[std::size_t(vh.idx())] = Eigen::Vector2d(t[0], t[1]);
    }
    void set_status(VertexHandle, const Attributes::StatusInfo&) override {}
    void set_next(HalfedgeHandle, HalfedgeHandle) override {}
    void set_face(HalfedgeHandle, FaceHandle) override {}
    void request_face_texcoords2D() override {}
    void set_texcoord(HalfedgeHandle, const Vec2f&) override {}
    void set_texcoord(VertexHandle, const Vec3f&) override {}
    void set_texcoord(HalfedgeHandle, const Vec3f&) override {}
    void set_status(HalfedgeHandle, const Attributes::StatusInfo&) override {}
    void set_color(EdgeHandle, const Vec3uc&) override {}
    void set_color(EdgeHandle, const Vec4uc&) override {}
    void set_color(EdgeHandle, const Vec3f&) override {}
    void set_color(EdgeHandle, const Vec4f&) override {}
    void set_status(EdgeHandle, const Attributes::StatusInfo&) override {}
    void set_normal(FaceHandle, const Vec3f&) override {}
    void set_normal(FaceHandle, const Vec3d&) override {}
    void set_color(FaceHandle, const Vec3uc&) override {}
    void set_color(FaceHandle, const Vec4uc&) override {}
    void set_color(FaceHandle, const Vec3f&) override {}
    void set_color(FaceHandle, const Vec4f&) override {}
    void set_status(FaceHandle, const Attributes::StatusInfo&) override {}
    void add_texture_information(int, std::string) override {}
    size_t n_vertices() const override { return mesh.vertices.size(); }
    size_t n_faces() const override { return polygon_count; }
    size_t n_edges() const override { return 0; }
};

struct DoubleTraits : DefaultTraits {
    using Point = Vec3d;
    using Normal = Vec3d;
};
using OutputMesh = PolyMesh_ArrayKernelT<DoubleTraits>;

std::string lower_extension(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext;
}

/// OpenMesh's readers and writers report through omerr/omlog; library code must not print.
struct QuietOpenMesh {
    QuietOpenMesh() {
        omerr().disable();
        omlog().disable();
        omout().disable();
    }
};

} // namespace mesh_io_internal

using namespace mesh_io_internal;

bool is_mesh_path(const std::string& path) {
    const auto ext = lower_extension(path);
    return ext == ".obj" || ext == ".off" || ext == ".ply" || ext == ".stl" || ext == ".om" || ext == ".gltf" || ext == ".glb";
}

namespace {

/// Drops each triangle whose three vertices (in any order or orientation) an earlier triangle already has, with its
/// attributes; returns how many. Counted twice, a face doubles its share of the enclosed volume and of the winding
/// number (a unit cube with one face repeated read 1.33).
std::size_t drop_repeated_triangles(TriangleMesh& mesh) {
    using Key = std::array<std::int32_t, 3>;
    std::vector<std::pair<Key, std::uint32_t>> keys(mesh.triangles.size());
    for (std::size_t t = 0; t < keys.size(); ++t) {
        Key k = mesh.triangles[t];
        std::sort(k.begin(), k.end());
        keys[t] = {k, std::uint32_t(t)};
    }
    std::sort(keys.begin(), keys.end());
    std::vector<char> keep(mesh.triangles.size(), 1);
    std::size_t dropped = 0;
    for (std::size_t i = 1; i < keys.size(); ++i)
        if (keys[i].first == keys[i - 1].first) keep[keys[i].second] = 0, ++dropped; // the sort leaves the first one first
    if (dropped == 0) return 0;
    auto compact = [&](auto& per_triangle) {
        if (per_triangle.empty()) return;
        std::size_t out = 0;
        for (std::size_t t = 0; t < keep.size(); ++t)
            if (keep[t]) per_triangle[out++] = per_triangle[t];
        per_triangle.resize(out);
    };
    compact(mesh.triangle_uvs);
    compact(mesh.triangle_normals);
    compact(mesh.triangle_materials);
    compact(mesh.triangle_groups);
    compact(mesh.triangles);
    return dropped;
}

} // namespace

void mesh_io_internal::weld_by_position(TriangleMesh& mesh) {
    std::unordered_map<Eigen::Vector3d, std::int32_t, PositionHash> first;
    first.reserve(mesh.vertices.size());
    std::vector<std::int32_t> to(mesh.vertices.size());
    std::size_t kept = 0;
    for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
        const auto [it, added] = first.try_emplace(mesh.vertices[v], std::int32_t(kept));
        if (added) {
            mesh.vertices[kept] = mesh.vertices[v];
            if (!mesh.colours.empty()) mesh.colours[kept] = mesh.colours[v];
            ++kept;
        }
        to[v] = it->second;
    }
    if (kept == mesh.vertices.size()) return;
    mesh.vertices.resize(kept);
    if (!mesh.colours.empty()) mesh.colours.resize(kept);
    for (auto& t : mesh.triangles)
        for (auto& c : t) c = to[std::size_t(c)];
}

namespace {

TriangleMesh read_mesh_as_written(const std::string& path, std::vector<std::string>* warnings) {
    static QuietOpenMesh quiet;
    namespace fs = std::filesystem;
    std::error_code ec;
    if (!fs::exists(path, ec)) throw IOError(path + ": no such file");
    if (fs::is_directory(path, ec)) throw IOError(path + ": is a directory, expected a mesh file");
    if (!is_mesh_path(path))
        throw InvalidInput(path + ": unknown mesh format '" + lower_extension(path) + "', expected .obj, .off, .ply, .stl, .om, .gltf or .glb");
    if (std::ifstream probe(path, std::ios::binary); !probe) throw IOError(path + ": cannot open for reading");
    const auto file_size = fs::file_size(path, ec);
    if (file_size == 0) throw InvalidInput(path + ": file is empty");
    std::vector<std::string> ignored;
    if (lower_extension(path) == ".gltf" || lower_extension(path) == ".glb") {
        TriangleMesh mesh = read_gltf(path, lower_extension(path) == ".glb", warnings ? *warnings : ignored);
        if (mesh.vertices.empty()) throw InvalidInput(path + ": no vertices");
        if (mesh.triangles.empty()) throw InvalidInput(path + ": no faces");
        check_attributes(mesh, path);
        return mesh;
    }
    if (TriangleMesh direct; read_mesh_directly(path, lower_extension(path), file_size, direct, warnings ? *warnings : ignored)) {
        if (direct.vertices.empty()) throw InvalidInput(path + ": no vertices");
        if (direct.triangles.empty()) throw InvalidInput(path + ": no faces");
        return direct;
    }
    validate_before_openmesh(path, lower_extension(path), file_size);

    SoupImporter importer;
    IO::Options options(IO::Options::VertexColor | IO::Options::VertexTexCoord | IO::Options::VertexNormal);
    if (!IO::IOManager().read(path, importer, options)) {
        throw InvalidInput(path + ": cannot parse as a " + lower_extension(path).substr(1) + " mesh" +
                           (importer.first_problem.empty() ? "" : ": " + importer.first_problem));
    }
    if (!importer.first_problem.empty()) throw InvalidInput(path + ": " + importer.first_problem);
    if (importer.mesh.vertices.empty()) throw InvalidInput(path + ": no vertices");
    if (importer.mesh.triangles.empty()) throw InvalidInput(path + ": no faces");
    TriangleMesh& mesh = importer.mesh;
    if (!mesh.colours.empty()) mesh.colours.resize(mesh.vertices.size(), Eigen::Vector3f::Ones());
    if (!mesh.uvs.empty()) {
        mesh.uvs.resize(mesh.vertices.size(), Eigen::Vector2d::Zero());
        mesh.triangle_uvs = mesh.triangles;
    }
    if (!mesh.normals.empty()) {
        mesh.normals.resize(mesh.vertices.size(), Eigen::Vector3d::Zero());
        mesh.triangle_normals = mesh.triangles;
    }
    for (std::size_t i = 0; i < mesh.uvs.size(); ++i)
        if (!mesh.uvs[i].allFinite()) throw InvalidInput(path + ": vertex " + std::to_string(i + 1) + " has a non-finite texture coordinate");
    check_attributes(mesh, path); // the normals
    // PLY holds texture coordinates and normals per vertex, so a writer (voxwarp's own) splits a vertex on a seam or
    // a hard edge into one per side: joined again, as glTF's are, the model is closed (Spot's head turn at 128 read
    // back with 5,324 boundary edges in 13 pieces), each corner keeping its side's coordinates.
    if (lower_extension(path) == ".ply" && (!mesh.triangle_uvs.empty() || !mesh.triangle_normals.empty())) weld_by_position(mesh);
    return std::move(mesh);
}

} // namespace

TriangleMesh read_mesh(const std::string& path, std::vector<std::string>* warnings) {
    TriangleMesh mesh = read_mesh_as_written(path, warnings);
    if (const std::size_t dropped = drop_repeated_triangles(mesh); dropped > 0 && warnings)
        warnings->push_back(path + ": " + std::to_string(dropped) + (dropped == 1 ? " triangle repeats" : " triangles repeat") +
                            " the corners of an earlier one; each is read once");
    return mesh;
}

void write_mesh(const TriangleMesh& mesh, const std::string& path) {
    static QuietOpenMesh quiet;
    if (!is_mesh_path(path))
        throw InvalidInput(path + ": unknown mesh format '" + lower_extension(path) + "', expected .obj, .off, .ply, .stl, .om, .gltf or .glb");
    if (lower_extension(path) != ".om") {
        if (lower_extension(path) == ".gltf" || lower_extension(path) == ".glb") return write_gltf(mesh, path, lower_extension(path) == ".glb");
        std::string library;
        if (lower_extension(path) == ".obj" && !mesh.materials.empty()) {
            const std::filesystem::path obj(path);
            library = obj.stem().string() + ".mtl";
            // A library of that name that voxwarp did not write (the input's own, say) is never overwritten.
            if (std::ifstream existing(obj.parent_path() / library); existing) {
                std::string first;
                std::getline(existing, first);
                if (first != "# voxwarp") library = obj.stem().string() + "_voxwarp.mtl";
            }
            const std::string library_path = (obj.parent_path() / library).string();
            // A texture that came embedded (a .glb's) becomes a file beside the output, which the library names.
            std::vector<Material> materials = mesh.materials;
            for (auto& m : materials) {
                if (m.texture_bytes.empty()) continue;
                const std::string file = (obj.parent_path() / (obj.stem().string() + "_" + std::filesystem::path(m.texture).filename().string())).string();
                write_file_atomically(file, m.texture_bytes, "the texture");
                m.texture = file, m.texture_bytes.clear();
            }
            write_file_atomically(library_path, encode_material_library(materials, obj.parent_path().string()), "the material library");
        }
        const auto chunks = encode_mesh_chunks(mesh, lower_extension(path), library);
        write_atomically(path, [&](const std::string& tmp) {
            std::ofstream out(tmp, std::ios::binary);
            for (const auto& c : chunks) out.write(c.data(), std::streamsize(c.size()));
            out.close();
            if (!out) throw IOError(path + ": writing the mesh failed");
        });
        return;
    }
    OutputMesh om;
    om.reserve(mesh.vertices.size(), 3 * mesh.face_count() / 2, mesh.face_count());
    std::vector<OutputMesh::VertexHandle> handles;
    handles.reserve(mesh.vertices.size());
    for (const auto& v : mesh.vertices) handles.push_back(om.add_vertex(OutputMesh::Point(v.x(), v.y(), v.z())));
    auto add = [&](const auto& face) {
        std::vector<OutputMesh::VertexHandle> ids;
        for (auto i : face) ids.push_back(handles[std::size_t(i)]);
        if (om.add_face(ids).is_valid()) return;
        // A face OpenMesh's halfedge structure refuses (non-manifold spot, e.g. a vertex-mode deform of a scan)
        // is written on its own copies of its vertices: the geometry is kept, the file stays readable.
        for (auto& h : ids) h = om.add_vertex(om.point(h));
        om.add_face(ids);
    };
    for (const auto& t : mesh.triangles) add(t);
    for (const auto& q : mesh.quads) add(q);

    const bool binary = lower_extension(path) == ".stl" || lower_extension(path) == ".om";
    IO::Options options = binary ? IO::Options(IO::Options::Binary) : IO::Options();
    write_atomically(path, [&](const std::string& tmp) {
        if (!IO::write_mesh(om, tmp, options, 10)) throw IOError(path + ": writing the mesh failed");
    });
}

} // namespace voxwarp
