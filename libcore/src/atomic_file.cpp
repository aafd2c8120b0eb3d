#include <voxwarp/atomic_file.h>
#include <voxwarp/errors.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <system_error>

namespace voxwarp {

void write_atomically(const std::string& path, const std::function<void(const std::string&)>& write) {
    namespace fs = std::filesystem;
    const fs::path target(path);
    // The temporary keeps the target's extension: writers choose the format by it.
    std::random_device rd;
    // Built by appending: GCC 12 misreads "." + std::string as an overlapping copy (-Wrestrict, its bug 105329).
    std::string name(".");
    name.append(target.stem().string()).append(".tmp").append(std::to_string(rd() % 1000000)).append(target.extension().string());
    const fs::path tmp = target.parent_path() / name;
    try {
        write(tmp.string());
        std::error_code ec;
        if (!fs::exists(tmp, ec)) throw IOError(path + ": the writer produced no file");
        fs::rename(tmp, target, ec);
        if (ec) throw IOError(path + ": cannot move the finished output into place: " + ec.message());
    } catch (...) {
        std::error_code ec;
        fs::remove(tmp, ec);
        throw;
    }
}

void write_file_atomically(const std::string& path, std::string_view bytes, const std::string& what) {
    write_atomically(path, [&](const std::string& tmp) {
        std::ofstream out(tmp, std::ios::binary);
        out.write(bytes.data(), std::streamsize(bytes.size()));
        out.close();
        if (!out) throw IOError(path + ": writing " + what + " failed");
    });
}

} // namespace voxwarp
