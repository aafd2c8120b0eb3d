// OBJ material libraries (.mtl): read what voxwarp carries (names, Kd, map_Kd, and every other statement as text),
// and write them back beside an output with texture paths that still lead to the textures.
#include "mesh_validate.h"

#include <voxwarp/errors.h>
#include <voxwarp/mesh_io.h>

#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <unordered_map>

namespace voxwarp {

namespace {

namespace fs = std::filesystem;

std::string trim(const std::string& s) {
    const auto b = s.find_first_not_of(" \t\r\v\f");
    if (b == std::string::npos) return "";
    return s.substr(b, s.find_last_not_of(" \t\r\v\f") - b + 1);
}

// Statements whose last word is a texture file.
bool names_a_map(const std::string& keyword) {
    return keyword.rfind("map_", 0) == 0 || keyword == "bump" || keyword == "disp" || keyword == "decal" || keyword == "norm" || keyword == "refl";
}

// The statement with its last word (the file) replaced.
std::string with_file(const std::string& statement, const std::string& file) {
    const auto at = statement.find_last_of(" \t");
    return statement.substr(0, at + 1) + file;
}

// A word of a file for a message: printable, and short.
std::string printable(const std::string& word) {
    std::string out;
    for (const char c : word.substr(0, 40)) out += std::isprint(static_cast<unsigned char>(c)) ? c : '?';
    return "'" + out + (word.size() > 40 ? "...'" : "'");
}

std::string last_word(const std::string& statement) {
    const auto at = statement.find_last_of(" \t");
    return at == std::string::npos ? "" : statement.substr(at + 1);
}

} // namespace

std::vector<Material> read_material_library(const std::string& path, std::vector<std::string>* warnings) {
    std::ifstream in(path);
    if (!in) throw IOError(path + ": cannot open for reading");
    const fs::path folder = fs::path(path).parent_path();
    std::vector<Material> materials;
    std::string raw;
    std::size_t number = 0;
    while (std::getline(in, raw)) {
        ++number;
        const std::string line = trim(raw);
        if (line.empty() || line[0] == '#') continue;
        std::istringstream words(line);
        std::string keyword;
        words >> keyword;
        if (keyword == "newmtl") {
            std::string name;
            std::getline(words, name);
            materials.push_back(Material{trim(name)});
            continue;
        }
        if (materials.empty()) throw InvalidInput(path + ": line " + std::to_string(number) + ": " + printable(keyword) + " before any newmtl");
        Material& m = materials.back();
        if (keyword == "Kd") {
            Eigen::Vector3d kd;
            if (!(words >> kd[0] >> kd[1] >> kd[2]) || !kd.allFinite())
                throw InvalidInput(path + ": line " + std::to_string(number) + ": Kd needs three finite numbers");
            m.diffuse = kd;
            continue;
        }
        if (!names_a_map(keyword)) {
            m.statements.push_back(line);
            continue;
        }
        const std::string file = last_word(line);
        if (file.empty()) throw InvalidInput(path + ": line " + std::to_string(number) + ": " + keyword + " names no file");
        const std::string usable = (folder / file).lexically_normal().string();
        std::error_code ec;
        if (warnings && !fs::exists(usable, ec)) warnings->push_back(path + ": material '" + m.name + "': texture " + usable + " not found");
        if (keyword == "map_Kd" && m.texture.empty() && line.size() == keyword.size() + 1 + file.size()) m.texture = usable; // no options: the plain diffuse map
        else m.statements.push_back(with_file(line, usable));
    }
    return materials;
}

std::string encode_material_library(const std::vector<Material>& materials, const std::string& folder) {
    auto from_folder = [&](const std::string& file) { return mesh_io_internal::path_from_folder(file, folder); };
    std::ostringstream out;
    out << "# voxwarp\n";
    for (const auto& m : materials) {
        out << "newmtl " << m.name << "\nKd " << m.diffuse.x() << ' ' << m.diffuse.y() << ' ' << m.diffuse.z() << '\n';
        if (!m.texture.empty()) out << "map_Kd " << from_folder(m.texture) << '\n';
        for (const auto& s : m.statements) {
            std::istringstream words(s);
            std::string keyword;
            words >> keyword;
            out << (names_a_map(keyword) ? with_file(s, from_folder(last_word(s))) : s) << '\n';
        }
    }
    return out.str();
}

namespace mesh_io_internal {

std::string path_from_folder(const std::string& file, const std::string& folder) {
    std::error_code ec;
    const fs::path absolute = fs::absolute(file, ec);
    const fs::path relative = fs::relative(absolute, fs::absolute(folder.empty() ? fs::path(".") : fs::path(folder)), ec);
    return (ec || relative.empty() ? absolute : relative).generic_string();
}

void fill_materials(const std::string& obj_path, const std::vector<std::string>& libraries, std::vector<Material>& materials, std::vector<std::string>& warnings) {
    const fs::path folder = fs::path(obj_path).parent_path();
    std::unordered_map<std::string, std::size_t> by_name;
    for (std::size_t i = 0; i < materials.size(); ++i) by_name.emplace(materials[i].name, i);
    std::vector<bool> defined(materials.size(), false);
    bool all_found = true;
    if (libraries.empty()) warnings.push_back(obj_path + ": uses materials but names no material library (mtllib)");
    for (const auto& library : libraries) {
        const std::string path = (folder / library).lexically_normal().string();
        std::error_code ec;
        if (!fs::is_regular_file(path, ec)) {
            warnings.push_back(obj_path + ": material library " + path + " not found; its materials keep their names only");
            all_found = false;
            continue;
        }
        for (auto& m : read_material_library(path, &warnings))
            if (const auto it = by_name.find(m.name); it != by_name.end() && !defined[it->second]) {
                materials[it->second] = std::move(m);
                defined[it->second] = true;
            }
    }
    for (std::size_t i = 0; i < materials.size(); ++i)
        if (!defined[i] && !libraries.empty() && all_found) warnings.push_back(obj_path + ": material '" + materials[i].name + "' is defined in no material library");
}

} // namespace mesh_io_internal

} // namespace voxwarp
