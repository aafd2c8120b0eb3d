#include "mesh_validate.h"

#include <voxwarp/errors.h>

#include <array>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>
#include <vector>

namespace voxwarp::mesh_io_internal {

std::string read_head(const std::string& path, std::uintmax_t file_size) {
    std::ifstream in(path, std::ios::binary);
    std::string head(std::size_t(std::min<std::uintmax_t>(file_size, 65536)), '\0');
    in.read(head.data(), std::streamsize(head.size()));
    head.resize(std::size_t(in.gcount()));
    return head;
}

namespace {

/// Header counts that need more bytes than the file holds: refused before a reader loops over (or reserves
/// for) a billion vertices. Minimum record sizes: ASCII "0 0 0\n" is 6 bytes a vertex, "3 0 1 2\n" 8 bytes a
/// face; binary records are their properties' sizes.
[[noreturn]] void refuse_counts(const std::string& path, std::uint64_t vertices, std::uint64_t faces, std::uint64_t needed, std::uint64_t available) {
    throw InvalidInput(path + ": header declares " + std::to_string(vertices) + " vertices and " + std::to_string(faces) +
                       " faces, which need at least " + std::to_string(needed) + " bytes, but the file holds " + std::to_string(available));
}

} // namespace

void validate_before_openmesh(const std::string& path, const std::string& ext, std::uintmax_t file_size) {
    if (ext == ".obj") validate_obj(path);
    else if (ext == ".off") validate_off(path, read_head(path, file_size), file_size);
    else if (ext == ".ply") validate_ply(path, file_size);
    else if (ext == ".stl") validate_stl(path, read_head(path, file_size), file_size);
}

void validate_obj(const std::string& path) {
    // OpenMesh skips a vertex line it cannot parse ("v nan 0 0"), shifting the faces after it, and asserts on
    // a face vertex without an index ("f /6 1 4", found by fuzzing): check vertex and face lines here.
    std::ifstream obj(path);
    std::string obj_line;
    std::size_t line_no = 0, vertex_no = 0;
    std::int64_t max_index = 0;
    std::size_t max_index_line = 0;
    auto bad = [&](const std::string& what) { throw InvalidInput(path + ": line " + std::to_string(line_no) + ": " + what); };
    while (std::getline(obj, obj_line)) {
        ++line_no;
        // Read the keyword the way OpenMesh does (stream extraction: any whitespace, leading or after the
        // keyword, separates; found by fuzzing with indented lines and "f\r/4").
        std::istringstream fields(obj_line);
        std::string keyword;
        fields >> keyword;
        if (keyword == "v") {
            ++vertex_no;
            for (int a = 0; a < 3; ++a) {
                std::string number;
                fields >> number;
                char* end = nullptr;
                const double x = std::strtod(number.c_str(), &end);
                if (number.empty() || end == number.c_str()) bad("vertex " + std::to_string(vertex_no) + " needs three numbers");
                if (!std::isfinite(x)) bad("vertex " + std::to_string(vertex_no) + " has a non-finite coordinate");
            }
        } else if (keyword == "f") {
            std::string token;
            int corners = 0;
            while (fields >> token) {
                char* end = nullptr;
                const long long index = std::strtoll(token.c_str(), &end, 10);
                if (end == token.c_str() || (*end != '\0' && *end != '/')) bad("face vertex '" + token + "' does not start with a vertex index");
                if (index == 0) bad("face vertex index 0 (OBJ indices start at 1)");
                if (index < 0 && index < -static_cast<long long>(vertex_no)) // no negation: index may be LLONG_MIN
                    bad("face vertex index " + std::to_string(index) + " reaches before the first vertex");
                if (index > max_index) max_index = index, max_index_line = line_no;
                ++corners;
            }
            if (corners < 3) bad("face has " + std::to_string(corners) + " vertices, expected at least 3");
        }
    }
    if (std::uint64_t(max_index) > vertex_no)
        throw InvalidInput(path + ": line " + std::to_string(max_index_line) + ": face refers to vertex " + std::to_string(max_index) + ", file has " +
                           std::to_string(vertex_no) + " vertices");
}

void validate_stl(const std::string& path, const std::string& head, std::uintmax_t file_size) {
    const bool ascii = head.rfind("solid", 0) == 0 && head.find("facet") != std::string::npos;
    if (ascii) return;
    if (file_size < 84) {
        // "solid" with no facet: an ASCII STL without triangles, not a short binary one.
        if (head.rfind("solid", 0) == 0) throw InvalidInput(path + ": ASCII STL without a facet: no triangles");
        throw InvalidInput(path + ": binary STL shorter than its 84-byte header");
    }
    std::uint32_t count = 0;
    std::memcpy(&count, head.data() + 80, 4);
    if (84 + 50 * std::uint64_t(count) != file_size)
        throw InvalidInput(path + ": binary STL declares " + std::to_string(count) + " triangles (" + std::to_string(84 + 50 * std::uint64_t(count)) +
                           " bytes) but the file holds " + std::to_string(file_size) + " bytes");
}

void validate_off(const std::string& path, const std::string& head, std::uintmax_t file_size, bool body) {
    std::istringstream text(head);
    std::string line;
    // Header: a keyword ([ST][C][N][4][n]OFF, optionally followed by BINARY), then "#vertices #faces #edges"
    // on the same or the next non-comment line. Anything else is refused: OpenMesh reads on regardless.
    std::getline(text, line);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream first_words(line);
    std::string keyword, word;
    first_words >> keyword;
    static const std::regex off_keyword("^(ST)?C?N?4?n?OFF$");
    if (!std::regex_match(keyword, off_keyword)) throw InvalidInput(path + ": line 1: expected an OFF keyword, got '" + keyword.substr(0, 20) + "'");
    bool binary = false;
    std::string rest;
    while (first_words >> word) {
        if (word == "BINARY" && rest.empty())
            binary = true;
        else
            rest += word + " ";
    }
    // OpenMesh's binary OFF reader loops on malformed bodies (found by fuzzing) and voxwarp has no
    // validator for them: refuse the rare format rather than hang.
    if (binary) throw InvalidInput(path + ": binary OFF is not supported; convert it to ASCII OFF, PLY or STL");
    while (rest.empty() && std::getline(text, line)) {
        const auto start = line.find_first_not_of(" \t\r");
        if (start != std::string::npos && line[start] != '#') rest = line;
    }
    std::istringstream counts(rest);
    std::int64_t nv = -1, nf = -1;
    std::string tail;
    if (!(counts >> nv >> nf) || nv < 0 || nf < 0)
        throw InvalidInput(path + ": OFF header: expected the vertex and face counts, got '" + rest.substr(0, 40) + "'");
    // OpenMesh's ASCII OFF reader hangs on "OFF 0 0" (found by fuzzing); such a file holds nothing anyway.
    if (nv < 3 || nf < 1)
        throw InvalidInput(path + ": OFF header declares " + std::to_string(nv) + " vertices and " + std::to_string(nf) + " faces: nothing to read");
    const std::uint64_t needed = binary ? 12 * std::uint64_t(nv) + 16 * std::uint64_t(nf) : 6 * std::uint64_t(nv) + 8 * std::uint64_t(nf);
    if (needed > file_size) refuse_counts(path, std::uint64_t(nv), std::uint64_t(nf), needed, file_size);
    if (binary || !body) return;
    // ASCII body: OpenMesh reads a face's vertex count as unsigned, so "-3 0 1 2" becomes four billion
    // vertices (found by fuzzing). Check every vertex and face line against the header first.
    std::ifstream off(path);
    std::string off_line;
    std::int64_t seen_header = 0, vertices = 0, faces = 0, line_no = 0;
    auto bad = [&](const std::string& what) { throw InvalidInput(path + ": line " + std::to_string(line_no) + ": " + what); };
    while (std::getline(off, off_line) && faces < nf) {
        ++line_no;
        const auto first = off_line.find_first_not_of(" \t\r");
        if (first == std::string::npos || off_line[first] == '#') continue;
        if (seen_header < 2) { // the OFF keyword line, then the counts line (possibly the same line)
            seen_header += off_line.find("OFF") != std::string::npos && off_line.find_first_of("0123456789") == std::string::npos ? 1 : 2;
            continue;
        }
        std::istringstream numbers(off_line);
        if (vertices < nv) {
            double x[3];
            for (double& c : x)
                if (!(numbers >> c) || !std::isfinite(c)) bad("vertex " + std::to_string(vertices + 1) + " needs three finite numbers");
            ++vertices;
            continue;
        }
        std::int64_t corners = 0;
        if (!(numbers >> corners) || corners < 3 || corners > 1000000) bad("face " + std::to_string(faces + 1) + " has a vertex count outside [3, 10^6]");
        for (std::int64_t q = 0; q < corners; ++q) {
            std::int64_t index = -1;
            if (!(numbers >> index) || index < 0 || index >= nv)
                bad("face " + std::to_string(faces + 1) + " refers to a vertex outside [0, " + std::to_string(nv) + ")");
        }
        ++faces;
    }
    if (vertices < nv || faces < nf)
        throw InvalidInput(path + ": ends after " + std::to_string(vertices) + " of " + std::to_string(nv) + " vertices and " + std::to_string(faces) +
                           " of " + std::to_string(nf) + " faces");
}

namespace {

/// A PLY scalar type: its size in bytes, whether it is an integer, whether it is signed.
struct PlyType {
    std::uint64_t size = 0;
    bool integer = false, is_signed = false;
};

bool ply_type(const std::string& name, PlyType& type) {
    static const std::vector<std::pair<std::string, PlyType>> types{
        {"char", {1, true, true}},     {"int8", {1, true, true}},     {"uchar", {1, true, false}},   {"uint8", {1, true, false}},
        {"short", {2, true, true}},    {"int16", {2, true, true}},    {"ushort", {2, true, false}},  {"uint16", {2, true, false}},
        {"int", {4, true, true}},      {"int32", {4, true, true}},    {"uint", {4, true, false}},    {"uint32", {4, true, false}},
        {"float", {4, false, true}},   {"float32", {4, false, true}}, {"double", {8, false, true}}, {"float64", {8, false, true}}};
    for (const auto& [n, t] : types)
        if (n == name) {
            type = t;
            return true;
        }
    return false;
}

struct PlyProperty {
    std::string name;
    bool list = false;
    PlyType count, item; // count: lists only
};

struct PlyElement {
    std::string name;
    std::uint64_t count = 0;
    std::vector<PlyProperty> properties;
};

struct PlyHeader {
    bool binary = false, big_endian = false;
    std::vector<PlyElement> elements;
    std::size_t body = 0; // offset of the first byte after end_header
};

/// The header's grammar, line by line: OpenMesh's PLY reader crashes or hangs on malformed headers (a property
/// before any element, no end_header, a NUL byte, a version other than 1.0).
PlyHeader read_ply_header(const std::string& path, const std::string& head) {
    if (head.rfind("ply", 0) != 0) throw InvalidInput(path + ": not a PLY file (it does not start with \"ply\")");
    PlyHeader header;
    std::istringstream text(head);
    std::string line;
    std::size_t line_no = 0;
    bool format_seen = false;
    auto bad = [&](const std::string& what) { throw InvalidInput(path + ": PLY header line " + std::to_string(line_no) + ": " + what); };
    while (std::getline(text, line)) {
        ++line_no;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        for (unsigned char ch : line)
            if ((ch < 0x20 && ch != '\t') || ch >= 0x7f) bad("header holds a non-printable byte");
        std::istringstream words(line);
        std::string word;
        words >> word;
        if (line_no == 1) {
            if (word != "ply") bad("expected \"ply\"");
            continue;
        }
        if (word == "format") {
            std::string format, version;
            words >> format >> version;
            if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian") bad("unknown format '" + format.substr(0, 20) + "'");
            if (version != "1.0") bad("unsupported PLY version '" + version.substr(0, 20) + "', expected 1.0");
            header.binary = format != "ascii";
            header.big_endian = format == "binary_big_endian";
            format_seen = true;
        } else if (word == "element") {
            std::string name, count_text;
            words >> name >> count_text;
            if (name.empty() || count_text.empty() || count_text.find_first_not_of("0123456789") != std::string::npos || count_text.size() > 12)
                bad("expected \"element <name> <count>\"");
            header.elements.push_back({name, std::stoull(count_text), {}});
        } else if (word == "property") {
            if (header.elements.empty()) bad("property before any element");
            PlyProperty property;
            std::string type;
            words >> type;
            if (type == "list") {
                std::string count_type, item_type;
                words >> count_type >> item_type >> property.name;
                property.list = true;
                if (!ply_type(count_type, property.count) || !ply_type(item_type, property.item) || property.name.empty())
                    bad("expected \"property list <type> <type> <name>\"");
                if (!property.count.integer) bad("list count type '" + count_type + "' is not an integer type");
            } else {
                words >> property.name;
                if (!ply_type(type, property.item) || property.name.empty()) bad("expected \"property <type> <name>\"");
            }
            if (std::string extra; words >> extra) bad("unexpected '" + extra.substr(0, 20) + "' after the property name");
            header.elements.back().properties.push_back(property);
        } else if (word == "end_header") {
            if (!format_seen) bad("end_header before any format line");
            header.body = std::size_t(text.tellg());
            return header;
        } else if (word != "comment" && word != "obj_info" && !word.empty()) {
            bad("unexpected '" + word.substr(0, 20) + "'");
        }
    }
    throw InvalidInput(path + ": PLY header has no end_header line within its first 64 KiB");
}

/// The body, element by element: OpenMesh reads a list's count as unsigned, so a negative count ("-3 0 1 2")
/// becomes a four-billion-entry list (found by fuzzing), and it reads past the data when a list or the file is short.
void walk_ply_body(const std::string& path, const PlyHeader& header, const std::string& body) {
    std::size_t at = 0;
    const PlyElement* element = nullptr;
    const PlyProperty* property = nullptr;
    std::uint64_t n = 0;
    auto bad = [&](const std::string& what) {
        throw InvalidInput(path + ": PLY element '" + element->name.substr(0, 20) + "' " + std::to_string(n + 1) + " of " + std::to_string(element->count) +
                           ", property '" + property->name.substr(0, 20) + "': " + what);
    };
    // ASCII: whitespace-separated numbers.
    auto token = [&]() -> std::string_view {
        while (at < body.size() && std::isspace(static_cast<unsigned char>(body[at]))) ++at;
        const std::size_t start = at;
        while (at < body.size() && !std::isspace(static_cast<unsigned char>(body[at]))) ++at;
        if (start == at) bad("the file ends here");
        return std::string_view(body).substr(start, at - start);
    };
    auto ascii_number = [&](const PlyType& type) -> double {
        std::string_view t = token();
        if (t.size() > 1 && t[0] == '+') t.remove_prefix(1); // from_chars takes no plus sign; stream input does
        if (type.integer) {
            std::int64_t v = 0;
            const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
            if (ec != std::errc() || end != t.data() + t.size()) bad("'" + std::string(t.substr(0, 20)) + "' is not an integer");
            return double(v);
        }
        double v = 0;
        const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
        if (ec != std::errc() || end != t.data() + t.size()) bad("'" + std::string(t.substr(0, 20)) + "' is not a number");
        return v;
    };
    // Binary: only list counts are read; everything else is skipped by size.
    auto binary_count = [&](const PlyType& type) -> double {
        if (body.size() - at < type.size) bad("the file ends here");
        std::array<unsigned char, 8> bytes{};
        std::memcpy(bytes.data(), body.data() + at, type.size);
        at += type.size;
        if (header.big_endian) std::reverse(bytes.begin(), bytes.begin() + std::ptrdiff_t(type.size));
        std::uint64_t u = 0;
        for (std::size_t b = type.size; b-- > 0;) u = (u << 8) | bytes[b];
        if (type.is_signed && (u >> (8 * type.size - 1)) & 1) return double(std::int64_t(u)) - std::ldexp(1.0, int(8 * type.size)); // two's complement
        return double(u);
    };
    auto skip = [&](std::uint64_t bytes) {
        if (body.size() - at < bytes) bad("the file ends here");
        at += bytes;
    };
    for (const auto& e : header.elements)
        for (n = 0, element = &e; n < e.count; ++n)
            for (const auto& p : e.properties) {
                property = &p;
                if (!p.list) {
                    if (header.binary) skip(p.item.size);
                    else ascii_number(p.item);
                    continue;
                }
                const double count = header.binary ? binary_count(p.count) : ascii_number(p.count);
                const double largest = std::ldexp(1.0, int(8 * p.count.size) - (p.count.is_signed ? 1 : 0)) - 1;
                if (count < 0) bad("list count " + std::to_string(std::int64_t(count)) + " is negative");
                if (count > largest) bad("list count " + std::to_string(std::uint64_t(count)) + " does not fit its type");
                if (header.binary) {
                    if (double(body.size() - at) < count * double(p.item.size)) bad("the file ends inside a list of " + std::to_string(std::uint64_t(count)));
                    at += std::size_t(count) * std::size_t(p.item.size);
                } else {
                    for (std::uint64_t q = 0; q < std::uint64_t(count); ++q) ascii_number(p.item);
                }
            }
}

} // namespace

void validate_ply(const std::string& path, std::uintmax_t file_size) {
    const PlyHeader header = read_ply_header(path, read_head(path, file_size));
    std::uint64_t nv = 0, nf = 0, vertex_bytes = 0;
    for (const auto& e : header.elements) {
        if (e.name == "vertex") {
            nv = e.count;
            for (const auto& p : e.properties) vertex_bytes += header.binary ? p.item.size : 2;
        }
        if (e.name == "face") nf = e.count;
    }
    if (nv < 3 || nf < 1)
        throw InvalidInput(path + ": PLY header declares " + std::to_string(nv) + " vertices and " + std::to_string(nf) + " faces: nothing to read");
    const std::uint64_t available = file_size - std::min<std::uint64_t>(file_size, header.body);
    const std::uint64_t needed = nv * std::max<std::uint64_t>(vertex_bytes, header.binary ? 12 : 6) + nf * (header.binary ? 13 : 8);
    if (needed > available) refuse_counts(path, nv, nf, needed, available);
    std::ifstream in(path, std::ios::binary);
    in.seekg(std::streamoff(header.body));
    std::string body(std::size_t(available), '\0');
    in.read(body.data(), std::streamsize(body.size()));
    body.resize(std::size_t(in.gcount()));
    walk_ply_body(path, header, body);
}

} // namespace voxwarp::mesh_io_internal
