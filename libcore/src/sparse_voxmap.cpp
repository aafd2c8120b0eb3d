#include <voxwarp/errors.h>
#include <voxwarp/resources.h>
#include <voxwarp/sparse_voxmap.h>

#include "trilinear.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <string>

namespace voxwarp {

SparseVoxmap::SparseVoxmap(std::array<std::int64_t, 3> dims, const Eigen::Vector3d& origin, double voxel_size)
    : dims_(dims), origin_(origin), voxel_size_(voxel_size) {
    for (int a = 0; a < 3; ++a)
        if (dims[std::size_t(a)] <= 0) throw InvalidInput("voxmap: dimension " + std::to_string(a) + " is " + std::to_string(dims[std::size_t(a)]) + ", expected > 0");
    if (!(voxel_size > 0) || !std::isfinite(voxel_size)) throw InvalidInput("voxmap: voxel size " + std::to_string(voxel_size) + ", expected a finite value > 0");
    for (std::size_t a = 0; a < 3; ++a) block_dims_[a] = (dims[a] + kSide - 1) / kSide;
    uniform_.assign(std::size_t(block_count()), 0.0f);
    stored_.resize(std::size_t(block_count()));
}

SparseVoxmap::SparseVoxmap(const SparseVoxmap& other)
    : dims_(other.dims_), block_dims_(other.block_dims_), origin_(other.origin_), voxel_size_(other.voxel_size_), uniform_(other.uniform_) {
    stored_.resize(other.stored_.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, stored_.size(), 4096), [&](const auto& r) {
        for (std::size_t b = r.begin(); b != r.end(); ++b)
            if (other.stored_[b]) {
                stored_[b] = std::make_unique_for_overwrite<float[]>(std::size_t(kBlockVoxels));
                std::memcpy(stored_[b].get(), other.stored_[b].get(), sizeof(float) * std::size_t(kBlockVoxels));
            }
    });
}

SparseVoxmap& SparseVoxmap::operator=(const SparseVoxmap& other) {
    if (this != &other) *this = SparseVoxmap(other);
    return *this;
}

void SparseVoxmap::set_uniform(std::int64_t b, float value) {
    stored_[std::size_t(b)].reset();
    uniform_[std::size_t(b)] = value;
}

void SparseVoxmap::set_block(std::int64_t b, const float* values) {
    const std::int64_t bx = b % block_dims_[0], by = (b / block_dims_[0]) % block_dims_[1], bz = b / (block_dims_[0] * block_dims_[1]);
    // Voxels of this block inside dims: [0, nx) x [0, ny) x [0, nz), block-relative.
    const std::int64_t nx = std::min(kSide, dims_[0] - kSide * bx), ny = std::min(kSide, dims_[1] - kSide * by), nz = std::min(kSide, dims_[2] - kSide * bz);
    const std::uint32_t pattern = std::bit_cast<std::uint32_t>(values[0]);
    std::uint32_t differs = 0;
    if (nx == kSide && ny == kSide && nz == kSide) {
        for (std::int64_t q = 0; q < kBlockVoxels; ++q) differs |= std::bit_cast<std::uint32_t>(values[q]) ^ pattern;
    } else {
        for (std::int64_t z = 0; z < nz; ++z)
            for (std::int64_t y = 0; y < ny; ++y)
                for (std::int64_t x = 0; x < nx; ++x) differs |= std::bit_cast<std::uint32_t>(values[x + kSide * (y + kSide * z)]) ^ pattern;
    }
    auto& slot = stored_[std::size_t(b)];
    if (differs == 0) {
        slot.reset();
        uniform_[std::size_t(b)] = values[0];
        return;
    }
    if (!slot) slot = std::make_unique_for_overwrite<float[]>(std::size_t(kBlockVoxels));
    float* out = slot.get();
    std::memcpy(out, values, sizeof(float) * std::size_t(kBlockVoxels));
    if (nx < kSide || ny < kSide || nz < kSide)
        for (std::int64_t z = 0; z < kSide; ++z)
            for (std::int64_t y = 0; y < kSide; ++y)
                for (std::int64_t x = 0; x < kSide; ++x)
                    if (x >= nx || y >= ny || z >= nz) out[x + kSide * (y + kSide * z)] = 0.0f;
}

std::int64_t SparseVoxmap::stored_block_count() const {
    return std::int64_t(std::count_if(stored_.begin(), stored_.end(), [](const auto& p) { return p != nullptr; }));
}

std::uint64_t SparseVoxmap::bytes() const {
    return std::uint64_t(stored_block_count()) * sizeof(float) * std::uint64_t(kBlockVoxels) + stored_.size() * (sizeof(float) + sizeof(void*));
}

bool SparseVoxmap::read_row(std::int64_t j, std::int64_t k, float* out) const {
    if (j < 0 || k < 0 || j >= dims_[1] || k >= dims_[2]) {
        std::fill_n(out, dims_[0], 0.0f);
        return false;
    }
    const std::int64_t row = kSide * ((j & 7) + kSide * (k & 7));
    const std::int64_t b0 = block_index(0, j >> 3, k >> 3);
    bool any = false;
    for (std::int64_t bx = 0; bx < block_dims_[0]; ++bx) {
        const std::int64_t x0 = kSide * bx, n = std::min(kSide, dims_[0] - x0);
        if (const float* v = stored_[std::size_t(b0 + bx)].get()) {
            std::copy_n(v + row, n, out + x0);
            any = true;
        } else {
            const float u = uniform_[std::size_t(b0 + bx)];
            std::fill_n(out + x0, n, u);
            any |= std::bit_cast<std::uint32_t>(u) != 0;
        }
    }
    return any;
}

bool SparseVoxmap::row_is_zero(std::int64_t j, std::int64_t k) const {
    if (j < 0 || k < 0 || j >= dims_[1] || k >= dims_[2]) return true;
    const std::size_t b0 = std::size_t(block_index(0, j >> 3, k >> 3));
    for (std::size_t b = b0; b < b0 + std::size_t(block_dims_[0]); ++b)
        if (stored_[b] || std::bit_cast<std::uint32_t>(uniform_[b]) != 0) return false;
    return true;
}

float SparseVoxmap::sample(const Eigen::Vector3d& p) const {
    return core_internal::trilinear(p, [this](std::int64_t i, std::int64_t j, std::int64_t k) { return at(i, j, k); });
}

SparseVoxmap to_sparse(const Voxmap& voxmap) {
    SparseVoxmap out(voxmap.dims, voxmap.origin, voxmap.voxel_size);
    const auto& bd = out.block_dims();
    constexpr std::int64_t S = SparseVoxmap::kSide;
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, out.block_count()), [&](const auto& r) {
        float values[SparseVoxmap::kBlockVoxels];
        for (std::int64_t b = r.begin(); b != r.end(); ++b) {
            const std::int64_t i0 = S * (b % bd[0]), j0 = S * ((b / bd[0]) % bd[1]), k0 = S * (b / (bd[0] * bd[1]));
            const std::int64_t n = std::min(S, voxmap.dims[0] - i0);
            for (std::int64_t z = 0; z < S; ++z)
                for (std::int64_t y = 0; y < S; ++y) {
                    float* row = values + S * (y + S * z);
                    if (j0 + y < voxmap.dims[1] && k0 + z < voxmap.dims[2]) {
                        std::copy_n(&voxmap.density[std::size_t(voxmap.index(i0, j0 + y, k0 + z))], n, row);
                        std::fill(row + n, row + S, 0.0f);
                    } else {
                        std::fill(row, row + S, 0.0f);
                    }
                }
            out.set_block(b, values);
        }
    });
    return out;
}

Voxmap to_dense(const SparseVoxmap& voxmap) {
    const auto& dims = voxmap.dims();
    require_memory(voxmap_bytes(dims), 0, "a dense voxmap of " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]));
    Voxmap out;
    out.dims = dims;
    out.origin = voxmap.origin();
    out.voxel_size = voxmap.voxel_size();
    out.density.resize(std::size_t(out.voxel_count())); // uninitialised: every row is written below
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, dims[1] * dims[2], 64), [&](const auto& r) {
        for (std::int64_t q = r.begin(); q != r.end(); ++q) {
            const std::int64_t j = q % dims[1], k = q / dims[1];
            voxmap.read_row(j, k, &out.density[std::size_t(out.index(0, j, k))]);
        }
    });
    return out;
}

double enclosed_volume(const SparseVoxmap& voxmap) {
    const auto& bd = voxmap.block_dims();
    const auto& dims = voxmap.dims();
    constexpr std::int64_t S = SparseVoxmap::kSide;
    const double sum = tbb::parallel_deterministic_reduce(
        tbb::blocked_range<std::int64_t>(0, voxmap.block_count(), 1024), 0.0,
        [&](const tbb::blocked_range<std::int64_t>& r, double acc) {
            for (std::int64_t b = r.begin(); b != r.end(); ++b) {
                if (const float* v = voxmap.block_values(b)) {
                    double partial[8] = {}; // independent sums: one running sum is a dependent chain
                    for (std::int64_t q = 0; q < SparseVoxmap::kBlockVoxels; q += 8)
                        for (int t = 0; t < 8; ++t) partial[t] += double(v[q + t]);
                    for (double p : partial) acc += p;
                } else if (const float u = voxmap.block_uniform(b); u != 0.0f) {
                    const std::int64_t bx = b % bd[0], by = (b / bd[0]) % bd[1], bz = b / (bd[0] * bd[1]);
                    const std::int64_t n = std::min(S, dims[0] - S * bx) * std::min(S, dims[1] - S * by) * std::min(S, dims[2] - S * bz);
                    acc += double(u) * double(n);
                }
            }
            return acc;
        },
        [](double a, double b) { return a + b; });
    const double h = voxmap.voxel_size();
    return sum * h * h * h;
}

} // namespace voxwarp
