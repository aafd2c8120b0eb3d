/// @file transfer.h
/// @brief The input's attributes (texture coordinates, normals, vertex colours, materials, groups) given to a
///        re-polygonized output,
///        read at each output vertex's source point on the input (snap.h, find_sources).
///
/// Frames: attributes are read on the input surface, whatever warps lie between it and the output; normals, read in
/// the input frame, are carried through the warps to the output's.
#pragma once

#include <voxwarp/snap.h>
#include <voxwarp/triangle_mesh.h>

#include <vector>

namespace voxwarp {

/// What transfer_attributes did.
struct TransferReport {
    std::size_t triangles_across_charts = 0; ///< output triangles whose corners' sources lay in different charts: each was cut along the seam
    std::size_t vertices_added = 0;          ///< vertices added on seams (each output edge that crosses one gets one)
    std::size_t vertices_without_source = 0; ///< output vertices given the source of a neighbour (none of their own)
};

/// Give `output` (triangles only) the attributes of the input `surface.mesh()`, each output vertex reading them at
/// its source point (`sources[v]`, as find_sources gives them):
/// - charts: the input's triangles joined across edges whose two sides have the same material and group, and the
///   same texture coordinates and normals at both ends; a chart's boundary is a UV seam, a hard edge (normals that
///   differ across it), or a material or group boundary;
/// - an output triangle whose corners' sources lie in different charts is cut along the seam: each output edge
///   between two charts gets a vertex where the input's seam crosses it (found by bisection between the corners'
///   source points; placed on the output edge, so no triangle turns), carrying each chart's texture coordinates of that seam point, so that every output triangle
///   lies in one chart and interpolates one chart's texture coordinates, and corners on a seam have one texture
///   coordinate per chart (OBJ's v/vt);
/// - texture coordinates, normals and materials: per triangle from its chart at its corners' source points; vertex
///   colours interpolated at the source point; normals then carried through `steps` (push_normal), the warps
///   between the input and the output (none for a round trip).
/// A vertex with no source takes a neighbour's. Attributes the input lacks stay empty in `output`.
/// @throw InvalidInput when `output` has quads or `sources` does not match its vertices.
TransferReport transfer_attributes(TriangleMesh& output, const SourceSurface& surface, const std::vector<SourcePoint>& sources,
                                   const std::vector<WarpStep>& steps = {});

} // namespace voxwarp
