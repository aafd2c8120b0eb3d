#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp/vdb_io.h>

#include <voxwarp_internal/messages.h>
#include <voxwarp_internal/vdb_convert.h>

#include "vdb_check.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <new>
#include <stdexcept>

namespace voxwarp {

namespace {

void write_density_grid(openvdb::FloatGrid::Ptr grid, const std::array<std::int64_t, 3>& dims, const std::string& path) {
    grid->setName("density");
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    grid->insertMeta("voxwarp_density_convention", openvdb::StringMetadata("density in [0,1], surface at 0.5"));
    grid->insertMeta("voxwarp_dims", openvdb::Vec3IMetadata(openvdb::Vec3i(int(dims[0]), int(dims[1]), int(dims[2]))));
    write_atomically(path, [&](const std::string& tmp) {
        try {
            openvdb::io::File file(tmp);
            file.write({grid});
            file.close();
        } catch (const openvdb::Exception& e) {
            throw IOError(path + ": writing failed: " + internal::excerpt(e.what()));
        }
    });
}

openvdb::FloatGrid::Ptr read_float_grid(const std::string& path, const std::string& grid_name) {
    openvdb::initialize();
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw IOError(path + ": no such file");
    const std::uint64_t size = std::filesystem::file_size(path, ec);
    if (!ec && size == 0) throw InvalidInput(path + ": file is empty");
    vdb_internal::VdbLayout layout;
    if (!ec) layout = vdb_internal::read_vdb_layout(path, size);
    auto no_grid = [&]() {
        return InvalidInput(path + (grid_name.empty() ? ": holds no float grid" : ": holds no float grid named '" + grid_name + "'"));
    };
    // What a tree takes in memory, before OpenVDB builds it: a damaged topology can ask for 30 times the file's
    // bytes (each 64-byte leaf mask becomes a leaf with a 2 KiB buffer).
    auto require_tree_memory = [&](const vdb_internal::TreeNodeCounts& nodes, const std::string& what) {
        using Upper = openvdb::FloatTree::RootNodeType::ChildNodeType;
        using Lower = Upper::ChildNodeType;
        using Leaf = Lower::ChildNodeType;
        require_memory(nodes.upper * sizeof(Upper) + nodes.lower * sizeof(Lower) + nodes.leaves * (sizeof(Leaf) + Leaf::SIZE * sizeof(float)), 0,
                       path + ": reading " + what + " (" + std::to_string(nodes.leaves) + " leaves)");
    };
    // Where the file's table of grids was read, only the grid wanted is read, and only after walking it (OpenVDB's
    // reader overruns its buffers on some damaged sizes; vdb_check.cpp). A stream's grids were walked with its
    // layout (OpenVDB reads them all on opening it). Otherwise OpenVDB reads every grid unchecked.
    const vdb_internal::VdbGridEntry* wanted = nullptr;
    if (layout.stream_walked) require_tree_memory(layout.stream_nodes, "every grid");
    if (layout.walkable) {
        for (const auto& g : layout.grids)
            if (vdb_internal::is_float_tree(g.type) && (grid_name.empty() || vdb_internal::base_name(g.unique_name) == grid_name)) {
                wanted = &g;
                break;
            }
        if (!wanted) throw no_grid();
        vdb_internal::TreeNodeCounts nodes = vdb_internal::check_float_grid(path, layout, *wanted);
        if (!wanted->instance_parent.empty())
            for (const auto& g : layout.grids)
                if (g.unique_name == wanted->instance_parent && vdb_internal::is_float_tree(g.type)) nodes = vdb_internal::check_float_grid(path, layout, g);
        require_tree_memory(nodes, "grid '" + internal::excerpt(vdb_internal::base_name(wanted->unique_name), 60) + "'");
    }
    openvdb::GridPtrVecPtr grids;
    try {
        openvdb::io::File file(path);
        file.open(/*delayLoad=*/false); // all of it now, so that a damaged block fails here, not when a later step reads it
        if (wanted && file.hasGrid(vdb_internal::lookup_name(wanted->unique_name))) {
            grids = std::make_shared<openvdb::GridPtrVec>();
            grids->push_back(file.readGrid(vdb_internal::lookup_name(wanted->unique_name)));
        } else { // no table of grids, or a name OpenVDB cannot look up (one written "a[1]" is read as the second "a")
            grids = file.getGrids();
        }
        file.close();
    } catch (const std::bad_alloc&) { // a length read from damaged bytes
        throw InvalidInput(path + ": not a readable .vdb file: a size in it is damaged (reading it ran out of memory)");
    } catch (const std::length_error&) {
        throw InvalidInput(path + ": not a readable .vdb file: a size in it is damaged");
    } catch (const std::exception& e) {
        throw InvalidInput(path + ": not a readable .vdb file: " + internal::excerpt(e.what()));
    }
    for (const auto& base : *grids) {
        if (!base || (!grid_name.empty() && base->getName() != grid_name)) continue;
        if (auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(base)) return g;
    }
    throw no_grid();
}

} // namespace

namespace {

/// The grid for a .vdb at `path`; the voxmap's own problems (a voxel too small for OpenVDB) name the file.
template <class V>
openvdb::FloatGrid::Ptr grid_for(const V& voxmap, const std::string& path) {
    try {
        return vdb_internal::to_density_grid(voxmap);
    } catch (const InvalidInput& e) {
        throw InvalidInput(path + ": " + e.what());
    }
}

} // namespace

void write_vdb(const Voxmap& voxmap, const std::string& path) {
    openvdb::initialize();
    write_density_grid(grid_for(voxmap, path), voxmap.dims, path);
}

void write_vdb(const SparseVoxmap& voxmap, const std::string& path) {
    openvdb::initialize();
    write_density_grid(grid_for(voxmap, path), voxmap.dims(), path);
}

Voxmap read_vdb(const std::string& path, const std::string& grid_name) { return vdb_internal::from_float_grid(*read_float_grid(path, grid_name), path); }

SparseVoxmap read_vdb_sparse(const std::string& path, const std::string& grid_name) {
    return vdb_internal::sparse_from_float_grid(*read_float_grid(path, grid_name), path);
}

} // namespace voxwarp
