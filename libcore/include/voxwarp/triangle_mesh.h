/// @file triangle_mesh.h
/// @brief A plain indexed polygon mesh (triangles and optional quads) with its attributes (texture coordinates,
///        per-corner normals, vertex colours, materials, groups): voxwarp's currency between libraries.
///
/// Positions are in world units. Faces index into `vertices` (0-based) and are counter-clockwise seen from
/// outside. The struct makes no manifoldness promise: a mesh read from a scan may be a triangle soup.
/// Attributes belong to triangles (a mesh with quads has none): each attribute array is either empty (absent) or
/// sized as documented.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace voxwarp {

/// A surface material as an OBJ material library (.mtl) names it. voxwarp does not shade with it; it carries it
/// from input to output, texture paths kept valid.
struct Material {
    std::string name;
    Eigen::Vector3d diffuse{0.8, 0.8, 0.8}; ///< Kd, RGB in [0, 1]
    std::string texture;                    ///< map_Kd: the diffuse texture's path, usable from the current directory; empty: none
    /// The material's other .mtl statements as read ("Ks 0 0 0", "map_Bump -bm 0.5 bump.png"), written back as they
    /// are, except that a texture map's file (the last word of a map_*, bump, disp, decal or norm line) is a path
    /// usable from the current directory, like `texture`.
    std::vector<std::string> statements;
    std::string texture_bytes; ///< the texture file's bytes when it came embedded (a .glb's); `texture` is then its name
};

struct TriangleMesh {
    std::vector<Eigen::Vector3d> vertices;          ///< #V positions, world units
    std::vector<std::array<std::int32_t, 3>> triangles; ///< #T vertex index triples
    std::vector<std::array<std::int32_t, 4>> quads;     ///< #Q vertex index quadruples (extraction only)

    std::vector<Eigen::Vector2d> uvs;                      ///< texture coordinates (OBJ's vt), shared by corners that index them
    std::vector<std::array<std::int32_t, 3>> triangle_uvs; ///< #T or empty: each triangle's corners' indices into uvs (-1: none)
    /// Shading normals (OBJ's vn, glTF's NORMAL), unit length, shared by corners that index them; where a model has
    /// hard edges, the corners on either side index different normals.
    std::vector<Eigen::Vector3d> normals;
    std::vector<std::array<std::int32_t, 3>> triangle_normals; ///< #T or empty: each triangle's corners' indices into normals (-1: none)
    std::vector<Eigen::Vector3f> colours;                  ///< #V or empty: vertex colours, RGB in [0, 1]
    std::vector<std::int32_t> triangle_materials;          ///< #T or empty: each triangle's index into materials (-1: none)
    std::vector<std::string> groups;                       ///< group names (OBJ's g and o statements, the rest of the line)
    std::vector<std::int32_t> triangle_groups;             ///< #T or empty: each triangle's index into groups (-1: none)
    std::vector<Material> materials;

    bool has_attributes() const {
        return !triangle_uvs.empty() || !triangle_normals.empty() || !colours.empty() || !triangle_materials.empty() || !triangle_groups.empty();
    }

    std::size_t face_count() const { return triangles.size() + quads.size(); }
    /// The same surface with every quad split into two triangles (along its shorter diagonal).
    TriangleMesh triangulated() const;
};

/// Every face as a triangle: `mesh.triangles` itself when the mesh has no quads, otherwise the triangles of
/// mesh.triangulated(), kept alive in `storage`. Avoids copying the common all-triangle mesh.
const std::vector<std::array<std::int32_t, 3>>& all_triangles(const TriangleMesh& mesh, TriangleMesh& storage);

/// Axis-aligned bounds of the vertices, world units. Empty mesh: min = +inf, max = -inf.
struct Bounds {
    Eigen::Vector3d min, max;
    Eigen::Vector3d size() const { return max - min; }
};
Bounds bounds(const TriangleMesh& mesh);

/// Topology facts a user checks first: is it a closed 2-manifold, what is its Euler characteristic.
struct MeshTopology {
    std::int64_t vertices = 0;           ///< vertices referenced by at least one face
    std::int64_t edges = 0;              ///< distinct undirected edges
    std::int64_t faces = 0;
    std::int64_t boundary_edges = 0;     ///< edges with one incident face
    std::int64_t nonmanifold_edges = 0;  ///< edges with three or more incident faces
    std::int64_t nonmanifold_vertices = 0; ///< vertices whose incident faces form more than one fan
    std::int64_t misoriented_edges = 0;  ///< two-face edges traversed in the same direction by both faces
    std::int64_t degenerate_faces = 0;   ///< faces with a repeated vertex index
    std::int64_t components = 0;         ///< connected components of faces (through shared vertices)
    std::int64_t euler = 0;              ///< V - E + F
    bool closed() const { return boundary_edges == 0; }
    bool manifold() const { return nonmanifold_edges == 0 && nonmanifold_vertices == 0; }
    bool oriented() const { return misoriented_edges == 0; }
    /// Closed, manifold and consistently oriented: a watertight solid boundary.
    bool watertight() const { return closed() && manifold() && oriented() && degenerate_faces == 0; }
};
MeshTopology topology(const TriangleMesh& mesh);

/// Check a mesh built in memory (from arrays, not read from a file): vertices finite, every face's indices within
/// the vertex list, at least one face with area. Indices in messages are 0-based, as the arrays'.
/// @throw InvalidInput whose message starts with `source` and says what is wrong (e.g. "F: face 12 refers to vertex
///        4001, the mesh has 1839 vertices").
void check_mesh(const TriangleMesh& mesh, const std::string& source);
/// The attribute part of check_mesh: array sizes, indices within uvs, normals, materials and groups, finite values.
void check_attributes(const TriangleMesh& mesh, const std::string& source);

/// Signed volume enclosed by a closed, outward-oriented mesh (divergence theorem), world units cubed.
double enclosed_volume(const TriangleMesh& mesh);

} // namespace voxwarp
