#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp/vdb_io.h>

#include <voxwarp_internal/messages.h>
#include <voxwarp_internal/vdb_convert.h>

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

/// The layout of a .vdb up to its grids (OpenVDB's file format 221 and later: header, file metadata, then per grid a
/// descriptor holding where the grid's bytes start and end), checked against the file's size before OpenVDB reads
/// it. OpenVDB reads a string's length and then makes a string that long, whether or not the file holds it; past
/// the end of a truncated file that length is whatever was in memory: a 300-byte piece of a valid .vdb took 37 s and
/// 7 GB to fail, quoting 1.2 GB of blanks as a map type's name. Layouts this does not know (older versions, files
/// without grid offsets) are left to OpenVDB.
void check_vdb_layout(const std::string& path, std::uint64_t size) {
    std::ifstream in(path, std::ios::binary);
    std::uint64_t at = 0;
    auto corrupt = [&](const std::string& what) {
        return InvalidInput(path + ": truncated or corrupt .vdb file: " + what + " (the file holds " + std::to_string(size) + " bytes)");
    };
    auto read = [&](void* out, std::uint64_t bytes, const char* what) {
        if (bytes > size - at) throw corrupt(std::string(what) + " at byte " + std::to_string(at) + " runs past the end");
        in.read(static_cast<char*>(out), std::streamsize(bytes));
        if (!in) throw corrupt(std::string("cannot read ") + what + " at byte " + std::to_string(at));
        at += bytes;
    };
    auto skip_string = [&](const char* what) {
        std::uint32_t length = 0;
        read(&length, sizeof length, what);
        if (length > size - at)
            throw corrupt(std::string(what) + " at byte " + std::to_string(at) + " claims " + std::to_string(length) + " bytes, past the end");
        in.seekg(std::streamoff(length), std::ios::cur);
        at += length;
    };
    std::int64_t magic = 0;
    std::uint32_t version = 0, library[2];
    char offsets = 0;
    read(&magic, sizeof magic, "the header");
    if (magic != 0x56444220) return; // not a .vdb: OpenVDB says so
    read(&version, sizeof version, "the header");
    if (version < 221 || version > 0xffff) return;
    read(library, sizeof library, "the header");
    read(&offsets, 1, "the header");
    if (version < 222) { // 220-221 keep a compression flag here
        char compressed;
        read(&compressed, 1, "the header");
    }
    char uuid[36];
    read(uuid, sizeof uuid, "the header");
    std::uint32_t entries = 0;
    read(&entries, sizeof entries, "the file's metadata");
    for (std::uint32_t e = 0; e < entries; ++e) {
        skip_string("a metadata name");
        skip_string("a metadata type");
        skip_string("a metadata value");
    }
    if (!offsets) return; // a stream: its grids follow one another with no offsets to check
    std::int32_t grids = 0;
    read(&grids, sizeof grids, "the grid count");
    if (grids < 0) throw corrupt("a grid count of " + std::to_string(grids));
    for (std::int32_t g = 0; g < grids; ++g) {
        skip_string("a grid's name");
        skip_string("a grid's type");
        skip_string("a grid's instance parent");
        std::int64_t position[3]; // the grid's start, its data blocks' start, its end
        read(position, sizeof position, "a grid's offsets");
        if (!(std::int64_t(at) <= position[0] && position[0] <= position[1] && position[1] <= position[2] && std::uint64_t(position[2]) <= size))
            throw corrupt("grid " + std::to_string(g) + " ends at byte " + std::to_string(position[2]));
        in.seekg(position[2]);
        at = std::uint64_t(position[2]);
    }
}

openvdb::FloatGrid::Ptr read_float_grid(const std::string& path, const std::string& grid_name) {
    openvdb::initialize();
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw IOError(path + ": no such file");
    const std::uint64_t size = std::filesystem::file_size(path, ec);
    if (!ec && size == 0) throw InvalidInput(path + ": file is empty");
    if (!ec) check_vdb_layout(path, size);
    openvdb::GridPtrVecPtr grids;
    try {
        openvdb::io::File file(path);
        file.open(/*delayLoad=*/false); // all of it now, so that a damaged block fails here, not when a later step reads it
        grids = file.getGrids();
        file.close();
    } catch (const std::bad_alloc&) { // a length read from damaged bytes
        throw InvalidInput(path + ": not a readable .vdb file: a size in it is damaged (reading it ran out of memory)");
    } catch (const std::length_error&) {
        throw InvalidInput(path + ": not a readable .vdb file: a size in it is damaged");
    } catch (const std::exception& e) {
        throw InvalidInput(path + ": not a readable .vdb file: " + internal::excerpt(e.what()));
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
