#include <voxwarp/errors.h>
#include <voxwarp/resources.h>

#include <sys/resource.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>

namespace voxwarp {

std::uint64_t available_memory_bytes() {
    std::ifstream meminfo("/proc/meminfo");
    std::string key;
    std::uint64_t kib = 0;
    std::string unit;
    while (meminfo >> key >> kib >> unit)
        if (key == "MemAvailable:") return kib * 1024;
    return 0;
}

std::uint64_t peak_resident_bytes() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return std::uint64_t(usage.ru_maxrss) * 1024; // Linux reports KiB
}

std::uint64_t resident_bytes() {
    std::ifstream statm("/proc/self/statm");
    std::uint64_t size = 0, resident = 0;
    if (!(statm >> size >> resident)) return 0;
    return resident * std::uint64_t(sysconf(_SC_PAGESIZE));
}

std::string format_bytes(std::uint64_t bytes) {
    const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
    double value = double(bytes);
    int u = 0;
    while (value >= 1024 && u < 4) value /= 1024, ++u;
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, u == 0 ? "%.0f %s" : "%.2f %s", value, units[u]);
    return buffer;
}

std::uint64_t memory_limit(std::uint64_t limit_bytes) {
    if (limit_bytes != 0) return limit_bytes;
    const std::uint64_t available = available_memory_bytes();
    return available == 0 ? std::numeric_limits<std::uint64_t>::max() : available / 10 * 9;
}

void require_memory(std::uint64_t bytes, std::uint64_t limit_bytes, const std::string& what) {
    const std::uint64_t limit = memory_limit(limit_bytes);
    const char* source = limit_bytes != 0 ? "--max-memory" : "90% of available memory";
    if (bytes > limit)
        throw ResourceLimit(what + " needs about " + format_bytes(bytes) + ", more than the limit of " + format_bytes(limit) +
                            " (" + source + "); lower the resolution or raise --max-memory");
}

} // namespace voxwarp
