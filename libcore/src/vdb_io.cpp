#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp/vdb_io.h>

#include <voxwarp_internal/vdb_convert.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <filesystem>

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
            throw IOError(path + ": writing failed: " + e.what());
        }
    });
}

openvdb::FloatGrid::Ptr read_float_grid(const std::string& path, const std::string& grid_name) {
    openvdb::initialize();
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw IOError(path + ": no such file");
    if (std::filesystem::file_size(path, ec) == 0) throw InvalidInput(path + ": file is empty");
    openvdb::GridPtrVecPtr grids;
    try {
        openvdb::io::File file(path);
        file.open();
        grids = file.getGrids();
        file.close();
    } catch (const openvdb::Exception& e) {
        throw InvalidInput(path + ": not a readable .vdb file: " + e.what());
    } catch (const std::exception& e) {
        throw InvalidInput(path + ": not a readable .vdb file: " + e.what());
    }
    openvdb::FloatGrid::Ptr grid;
    for (const auto& base : *grids) {
        if (!grid_name.empty() && base->getName() != grid_name) continue;
        if (auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(base)) {
            grid = g;
            break;
        }
    }
    if (!grid)
        throw InvalidInput(path + (grid_name.empty() ? ": holds no float grid" : ": holds no float grid named '" + grid_name + "'"));
    return grid;
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
