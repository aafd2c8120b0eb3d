// glTF 2.0 (.gltf, .glb) through Debian's tinygltf: positions, texture coordinates (TEXCOORD_0), normals (NORMAL), vertex colours
// (COLOR_0) and materials (base colour and its texture) in and out. glTF splits vertices where texture coordinates or normals
// differ; reading welds them again by position (exactly equal coordinates), so a closed model stays closed for
// voxelizing, each corner keeping its own texture coordinate. glTF's texture v runs down the image, OBJ's up:
// voxwarp keeps OBJ's, flipping on the way in and out.
#include "gltf_io.h"
#include "mesh_validate.h"
#include "weld.h"

#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>
#include <voxwarp_internal/messages.h>

#include <tiny_gltf.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <unordered_map>

namespace voxwarp::mesh_io_internal {

namespace {

namespace fs = std::filesystem;

// Images are carried, not shown: keep their encoded bytes as they are.
bool keep_image_bytes(tinygltf::Image* image, const int, std::string*, std::string*, int, int, const unsigned char* bytes, int size, void*) {
    image->image.assign(bytes, bytes + size);
    image->as_is = true;
    return true;
}

// Written images keep the URI (a file beside the output) or their buffer view (.glb) they were given.
bool keep_image_uri(const std::string*, const std::string*, const tinygltf::Image* image, bool, std::string* out_uri, void*) {
    *out_uri = image->uri;
    return true;
}

/// Element `i` of an accessor as up to four doubles (normalized integers scaled to [0, 1]).
class AccessorReader {
public:
    AccessorReader(const tinygltf::Model& model, int index, const std::string& path, const std::string& what) : path_(path), what_(what) {
        if (index < 0 || index >= int(model.accessors.size())) fail("refers to accessor " + std::to_string(index));
        accessor_ = &model.accessors[std::size_t(index)];
        if (accessor_->bufferView < 0 || accessor_->bufferView >= int(model.bufferViews.size())) fail("has no buffer view (sparse accessors are not read)");
        const auto& view = model.bufferViews[std::size_t(accessor_->bufferView)];
        if (view.buffer < 0 || view.buffer >= int(model.buffers.size())) fail("refers to a missing buffer");
        const auto& buffer = model.buffers[std::size_t(view.buffer)].data;
        components_ = tinygltf::GetNumComponentsInType(std::uint32_t(accessor_->type));
        size_ = tinygltf::GetComponentSizeInBytes(std::uint32_t(accessor_->componentType));
        if (components_ <= 0 || size_ <= 0) fail("has an unknown type");
        stride_ = view.byteStride > 0 ? view.byteStride : std::size_t(components_ * size_);
        const std::size_t start = view.byteOffset + accessor_->byteOffset;
        const std::size_t need = accessor_->count == 0 ? 0 : start + stride_ * (accessor_->count - 1) + std::size_t(components_ * size_);
        if (need > buffer.size() || view.byteOffset + view.byteLength > buffer.size()) fail("reaches past the end of its buffer");
        data_ = buffer.data() + start;
    }
    std::size_t count() const { return accessor_->count; }
    int components() const { return components_; }
    double get(std::size_t i, int c) const {
        const unsigned char* p = data_ + i * stride_ + std::size_t(c * size_);
        const bool normalized = accessor_->normalized;
        switch (accessor_->componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: { float x; std::memcpy(&x, p, 4); return x; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return normalized ? *p / 255.0 : *p;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { std::uint16_t x; std::memcpy(&x, p, 2); return normalized ? x / 65535.0 : x; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { std::uint32_t x; std::memcpy(&x, p, 4); return x; }
        case TINYGLTF_COMPONENT_TYPE_BYTE: { std::int8_t x; std::memcpy(&x, p, 1); return normalized ? std::max(x / 127.0, -1.0) : x; }
        case TINYGLTF_COMPONENT_TYPE_SHORT: { std::int16_t x; std::memcpy(&x, p, 2); return normalized ? std::max(x / 32767.0, -1.0) : x; }
        default: fail("has component type " + std::to_string(accessor_->componentType));
        }
        return 0;
    }

private:
    [[noreturn]] void fail(const std::string& what) const { throw InvalidInput(path_ + ": " + what_ + " " + what); }
    const tinygltf::Accessor* accessor_ = nullptr;
    const unsigned char* data_ = nullptr;
    std::size_t stride_ = 0;
    int components_ = 0, size_ = 0;
    std::string path_, what_;
};

/// A node's local transform (matrix, or translation * rotation * scale).
Eigen::Matrix4d local_transform(const tinygltf::Node& node) {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    if (node.matrix.size() == 16) {
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r) m(r, c) = node.matrix[std::size_t(4 * c + r)];
        return m;
    }
    Eigen::Affine3d a = Eigen::Affine3d::Identity();
    if (node.translation.size() == 3) a.translate(Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2]));
    if (node.rotation.size() == 4) a.rotate(Eigen::Quaterniond(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]).normalized());
    if (node.scale.size() == 3) a.scale(Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2]));
    return a.matrix();
}

std::string mime_of(const std::string& file) {
    std::string ext = fs::path(file).extension().string();
    for (auto& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext == ".jpg" || ext == ".jpeg" ? "image/jpeg" : "image/png";
}

} // namespace

TriangleMesh read_gltf(const std::string& path, bool binary, std::vector<std::string>& warnings) {
    tinygltf::TinyGLTF loader;
    loader.SetImageLoader(keep_image_bytes, nullptr);
    tinygltf::Model model;
    std::string err, warn;
    const bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path) : loader.LoadASCIIFromFile(&model, &err, &warn, path);
    if (!ok) throw InvalidInput(path + ": cannot parse as glTF" + (err.empty() ? std::string() : ": " + internal::excerpt(err)));
    if (!warn.empty()) warnings.push_back(path + ": " + internal::excerpt(warn));
    const fs::path folder = fs::path(path).parent_path();

    TriangleMesh mesh;
    // Materials: glTF's index -> ours (only those a primitive uses).
    std::map<int, std::int32_t> material_of;
    auto material = [&](int index) -> std::int32_t {
        if (index < 0 || index >= int(model.materials.size())) return -1;
        const auto [it, added] = material_of.try_emplace(index, std::int32_t(mesh.materials.size()));
        if (!added) return it->second;
        const auto& g = model.materials[std::size_t(index)];
        Material m;
        m.name = g.name.empty() ? "material" + std::to_string(index) : g.name;
        const auto& f = g.pbrMetallicRoughness.baseColorFactor;
        if (f.size() >= 3) m.diffuse = Eigen::Vector3d(f[0], f[1], f[2]);
        const int t = g.pbrMetallicRoughness.baseColorTexture.index;
        if (t >= 0 && t < int(model.textures.size()) && model.textures[std::size_t(t)].source >= 0 &&
            model.textures[std::size_t(t)].source < int(model.images.size())) {
            const auto& image = model.images[std::size_t(model.textures[std::size_t(t)].source)];
            if (!image.uri.empty() && image.uri.rfind("data:", 0) != 0) {
                m.texture = (folder / image.uri).lexically_normal().string();
                std::error_code ec;
                if (!fs::exists(m.texture, ec)) warnings.push_back(path + ": material '" + m.name + "': texture " + m.texture + " not found");
            } else if (!image.image.empty()) { // embedded: carried as bytes, named after the image
                const std::string ext = image.mimeType == "image/jpeg" ? ".jpg" : ".png";
                m.texture = (image.name.empty() ? "texture" + std::to_string(model.textures[std::size_t(t)].source) : image.name) + ext;
                m.texture_bytes.assign(image.image.begin(), image.image.end());
            }
        }
        mesh.materials.push_back(std::move(m));
        return it->second;
    };
    // Vertices welded by exact position, so that a model glTF split at its seams is closed again.
    std::unordered_map<Eigen::Vector3d, std::int32_t, PositionHash> weld;
    bool any_uv = false, any_normal = false, any_colour = false;

    auto add_primitive = [&](const tinygltf::Primitive& p, const Eigen::Matrix4d& transform, const std::string& where) {
        if (p.mode != -1 && p.mode != TINYGLTF_MODE_TRIANGLES) {
            warnings.push_back(path + ": " + where + " is not a triangle list (mode " + std::to_string(p.mode) + "); skipped");
            return;
        }
        const auto position = p.attributes.find("POSITION");
        if (position == p.attributes.end()) throw InvalidInput(path + ": " + where + " has no POSITION");
        const AccessorReader positions(model, position->second, path, where + " POSITION");
        if (positions.components() != 3) throw InvalidInput(path + ": " + where + " POSITION is not a 3-vector");
        std::vector<std::int32_t> vertex(positions.count());
        for (std::size_t i = 0; i < positions.count(); ++i) {
            const Eigen::Vector3d local(positions.get(i, 0), positions.get(i, 1), positions.get(i, 2));
            const Eigen::Vector3d q = (transform * local.homogeneous()).head<3>();
            if (!q.allFinite()) throw InvalidInput(path + ": " + where + " vertex " + std::to_string(i) + " has a non-finite coordinate");
            const auto [it, added] = weld.try_emplace(q, std::int32_t(mesh.vertices.size()));
            if (added) mesh.vertices.push_back(q);
            vertex[i] = it->second;
        }
        std::int32_t uv_base = -1;
        if (const auto t = p.attributes.find("TEXCOORD_0"); t != p.attributes.end()) {
            const AccessorReader uvs(model, t->second, path, where + " TEXCOORD_0");
            if (uvs.components() != 2 || uvs.count() != positions.count()) throw InvalidInput(path + ": " + where + " TEXCOORD_0 does not match POSITION");
            uv_base = std::int32_t(mesh.uvs.size());
            for (std::size_t i = 0; i < uvs.count(); ++i) {
                const Eigen::Vector2d uv(uvs.get(i, 0), 1.0 - uvs.get(i, 1));
                if (!uv.allFinite()) throw InvalidInput(path + ": " + where + " texture coordinate " + std::to_string(i) + " is not finite");
                mesh.uvs.push_back(uv);
            }
            any_uv = true;
        }
        std::int32_t normal_base = -1;
        if (const auto t = p.attributes.find("NORMAL"); t != p.attributes.end()) {
            const AccessorReader normals(model, t->second, path, where + " NORMAL");
            if (normals.components() != 3 || normals.count() != positions.count()) throw InvalidInput(path + ": " + where + " NORMAL does not match POSITION");
            const Eigen::Matrix3d to_world = transform.topLeftCorner<3, 3>().inverse().transpose(); // normals go with the inverse transpose
            normal_base = std::int32_t(mesh.normals.size());
            for (std::size_t i = 0; i < normals.count(); ++i) {
                const Eigen::Vector3d n = to_world * Eigen::Vector3d(normals.get(i, 0), normals.get(i, 1), normals.get(i, 2));
                if (!n.allFinite()) throw InvalidInput(path + ": " + where + " normal " + std::to_string(i) + " is not finite");
                mesh.normals.push_back(n.norm() > 0 ? Eigen::Vector3d(n.normalized()) : n);
            }
            any_normal = true;
        }
        if (const auto c = p.attributes.find("COLOR_0"); c != p.attributes.end()) {
            const AccessorReader colours(model, c->second, path, where + " COLOR_0");
            if (colours.components() < 3 || colours.count() != positions.count()) throw InvalidInput(path + ": " + where + " COLOR_0 does not match POSITION");
            mesh.colours.resize(mesh.vertices.size(), Eigen::Vector3f::Ones());
            for (std::size_t i = 0; i < colours.count(); ++i)
                mesh.colours[std::size_t(vertex[i])] = Eigen::Vector3f(float(colours.get(i, 0)), float(colours.get(i, 1)), float(colours.get(i, 2))).cwiseMax(0.0f).cwiseMin(1.0f);
            any_colour = true;
        }
        std::vector<std::size_t> corners;
        if (p.indices >= 0) {
            const AccessorReader indices(model, p.indices, path, where + " indices");
            for (std::size_t i = 0; i < indices.count(); ++i) {
                const double k = indices.get(i, 0);
                if (!(k >= 0 && k < double(positions.count())))
                    throw InvalidInput(path + ": " + where + " index " + std::to_string(i) + " refers to vertex " + std::to_string(std::int64_t(k)) + ", it has " +
                                       std::to_string(positions.count()));
                corners.push_back(std::size_t(k));
            }
        } else {
            for (std::size_t i = 0; i < positions.count(); ++i) corners.push_back(i);
        }
        if (corners.size() % 3 != 0) throw InvalidInput(path + ": " + where + " has " + std::to_string(corners.size()) + " indices, not a multiple of 3");
        const std::int32_t m = material(p.material);
        const bool mirrored = transform.topLeftCorner<3, 3>().determinant() < 0; // keep faces wound outwards
        for (std::size_t i = 0; i < corners.size(); i += 3) {
            std::array<std::size_t, 3> k{corners[i], corners[i + 1], corners[i + 2]};
            if (mirrored) std::swap(k[1], k[2]);
            mesh.triangles.push_back({vertex[k[0]], vertex[k[1]], vertex[k[2]]});
            mesh.triangle_uvs.push_back(uv_base < 0 ? std::array<std::int32_t, 3>{-1, -1, -1}
                                                    : std::array<std::int32_t, 3>{uv_base + std::int32_t(k[0]), uv_base + std::int32_t(k[1]), uv_base + std::int32_t(k[2])});
            mesh.triangle_normals.push_back(normal_base < 0 ? std::array<std::int32_t, 3>{-1, -1, -1}
                                                            : std::array<std::int32_t, 3>{normal_base + std::int32_t(k[0]), normal_base + std::int32_t(k[1]),
                                                                                          normal_base + std::int32_t(k[2])});
            mesh.triangle_materials.push_back(m);
        }
    };
    // The default scene's nodes, transforms applied; a file without scenes: every mesh as it is.
    std::vector<bool> seen(model.nodes.size(), false);
    std::function<void(int, const Eigen::Matrix4d&)> visit = [&](int n, const Eigen::Matrix4d& parent) {
        if (n < 0 || n >= int(model.nodes.size()) || seen[std::size_t(n)]) return; // a cycle, or a node used twice
        seen[std::size_t(n)] = true;
        const auto& node = model.nodes[std::size_t(n)];
        const Eigen::Matrix4d transform = parent * local_transform(node);
        if (node.mesh >= 0 && node.mesh < int(model.meshes.size()))
            for (std::size_t p = 0; p < model.meshes[std::size_t(node.mesh)].primitives.size(); ++p)
                add_primitive(model.meshes[std::size_t(node.mesh)].primitives[p], transform, "mesh " + std::to_string(node.mesh) + " primitive " + std::to_string(p));
        for (const int child : node.children) visit(child, transform);
    };
    const int scene = model.defaultScene >= 0 ? model.defaultScene : 0;
    if (scene < int(model.scenes.size())) {
        for (const int n : model.scenes[std::size_t(scene)].nodes) visit(n, Eigen::Matrix4d::Identity());
    } else {
        for (std::size_t m = 0; m < model.meshes.size(); ++m)
            for (std::size_t p = 0; p < model.meshes[m].primitives.size(); ++p)
                add_primitive(model.meshes[m].primitives[p], Eigen::Matrix4d::Identity(), "mesh " + std::to_string(m) + " primitive " + std::to_string(p));
    }
    if (!any_uv) mesh.uvs.clear(), mesh.triangle_uvs.clear();
    if (!any_normal) mesh.normals.clear(), mesh.triangle_normals.clear();
    if (!any_colour) mesh.colours.clear();
    else mesh.colours.resize(mesh.vertices.size(), Eigen::Vector3f::Ones());
    if (mesh.materials.empty()) mesh.triangle_materials.clear();
    return mesh;
}

void write_gltf(const TriangleMesh& mesh, const std::string& path, bool binary) {
    if (!mesh.quads.empty()) throw InvalidInput(path + ": glTF output takes triangles; the mesh has quads");
    const fs::path folder = fs::path(path).parent_path();
    tinygltf::Model model;
    model.asset.version = "2.0";
    model.asset.generator = "voxwarp";
    model.buffers.resize(1);
    auto& bytes = model.buffers[0].data;
    auto view = [&](const void* data, std::size_t size, int target) {
        while (bytes.size() % 4) bytes.push_back(0);
        tinygltf::BufferView v;
        v.buffer = 0, v.byteOffset = bytes.size(), v.byteLength = size, v.target = target;
        const auto* p = static_cast<const unsigned char*>(data);
        bytes.insert(bytes.end(), p, p + size);
        model.bufferViews.push_back(v);
        return int(model.bufferViews.size() - 1);
    };
    auto accessor = [&](int buffer_view, int component, int type, std::size_t count, std::vector<double> min = {}, std::vector<double> max = {}) {
        tinygltf::Accessor a;
        a.bufferView = buffer_view, a.componentType = component, a.type = type, a.count = count, a.minValues = std::move(min), a.maxValues = std::move(max);
        model.accessors.push_back(a);
        return int(model.accessors.size() - 1);
    };

    // glTF keeps texture coordinates and normals per vertex: a vertex on a seam or a hard edge is written once per
    // (texture coordinate, normal) it has.
    const bool uvs = !mesh.triangle_uvs.empty(), normals = !mesh.triangle_normals.empty();
    const SeamSplit split = split_at_seams(mesh);
    const std::vector<std::int32_t>&vertex_of = split.vertex_of, &uv_of = split.uv_of, &normal_of = split.normal_of;
    std::vector<std::array<std::uint32_t, 3>> faces(mesh.triangles.size());
    for (std::size_t f = 0; f < faces.size(); ++f)
        for (std::size_t c = 0; c < 3; ++c) faces[f][c] = std::uint32_t(split.triangles[f][c]);
    std::vector<float> positions, texcoords, normal_values, colours;
    std::vector<double> lo(3, std::numeric_limits<double>::infinity()), hi(3, -std::numeric_limits<double>::infinity());
    for (std::size_t i = 0; i < vertex_of.size(); ++i) {
        const Eigen::Vector3d& p = mesh.vertices[std::size_t(vertex_of[i])];
        for (int a = 0; a < 3; ++a) {
            positions.push_back(float(p[a]));
            lo[std::size_t(a)] = std::min(lo[std::size_t(a)], double(float(p[a]))), hi[std::size_t(a)] = std::max(hi[std::size_t(a)], double(float(p[a])));
        }
        if (uvs) {
            const Eigen::Vector2d uv = uv_of[i] >= 0 ? mesh.uvs[std::size_t(uv_of[i])] : Eigen::Vector2d::Zero();
            texcoords.push_back(float(uv.x())), texcoords.push_back(float(1.0 - uv.y()));
        }
        if (normals) { // glTF wants unit normals: a corner without one gets +z
            const Eigen::Vector3d n = normal_of[i] >= 0 && mesh.normals[std::size_t(normal_of[i])].norm() > 0 ? mesh.normals[std::size_t(normal_of[i])].normalized()
                                                                                                         : Eigen::Vector3d::UnitZ();
            for (int a = 0; a < 3; ++a) normal_values.push_back(float(n[a]));
        }
        if (!mesh.colours.empty())
            for (int a = 0; a < 3; ++a) colours.push_back(mesh.colours[std::size_t(vertex_of[i])][a]);
    }
    tinygltf::Primitive base;
    base.mode = TINYGLTF_MODE_TRIANGLES;
    base.attributes["POSITION"] = accessor(view(positions.data(), positions.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER), TINYGLTF_COMPONENT_TYPE_FLOAT,
                                           TINYGLTF_TYPE_VEC3, vertex_of.size(), lo, hi);
    if (uvs)
        base.attributes["TEXCOORD_0"] =
            accessor(view(texcoords.data(), texcoords.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER), TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2, vertex_of.size());
    if (normals)
        base.attributes["NORMAL"] = accessor(view(normal_values.data(), normal_values.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER), TINYGLTF_COMPONENT_TYPE_FLOAT,
                                             TINYGLTF_TYPE_VEC3, vertex_of.size());
    if (!colours.empty())
        base.attributes["COLOR_0"] =
            accessor(view(colours.data(), colours.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER), TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, vertex_of.size());

    // Materials, each with its base colour texture: embedded in a .glb, a file beside a .gltf.
    for (std::size_t i = 0; i < mesh.materials.size(); ++i) {
        const Material& m = mesh.materials[i];
        tinygltf::Material g;
        g.name = m.name;
        g.pbrMetallicRoughness.baseColorFactor = {m.diffuse.x(), m.diffuse.y(), m.diffuse.z(), 1.0};
        g.pbrMetallicRoughness.metallicFactor = 0.0; // OBJ's diffuse materials are not metal
        g.pbrMetallicRoughness.roughnessFactor = 1.0;
        if (!m.texture.empty()) {
            tinygltf::Image image;
            image.name = fs::path(m.texture).stem().string();
            image.mimeType = mime_of(m.texture);
            std::string data = m.texture_bytes;
            if (binary && data.empty()) {
                std::ifstream in(m.texture, std::ios::binary);
                data.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
                if (!in && data.empty()) throw IOError(path + ": material '" + m.name + "': cannot read its texture " + m.texture + " to embed it");
            }
            if (binary) {
                image.bufferView = view(data.data(), data.size(), 0);
            } else if (!m.texture_bytes.empty()) { // an embedded texture going to a .gltf: a file beside it
                const std::string name = fs::path(path).stem().string() + "_" + fs::path(m.texture).filename().string();
                write_file_atomically((folder / name).string(), data, "the texture");
                image.uri = name;
            } else {
                image.uri = path_from_folder(m.texture, folder.string());
            }
            model.images.push_back(image);
            tinygltf::Texture texture;
            texture.source = int(model.images.size() - 1);
            model.textures.push_back(texture);
            g.pbrMetallicRoughness.baseColorTexture.index = int(model.textures.size() - 1);
        }
        model.materials.push_back(g);
    }
    // One primitive per material (in order of first use), sharing the vertex accessors.
    tinygltf::Mesh out_mesh;
    out_mesh.name = "voxwarp";
    std::map<std::int32_t, std::vector<std::uint32_t>> by_material;
    std::vector<std::int32_t> order;
    for (std::size_t f = 0; f < faces.size(); ++f) {
        const std::int32_t m = mesh.triangle_materials.empty() ? -1 : mesh.triangle_materials[f];
        auto [it, added] = by_material.try_emplace(m);
        if (added) order.push_back(m);
        it->second.insert(it->second.end(), faces[f].begin(), faces[f].end());
    }
    for (const std::int32_t m : order) {
        const auto& indices = by_material[m];
        tinygltf::Primitive p = base;
        p.indices = accessor(view(indices.data(), indices.size() * 4, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER), TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                             TINYGLTF_TYPE_SCALAR, indices.size());
        p.material = m;
        out_mesh.primitives.push_back(p);
    }
    model.meshes.push_back(out_mesh);
    tinygltf::Node node;
    node.mesh = 0;
    model.nodes.push_back(node);
    tinygltf::Scene scene;
    scene.nodes = {0};
    model.scenes.push_back(scene);
    model.defaultScene = 0;

    tinygltf::TinyGLTF writer;
    writer.SetImageWriter(keep_image_uri, nullptr);
    write_atomically(path, [&](const std::string& tmp) {
        // A .gltf holds its buffer as a data URI: one file (and its textures) to move around.
        if (!writer.WriteGltfSceneToFile(&model, tmp, false, true, !binary, binary)) throw IOError(path + ": writing glTF failed");
    });
}

} // namespace voxwarp::mesh_io_internal
