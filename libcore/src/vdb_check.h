/// @file vdb_check.h
/// @brief Internal: a .vdb's layout, and the float grid voxwarp reads from it, walked before OpenVDB reads them
/// (vdb_check.cpp). OpenVDB 10's reader trusts the counts and sizes it reads: a length past the end of a truncated
/// file becomes a string that long, and a damaged block size overruns the node it is read into.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace voxwarp::vdb_internal {

/// One grid's entry in a .vdb's table of grids.
struct VdbGridEntry {
    std::string unique_name;     ///< the name, with "\x1e" and a number after it where several grids share it
    std::string type;            ///< e.g. "Tree_float_5_4_3", "_HalfFloat" appended where values are stored as halves
    std::string instance_parent; ///< the grid whose tree this one shares, or empty
    std::int64_t start = 0, end = 0; ///< byte offsets of the grid's first byte and one past its last
};

/// The nodes a float grid's tree holds: what reading it allocates.
struct TreeNodeCounts {
    std::uint64_t upper = 0, lower = 0, leaves = 0; ///< 32^3 and 16^3 internal nodes, 8^3 leaves
    TreeNodeCounts& operator+=(const TreeNodeCounts& o) {
        upper += o.upper, lower += o.lower, leaves += o.leaves;
        return *this;
    }
};

/// What `read_vdb_layout` found.
struct VdbLayout {
    /// Header, file metadata and every grid's offsets read, in a format whose grids `check_float_grid` can walk
    /// (222 and later). Otherwise what was read was checked, and OpenVDB reads the rest.
    bool walkable = false;
    /// A file written as a stream (io::Stream): no offsets, and OpenVDB reads every grid on opening it. Where every
    /// grid is a float grid, each was walked in turn (`stream_walked`), `grids` has their extents and
    /// `stream_nodes` what they all take in memory.
    bool stream = false, stream_walked = false;
    TreeNodeCounts stream_nodes;
    std::uint32_t version = 0;
    std::vector<VdbGridEntry> grids; ///< in the file's order
};

/// Whether a grid type (as a grid table names it) is voxwarp's: a float tree, values full or half.
inline bool is_float_tree(const std::string& type) { return type == "Tree_float_5_4_3" || type == "Tree_float_5_4_3_HalfFloat"; }

/// The header, file metadata and grid table of the .vdb at `path` (`size` bytes); in a stream, its grids walked.
/// @throw InvalidInput naming `path` where any of them runs past the end of the file (or a stream's grid fails
///        its walk, as check_float_grid).
VdbLayout read_vdb_layout(const std::string& path, std::uint64_t size);

/// The grid's name without the "\x1e" number, and the name OpenVDB's File::readGrid finds it by ("name[N]").
std::string base_name(const std::string& unique_name);
std::string lookup_name(const std::string& unique_name);

/// Walks the float grid `grid` of `layout` (its metadata, transform, tree topology and voxel blocks) as OpenVDB
/// 10's reader will read it, so that the reader meets no count or size it cannot hold. Every block's size is checked
/// against the node it will be read into, every count against the bytes left in the grid. Returns the tree's nodes
/// (none where the layout or the grid's transform is one the walk leaves to OpenVDB, or the grid is an instance).
/// @throw InvalidInput naming `path`, the grid and the byte where the walk found a size the reader would overrun.
TreeNodeCounts check_float_grid(const std::string& path, const VdbLayout& layout, const VdbGridEntry& grid);

} // namespace voxwarp::vdb_internal
