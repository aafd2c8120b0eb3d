#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include <OpenMesh/Core/IO/IOManager.hh>
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/IO/importer/BaseImporter.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <regex>
#include <set>
#include <sstream>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

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
    void set_normal(VertexHandle, const Vec3f&) override {}
    void set_normal(VertexHandle, const Vec3d&) override {}
    void set_color(VertexHandle, const Vec3uc&) override {}
    void set_color(VertexHandle, const Vec4uc&) override {}
    void set_color(VertexHandle, const Vec3f&) override {}
    void set_color(VertexHandle, const Vec4f&) override {}
    void set_texcoord(VertexHandle, const Vec2f&) override {}
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

/// Checks run before OpenMesh reads a file, because its readers crash, assert or hang on malformed input:
/// counts versus file size, header grammar (PLY, OFF), OBJ vertex and face lines. Header counts first:
/// refuse files whose headers claim more elements than the file can hold, before an OpenMesh reader loops
/// over (or reserves for) a billion vertices. Minimum record sizes: ASCII "0 0 0\n" is 6 bytes a vertex,
/// "3 0 1 2\n" 8 bytes a face; binary records are their properties' sizes.
void validate_before_openmesh(const std::string& path, const std::string& ext, std::uintmax_t file_size) {
    std::ifstream in(path, std::ios::binary);
    std::string head(std::size_t(std::min<std::uintmax_t>(file_size, 65536)), '\0');
    in.read(head.data(), std::streamsize(head.size()));
    head.resize(std::size_t(in.gcount()));
    auto refuse = [&](std::uint64_t vertices, std::uint64_t faces, std::uint64_t needed, std::uint64_t available) {
        throw InvalidInput(path + ": header declares " + std::to_string(vertices) + " vertices and " + std::to_string(faces) +
                           " faces, which need at least " + std::to_string(needed) + " bytes, but the file holds " + std::to_string(available));
    };
    if (ext == ".obj") {
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
        return;
    }
    if (ext == ".stl") {
        const bool ascii = head.rfind("solid", 0) == 0 && head.find("facet") != std::string::npos;
        if (ascii) return;
        if (file_size < 84) throw InvalidInput(path + ": binary STL shorter than its 84-byte header");
        std::uint32_t count = 0;
        std::memcpy(&count, head.data() + 80, 4);
        if (84 + 50 * std::uint64_t(count) != file_size)
            throw InvalidInput(path + ": binary STL declares " + std::to_string(count) + " triangles (" + std::to_string(84 + 50 * std::uint64_t(count)) +
                               " bytes) but the file holds " + std::to_string(file_size) + " bytes");
        return;
    }
    std::istringstream text(head);
    std::string line;
    if (ext == ".off") {
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
        if (needed > file_size) refuse(std::uint64_t(nv), std::uint64_t(nf), needed, file_size);
        if (binary) return;
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
        return;
    }
    if (ext == ".ply") {
        bool binary = false;
        std::uint64_t nv = 0, nf = 0, vertex_bytes = 0;
        std::string current;
        std::size_t header_end = std::string::npos;
        auto type_size = [](const std::string& t) -> std::uint64_t {
            if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
            if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
            if (t == "double" || t == "float64") return 8;
            return 4;
        };
        // OpenMesh's PLY reader crashes or hangs on malformed headers (a property before any element, no
        // end_header: both found by fuzzing), so the header's grammar is checked here, line by line.
        static const std::set<std::string> types{"char", "uchar", "short", "ushort", "int", "uint", "float", "double", "int8", "uint8",
                                                 "int16", "uint16", "int32", "uint32", "float32", "float64"};
        std::size_t line_no = 0;
        bool format_seen = false;
        auto bad = [&](const std::string& what) {
            throw InvalidInput(path + ": PLY header line " + std::to_string(line_no) + ": " + what);
        };
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
                if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian") bad("unknown format '" + format + "'");
                if (version != "1.0") bad("unsupported PLY version '" + version.substr(0, 20) + "', expected 1.0"); // OpenMesh loops on others
                binary = format != "ascii";
                format_seen = true;
            } else if (word == "element") {
                std::string count_text;
                words >> current >> count_text;
                if (current.empty() || count_text.empty() || count_text.find_first_not_of("0123456789") != std::string::npos || count_text.size() > 12)
                    bad("expected \"element <name> <count>\"");
                const std::uint64_t n = std::stoull(count_text);
                if (current == "vertex") nv = n;
                if (current == "face") nf = n;
            } else if (word == "property") {
                if (current.empty()) bad("property before any element");
                std::string type, name;
                words >> type;
                if (type == "list") {
                    std::string count_type, item_type;
                    words >> count_type >> item_type >> name;
                    if (!types.count(count_type) || !types.count(item_type) || name.empty()) bad("expected \"property list <type> <type> <name>\"");
                } else {
                    words >> name;
                    if (!types.count(type) || name.empty()) bad("expected \"property <type> <name>\"");
                }
                if (std::string extra; words >> extra) bad("unexpected '" + extra.substr(0, 20) + "' after the property name");
                if (current == "vertex") vertex_bytes += binary ? type_size(type) : 2;
            } else if (word == "end_header") {
                if (!format_seen) bad("end_header before any format line");
                header_end = std::size_t(text.tellg());
                break;
            } else if (word != "comment" && word != "obj_info" && !word.empty()) {
                bad("unexpected '" + word + "'");
            }
        }
        // OpenMesh's PLY reader loops forever on a header without end_header (found by fuzzing).
        if (head.rfind("ply", 0) != 0) throw InvalidInput(path + ": not a PLY file (it does not start with \"ply\")");
        if (header_end == std::string::npos) throw InvalidInput(path + ": PLY header has no end_header line within its first 64 KiB");
        if (nv < 3 || nf < 1)
            throw InvalidInput(path + ": PLY header declares " + std::to_string(nv) + " vertices and " + std::to_string(nf) + " faces: nothing to read");
        const std::uint64_t available = file_size - std::min<std::uint64_t>(file_size, header_end);
        const std::uint64_t needed = nv * std::max<std::uint64_t>(vertex_bytes, binary ? 12 : 6) + nf * (binary ? 13 : 8);
        if (needed > available) refuse(nv, nf, needed, available);
    }
}

} // namespace mesh_io_internal

using namespace mesh_io_internal;

bool is_mesh_path(const std::string& path) {
    const auto ext = lower_extension(path);
    return ext == ".obj" || ext == ".off" || ext == ".ply" || ext == ".stl" || ext == ".om";
}

TriangleMesh read_mesh(const std::string& path) {
    static QuietOpenMesh quiet;
    namespace fs = std::filesystem;
    std::error_code ec;
    if (!fs::exists(path, ec)) throw IOError(path + ": no such file");
    if (fs::is_directory(path, ec)) throw IOError(path + ": is a directory, expected a mesh file");
    if (!is_mesh_path(path))
        throw InvalidInput(path + ": unknown mesh format '" + lower_extension(path) + "', expected .obj, .off, .ply, .stl or .om");
    if (std::ifstream probe(path, std::ios::binary); !probe) throw IOError(path + ": cannot open for reading");
    const auto file_size = fs::file_size(path, ec);
    if (file_size == 0) throw InvalidInput(path + ": file is empty");
    validate_before_openmesh(path, lower_extension(path), file_size);

    SoupImporter importer;
    IO::Options options;
    if (lower_extension(path) == ".om") {
        // The OM reader rebuilds halfedge connectivity, so it needs a real halfedge mesh behind it.
        OutputMesh om;
        if (!IO::read_mesh(om, path)) throw InvalidInput(path + ": cannot parse as an OpenMesh .om file");
        for (auto v : om.vertices()) importer.add_vertex(om.point(v));
        for (auto f : om.faces()) {
            IO::BaseImporter::VHandles ids;
            for (auto v : om.fv_range(f)) ids.push_back(v);
            importer.add_face(ids);
        }
    } else if (!IO::IOManager().read(path, importer, options)) {
        throw InvalidInput(path + ": cannot parse as a " + lower_extension(path).substr(1) + " mesh" +
                           (importer.first_problem.empty() ? "" : ": " + importer.first_problem));
    }
    if (!importer.first_problem.empty()) throw InvalidInput(path + ": " + importer.first_problem);
    if (importer.mesh.vertices.empty()) throw InvalidInput(path + ": no vertices");
    if (importer.mesh.triangles.empty()) throw InvalidInput(path + ": no faces");
    return std::move(importer.mesh);
}

void write_mesh(const TriangleMesh& mesh, const std::string& path) {
    static QuietOpenMesh quiet;
    if (!is_mesh_path(path))
        throw InvalidInput(path + ": unknown mesh format '" + lower_extension(path) + "', expected .obj, .off, .ply, .stl or .om");
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
