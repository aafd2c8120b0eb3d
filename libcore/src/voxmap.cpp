#include <voxwarp/errors.h>
#include <voxwarp/voxmap.h>

#include <limits>

#include "trilinear.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <cmath>
#include <string>

#include <sys/mman.h>

#include <cstdlib>
#include <new>

namespace voxwarp {

namespace {
constexpr std::size_t kLarge = std::size_t(4) << 20, kHugePage = std::size_t(2) << 20;
}

void* allocate_large(std::size_t bytes) {
    if (bytes < kLarge) return ::operator new(bytes);
    const std::size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
    void* p = std::aligned_alloc(kHugePage, rounded);
    if (!p) throw std::bad_alloc();
    madvise(p, rounded, MADV_HUGEPAGE); // a hint: without transparent huge pages this changes nothing
    return p;
}

void release_large(void* p, std::size_t bytes) noexcept {
    if (!p) return;
    if (bytes < kLarge)
        ::operator delete(p);
    else
        std::free(p);
}

Voxmap::Voxmap(std::array<std::int64_t, 3> d, const Eigen::Vector3d& o, double h) : dims(d), origin(o), voxel_size(h) {
    for (int a = 0; a < 3; ++a)
        if (dims[a] <= 0) throw InvalidInput("voxmap: dimension " + std::to_string(a) + " is " + std::to_string(dims[a]) + ", expected > 0");
    if (!(h > 0) || !std::isfinite(h)) throw InvalidInput("voxmap: voxel size " + std::to_string(h) + ", expected a finite value > 0");
    density.resize(std::size_t(voxel_count()));
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, density.size(), 1 << 18),
                      [&](const auto& r) { std::fill(density.begin() + std::ptrdiff_t(r.begin()), density.begin() + std::ptrdiff_t(r.end()), 0.0f); });
}

float Voxmap::sample(const Eigen::Vector3d& p) const {
    return core_internal::trilinear(p, [this](std::int64_t i, std::int64_t j, std::int64_t k) {
        return i < 0 || j < 0 || k < 0 || i >= dims[0] || j >= dims[1] || k >= dims[2] ? 0.0f : at(i, j, k);
    });
}

double enclosed_volume(const Voxmap& voxmap) {
    // Eight independent partial sums: one running sum is a chain of dependent additions, which at 512^3 took a
    // tenth of a second. Deterministic splitting keeps the figure identical from run to run.
    const double sum = tbb::parallel_deterministic_reduce(
        tbb::blocked_range<std::size_t>(0, voxmap.density.size(), 1 << 16), 0.0,
        [&](const tbb::blocked_range<std::size_t>& r, double acc) {
            double partial[8] = {};
            const float* d = voxmap.density.data();
            std::size_t i = r.begin();
            for (; i + 8 <= r.end(); i += 8)
                for (int k = 0; k < 8; ++k) partial[k] += double(d[i + std::size_t(k)]);
            for (; i != r.end(); ++i) partial[0] += double(d[i]);
            for (double p : partial) acc += p;
            return acc;
        },
        [](double a, double b) { return a + b; });
    return sum * voxmap.voxel_size * voxmap.voxel_size * voxmap.voxel_size;
}

std::uint64_t voxmap_bytes(const std::array<std::int64_t, 3>& dims) {
    // Saturating: a damaged file's grid can span 2^31 voxels a side, whose cube overflows 64 bits.
    const long double bytes = (long double)dims[0] * (long double)dims[1] * (long double)dims[2] * sizeof(float);
    return bytes >= 1.8e19L ? std::numeric_limits<std::uint64_t>::max() : std::uint64_t(bytes);
}

} // namespace voxwarp
