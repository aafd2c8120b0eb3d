// A .vdb walked before OpenVDB reads it. OpenVDB 10 (Debian 12's) reads sizes and counts from the file and acts on
// them before checking them: a block whose size field says "raw, N bytes" is read into its node's buffer and only
// then compared with the buffer's size (io::bloscFromStream, io::unzipFromStream), so a damaged size overruns the
// heap; a string's length becomes an allocation. This walk follows the reader's own order (Archive::readGrid,
// RootNode / InternalNode / LeafNode::readTopology and readBuffers, io::readCompressedValues) through one float
// grid without allocating anything the file asks for, and refuses the file where the reader would go wrong.
#include "vdb_check.h"

#include <voxwarp/errors.h>

#include <voxwarp_internal/messages.h>

#include <openvdb/Metadata.h>
#include <openvdb/io/Compression.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

namespace voxwarp::vdb_internal {

namespace {

constexpr std::uint32_t kFirstWalkableVersion = 222; // per-grid compression flags and per-block mask metadata
constexpr char kSeparator = '\x1e';

/// Reads a byte range of the file, never past `end`, and names the file, the grid and the byte in its complaints.
class Cursor {
public:
    Cursor(const std::string& path, std::uint64_t at, std::uint64_t end, std::string context)
        : buffer_(std::size_t(1) << 16), path_(path), at_(at), end_(end), context_(std::move(context)) {
        in_.rdbuf()->pubsetbuf(buffer_.data(), std::streamsize(buffer_.size())); // most skips then stay in the buffer
        in_.open(path, std::ios::binary);
        in_.seekg(std::streamoff(at));
    }
    std::uint64_t at() const { return at_; }
    std::uint64_t left() const { return end_ - at_; }
    [[noreturn]] void fail(const std::string& what) const {
        throw InvalidInput(path_ + ": truncated or corrupt .vdb file: " + context_ + what + " at byte " + std::to_string(at_) +
                           (context_.empty() ? " (the file holds " : " (the grid ends at byte ") + std::to_string(end_) + (context_.empty() ? " bytes)" : ")"));
    }
    void read(void* out, std::uint64_t bytes, const char* what) {
        if (bytes > left()) fail(std::string(what) + " runs past the end");
        in_.read(static_cast<char*>(out), std::streamsize(bytes));
        if (!in_) fail(std::string("cannot read ") + what);
        at_ += bytes;
    }
    template <class T>
    T get(const char* what) {
        T value{};
        read(&value, sizeof value, what);
        return value;
    }
    void skip(std::uint64_t bytes, const char* what) {
        if (bytes > left()) fail(std::string(what) + " (" + std::to_string(bytes) + " bytes) runs past the end");
        if (bytes <= buffer_.size()) in_.ignore(std::streamsize(bytes)); // through the buffer: a seek is a system call
        else in_.seekg(std::streamoff(bytes), std::ios::cur);
        at_ += bytes;
    }
    /// A length-prefixed string, at most `limit` bytes kept (the rest skipped).
    std::string string(const char* what, std::uint64_t limit = 4096) {
        const auto length = get<std::uint32_t>(what);
        if (length > left()) fail(std::string(what) + " claims " + std::to_string(length) + " bytes, past the end");
        std::string s(std::min<std::uint64_t>(length, limit), '\0');
        read(s.data(), s.size(), what);
        skip(length - s.size(), what);
        return s;
    }

private:
    std::vector<char> buffer_;
    std::ifstream in_;
    std::string path_;
    std::uint64_t at_, end_;
    std::string context_;
};

/// Where OpenVDB's readers go with a grid of a float tree (Tree_float_5_4_3): root, two levels of internal nodes
/// (32^3 and 16^3 children), leaves of 8^3 voxels.
class FloatGridWalk {
public:
    FloatGridWalk(Cursor& c, std::uint32_t compression) : c_(c), compression_(compression) {}

    void metadata() {
        const auto count = c_.get<std::uint32_t>("the grid's metadata count");
        if (count > c_.left() / 12) c_.fail("a metadata count of " + std::to_string(count));
        for (std::uint32_t i = 0; i < count; ++i) {
            const std::string name = c_.string("a metadata name");
            const std::string type = c_.string("a metadata type");
            const auto bytes = c_.get<std::uint32_t>("a metadata size");
            if (bytes > c_.left()) c_.fail("metadata '" + internal::excerpt(name, 60) + "' claims " + std::to_string(bytes) + " bytes, past the end");
            if (type == "__delayedload") {
                delayed_load(bytes);
            } else if (type != "string" && openvdb::Metadata::isRegisteredType(type)) {
                // OpenVDB reads a typed value's own size, whatever the size field says.
                auto value = openvdb::Metadata::createMetadata(type);
                if (bytes != value->size())
                    c_.fail("metadata '" + internal::excerpt(name, 60) + "' of type " + type + " claims " + std::to_string(bytes) + " bytes, not " +
                            std::to_string(value->size()));
                std::string raw(sizeof bytes + bytes, '\0');
                std::memcpy(raw.data(), &bytes, sizeof bytes);
                c_.read(raw.data() + sizeof bytes, bytes, "a metadata value");
                if (name == "is_saved_as_half_float") { // the metadata decides (GridBase::saveFloatAsHalf), not the type's suffix
                    std::istringstream s(raw);
                    value->read(s);
                    half_ = value->asBool();
                }
            } else {
                c_.skip(bytes, "a metadata value");
            }
        }
    }

    /// False where the map type is not one OpenVDB knows: it refuses the grid there, before its tree.
    bool transform() { return map(c_.string("the transform's type"), 0); }

    TreeNodeCounts tree() {
        c_.skip(4, "the tree's buffer count");
        c_.skip(4, "the background value");
        const auto tiles = c_.get<std::uint32_t>("the root's tile count");
        const auto children = c_.get<std::uint32_t>("the root's child count");
        constexpr std::uint64_t kTileBytes = 12 + 4 + 1; // origin, value, active flag
        if (tiles > c_.left() / kTileBytes) c_.fail("a root tile count of " + std::to_string(tiles));
        c_.skip(tiles * kTileBytes, "the root's tiles");
        if (children > c_.left() / (12 + 2 * mask_bytes(5))) c_.fail("a root child count of " + std::to_string(children));
        // The reader files children by origin (a std::map: the last of equal origins stays) and reads their voxel
        // blocks in that order, which damage may have made differ from the order of their topology.
        std::map<std::array<std::int32_t, 3>, std::vector<std::uint16_t>> roots;
        for (std::uint32_t i = 0; i < children; ++i) {
            std::array<std::int32_t, 3> origin{};
            c_.read(origin.data(), sizeof origin, "a root child's origin");
            std::vector<std::uint16_t> leaves;
            node(5, leaves);
            roots[origin] = std::move(leaves);
        }
        for (const auto& [origin, leaves] : roots)
            for (const std::uint16_t active : leaves) {
                c_.skip(mask_bytes(3), "a leaf's value mask"); // io::File's stream is seekable: the topology's mask is used
                values(512, active);
            }
        return counts_; // the nodes the reader allocates (overwritten duplicates included: they leak, not vanish)
    }

private:
    static std::uint64_t mask_bytes(int log2) { return (std::uint64_t(1) << (3 * log2)) / 8; }

    std::uint32_t mask(int log2, std::vector<std::uint64_t>& words, const char* what) {
        words.assign(mask_bytes(log2) / 8, 0);
        c_.read(words.data(), mask_bytes(log2), what);
        std::uint32_t on = 0;
        for (const std::uint64_t w : words) on += std::uint32_t(std::popcount(w));
        return on;
    }

    /// An internal node (log2 side 5 or 4) and everything below it; each leaf's active count appended to `leaves`.
    void node(int log2, std::vector<std::uint16_t>& leaves) {
        ++(log2 == 5 ? counts_.upper : counts_.lower);
        std::vector<std::uint64_t> child_mask, value_mask, leaf_mask;
        mask(log2, child_mask, "an internal node's child mask");
        const std::uint32_t active = mask(log2, value_mask, "an internal node's value mask");
        values(std::uint32_t(1) << (3 * log2), active);
        for (std::size_t w = 0; w < child_mask.size(); ++w)
            for (std::uint64_t bits = child_mask[w]; bits; bits &= bits - 1) {
                if (log2 == 5) {
                    node(4, leaves);
                } else {
                    leaves.push_back(std::uint16_t(mask(3, leaf_mask, "a leaf's value mask")));
                    ++counts_.leaves;
                }
            }
    }

    /// io::readCompressedValues for `count` values of a node whose value mask has `active` bits on.
    void values(std::uint32_t count, std::uint32_t active) {
        using namespace openvdb::io; // the mask flag's values
        const auto metadata = c_.get<std::int8_t>("a block's mask flag");
        if (metadata == NO_MASK_AND_ONE_INACTIVE_VAL || metadata == MASK_AND_ONE_INACTIVE_VAL || metadata == MASK_AND_TWO_INACTIVE_VALS)
            c_.skip(4, "a block's inactive value");
        if (metadata == MASK_AND_TWO_INACTIVE_VALS) c_.skip(4, "a block's second inactive value");
        if (metadata == MASK_AND_NO_INACTIVE_VALS || metadata == MASK_AND_ONE_INACTIVE_VAL || metadata == MASK_AND_TWO_INACTIVE_VALS)
            c_.skip(count / 8, "a block's selection mask");
        const std::uint32_t stored = (compression_ & COMPRESS_ACTIVE_MASK) && metadata != NO_MASK_AND_ALL_VALS ? active : count;
        if (half_ && stored == 0) return; // io::HalfReader reads nothing for no values (a full float block keeps its size field)
        block(std::uint64_t(stored) * (half_ ? 2 : 4));
    }

    /// The bytes of one block of values: raw, or a size and then zip or blosc data that must unpack to `bytes`.
    void block(std::uint64_t bytes) {
        if (!(compression_ & (openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ZIP))) {
            c_.skip(bytes, "a block of values");
            return;
        }
        const auto size = c_.get<std::int64_t>("a block's size");
        if (size <= 0) { // stored raw: the reader reads -size bytes into a buffer of `bytes`
            if (std::uint64_t(-(size + 1)) + 1 != bytes)
                c_.fail("a block of " + std::to_string(bytes) + " bytes claims " + std::to_string(std::uint64_t(-(size + 1)) + 1) + " raw bytes");
            c_.skip(bytes, "a block of values");
            return;
        }
        if (std::uint64_t(size) > c_.left()) c_.fail("a block claims " + std::to_string(size) + " compressed bytes, past the end");
        if (compression_ & openvdb::io::COMPRESS_BLOSC) blosc_header(std::uint64_t(size), bytes, "a block");
        else c_.skip(std::uint64_t(size), "a block of values");
    }

    /// Blosc decompresses from the chunk's own header (its sizes, not the reader's), so they must agree with the
    /// chunk's `size` in the file and the `bytes` it unpacks into (or, with `padded`, the 128 bytes OpenVDB pads
    /// short tables to).
    void blosc_header(std::uint64_t size, std::uint64_t bytes, const char* what, bool padded = false) {
        std::array<std::uint8_t, 16> header{};
        if (size < header.size()) c_.fail(std::string(what) + " of " + std::to_string(size) + " bytes is too short for blosc");
        c_.read(header.data(), header.size(), "a blosc header");
        std::uint32_t unpacked = 0, packed = 0;
        std::memcpy(&unpacked, header.data() + 4, 4);
        std::memcpy(&packed, header.data() + 12, 4);
        if ((unpacked != bytes && !(padded && unpacked == 128 && bytes <= 128)) || packed != size)
            c_.fail(std::string(what) + "'s blosc header says " + std::to_string(packed) + " bytes unpacking to " + std::to_string(unpacked) +
                    ", where the file has " + std::to_string(size) + " for " + std::to_string(bytes));
        c_.skip(size - header.size(), "a block of values");
    }

    /// io::DelayedLoadMetadata (a per-leaf table OpenVDB writes beside the grid, read even when loading is not delayed).
    void delayed_load(std::uint32_t bytes) {
        const std::uint64_t start = c_.at();
        if (bytes == 0) return;
        const auto count = c_.get<std::uint32_t>("the delayed-load table's count");
        auto table = [&](std::uint32_t packed, std::uint64_t entry) {
            if (packed == 0) c_.skip(std::uint64_t(count) * entry, "the delayed-load table");
            else blosc_header(packed, std::uint64_t(count) * entry, "the delayed-load table", true);
        };
        table(c_.get<std::uint32_t>("the delayed-load table's size"), 1);
        const auto sizes = c_.get<std::uint32_t>("the delayed-load table's size");
        if (sizes != 0xffffffffu) table(sizes, 8);
        if (c_.at() - start > bytes) c_.fail("the delayed-load table overruns its " + std::to_string(bytes) + " bytes");
        c_.skip(bytes - (c_.at() - start), "the delayed-load table");
    }

    bool map(const std::string& type, int depth) {
        if (type == "AffineMap" || type == "UnitaryMap") c_.skip(128, "the transform");
        else if (type == "ScaleMap" || type == "UniformScaleMap") c_.skip(120, "the transform");
        else if (type == "ScaleTranslateMap" || type == "UniformScaleTranslateMap") c_.skip(144, "the transform");
        else if (type == "TranslationMap") c_.skip(24, "the transform");
        else if (type == "NonlinearFrustumMap" && depth < 2) {
            c_.skip(48 + 8 + 8, "the transform"); // box, taper, depth; then the map it follows
            return map(c_.string("the transform's second type"), depth + 1);
        } else return false;
        return true;
    }

    Cursor& c_;
    std::uint32_t compression_;
    bool half_ = false;
    TreeNodeCounts counts_;
};

/// One float grid walked from `start`, never past `end`.
struct GridWalk {
    TreeNodeCounts nodes;
    std::uint64_t end = 0; ///< one past the grid's last byte
    bool complete = false; ///< false where the walk stopped before the tree (a map type OpenVDB does not know)
};

GridWalk walk_float_grid(const std::string& path, std::uint64_t start, std::uint64_t end, const VdbGridEntry& grid) {
    Cursor c(path, start, end, "grid '" + internal::excerpt(base_name(grid.unique_name), 60) + "': ");
    FloatGridWalk walk(c, c.get<std::uint32_t>("the grid's compression flags"));
    walk.metadata();
    if (!walk.transform()) return {}; // OpenVDB refuses a map type it does not know, before the tree
    GridWalk done;
    if (grid.instance_parent.empty()) done.nodes = walk.tree(); // an instance's tree is its parent's
    done.end = c.at();
    done.complete = true;
    return done;
}

} // namespace

std::string base_name(const std::string& unique_name) { return unique_name.substr(0, unique_name.find(kSeparator)); }

std::string lookup_name(const std::string& unique_name) {
    const std::size_t sep = unique_name.find(kSeparator);
    return sep == std::string::npos ? unique_name : unique_name.substr(0, sep) + "[" + unique_name.substr(sep + 1) + "]";
}

VdbLayout read_vdb_layout(const std::string& path, std::uint64_t size) {
    VdbLayout layout;
    Cursor c(path, 0, size, "");
    std::uint32_t library[2];
    char offsets = 0;
    if (c.get<std::int64_t>("the header") != 0x56444220) return layout; // not a .vdb: OpenVDB says so
    layout.version = c.get<std::uint32_t>("the header");
    if (layout.version < 221 || layout.version > 0xffff) return layout;
    c.read(library, sizeof library, "the header");
    c.read(&offsets, 1, "the header");
    if (layout.version < 222) c.skip(1, "the header"); // 221 keeps a compression flag here
    c.skip(36, "the header");                         // the file's UUID
    const auto entries = c.get<std::uint32_t>("the file's metadata");
    for (std::uint32_t e = 0; e < entries; ++e) {
        c.string("a metadata name", 0);
        c.string("a metadata type", 0);
        c.string("a metadata value", 0);
    }
    // A stream (no offsets) has its grids one after another, each a descriptor and the grid; OpenVDB reads them all
    // on opening it, so each is walked here, as far as the walk can measure them.
    layout.stream = !offsets;
    if (layout.stream && layout.version < kFirstWalkableVersion) return layout;
    const auto grids = c.get<std::int32_t>("the grid count");
    if (grids < 0) c.fail("a grid count of " + std::to_string(grids));
    for (std::int32_t g = 0; g < grids; ++g) {
        VdbGridEntry entry;
        entry.unique_name = c.string("a grid's name");
        entry.type = c.string("a grid's type");
        entry.instance_parent = c.string("a grid's instance parent");
        std::int64_t position[3]; // the grid's start, its data blocks' start (0 for an instance: it has none), its end
        c.read(position, sizeof position, "a grid's offsets"); // a stream writes them too, unset
        if (layout.stream) {
            if (!is_float_tree(entry.type)) return layout; // a grid the walk cannot measure: OpenVDB reads the rest
            entry.start = std::int64_t(c.at());
            const GridWalk walk = walk_float_grid(path, c.at(), size, entry);
            if (!walk.complete) return layout;
            layout.stream_nodes += walk.nodes;
            entry.end = std::int64_t(walk.end);
        } else {
            const bool blocks_inside = (position[1] == 0 && !entry.instance_parent.empty()) || (position[0] <= position[1] && position[1] <= position[2]);
            if (!(std::int64_t(c.at()) <= position[0] && position[0] <= position[2] && blocks_inside && std::uint64_t(position[2]) <= size))
                throw InvalidInput(path + ": truncated or corrupt .vdb file: grid " + std::to_string(g) + " ends at byte " + std::to_string(position[2]) +
                                   " (the file holds " + std::to_string(size) + " bytes)");
            entry.start = position[0];
            entry.end = position[2];
        }
        c.skip(std::uint64_t(entry.end) - c.at(), "a grid");
        layout.grids.push_back(std::move(entry));
    }
    layout.stream_walked = layout.stream;
    layout.walkable = !layout.stream && layout.version >= kFirstWalkableVersion;
    return layout;
}

TreeNodeCounts check_float_grid(const std::string& path, const VdbLayout& layout, const VdbGridEntry& grid) {
    if (!layout.walkable) return {};
    return walk_float_grid(path, std::uint64_t(grid.start), std::uint64_t(grid.end), grid).nodes;
}

} // namespace voxwarp::vdb_internal
