/// @file sparse_voxmap.h
/// @brief The voxmap stored in 8^3 blocks: a block whose voxels all hold one value keeps only that value.
///
/// Same frame and density convention as Voxmap (voxel (i, j, k) centre = origin + h * (i, j, k), density in
/// [0, 1], surface at 0.5). Block (bx, by, bz) holds voxels 8 bx .. 8 bx + 7 along x (likewise y, z), aligned
/// with OpenVDB's leaf nodes; a stored block keeps its 512 values x fastest. Voxels of a border block past
/// `dims` read 0 when the block is stored; a uniform block's value holds for its voxels inside `dims`. Away
/// from the surface almost every block is uniform (0 outside, 1 inside), so a model's voxmap costs memory in
/// proportion to its surface area, not its volume: the deform pipeline runs on this type end to end.
#pragma once

#include <voxwarp/voxmap.h>

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

namespace voxwarp {

class SparseVoxmap {
public:
    static constexpr std::int64_t kSide = 8, kBlockVoxels = kSide * kSide * kSide;

    SparseVoxmap() = default;
    /// All voxels 0. @throw InvalidInput for non-positive dims or voxel size.
    SparseVoxmap(std::array<std::int64_t, 3> dims, const Eigen::Vector3d& origin, double voxel_size);
    SparseVoxmap(const SparseVoxmap& other);
    SparseVoxmap& operator=(const SparseVoxmap& other);
    SparseVoxmap(SparseVoxmap&&) noexcept = default;
    SparseVoxmap& operator=(SparseVoxmap&&) noexcept = default;

    const std::array<std::int64_t, 3>& dims() const { return dims_; }
    const Eigen::Vector3d& origin() const { return origin_; }
    double voxel_size() const { return voxel_size_; }
    std::int64_t voxel_count() const { return dims_[0] * dims_[1] * dims_[2]; }
    bool empty() const { return voxel_count() == 0; }
    /// World position of a voxel centre.
    Eigen::Vector3d world(double i, double j, double k) const { return origin_ + voxel_size_ * Eigen::Vector3d(i, j, k); }
    /// Continuous index-space position of a world point.
    Eigen::Vector3d index_of(const Eigen::Vector3d& p) const { return (p - origin_) / voxel_size_; }

    /// Blocks per axis, and block (bx, by, bz)'s index.
    const std::array<std::int64_t, 3>& block_dims() const { return block_dims_; }
    std::int64_t block_count() const { return block_dims_[0] * block_dims_[1] * block_dims_[2]; }
    std::int64_t block_index(std::int64_t bx, std::int64_t by, std::int64_t bz) const { return bx + block_dims_[0] * (by + block_dims_[1] * bz); }
    /// A stored block's 512 values (x fastest), or null for a uniform block.
    const float* block_values(std::int64_t b) const { return stored_[std::size_t(b)].get(); }
    /// A uniform block's value (meaningless for a stored block).
    float block_uniform(std::int64_t b) const { return uniform_[std::size_t(b)]; }
    /// Set block b from 512 values (x fastest; those past dims are ignored and read 0): kept as one value when
    /// all its voxels inside dims agree bit for bit. Safe to call concurrently for distinct blocks.
    void set_block(std::int64_t b, const float* values);
    /// Set every voxel of block b to `value`. Safe to call concurrently for distinct blocks.
    void set_uniform(std::int64_t b, float value);
    /// Blocks that store their values, and the bytes the whole structure takes.
    std::int64_t stored_block_count() const;
    std::uint64_t bytes() const;

    /// Density of voxel (i, j, k); 0 outside dims.
    float at(std::int64_t i, std::int64_t j, std::int64_t k) const {
        if (i < 0 || j < 0 || k < 0 || i >= dims_[0] || j >= dims_[1] || k >= dims_[2]) return 0.0f;
        const std::int64_t b = block_index(i >> 3, j >> 3, k >> 3);
        const float* v = stored_[std::size_t(b)].get();
        return v ? v[(i & 7) + kSide * ((j & 7) + kSide * (k & 7))] : uniform_[std::size_t(b)];
    }
    /// Copy row (j, k) (dims[0] values, 0 when the row lies outside) into `out`; returns whether any is nonzero
    /// (false at once for a row through uniform-zero blocks only, without comparing values).
    bool read_row(std::int64_t j, std::int64_t k, float* out) const;
    /// Whether row (j, k) is all +0 by its blocks alone (each uniform +0), or lies outside; no value is read.
    bool row_is_zero(std::int64_t j, std::int64_t k) const;
    /// Trilinear density at a continuous index-space position; 0 outside.
    float sample(const Eigen::Vector3d& index_pos) const;

private:
    std::array<std::int64_t, 3> dims_{0, 0, 0};
    std::array<std::int64_t, 3> block_dims_{0, 0, 0};
    Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
    double voxel_size_ = 1.0;
    std::vector<float> uniform_;                    ///< per block: its value when not stored
    std::vector<std::unique_ptr<float[]>> stored_;  ///< per block: its values, or null
};

/// Block-sparse copy of a dense voxmap. Parallel.
SparseVoxmap to_sparse(const Voxmap& voxmap);
/// Dense copy of a sparse voxmap. Parallel. @throw ResourceLimit when the dense array would not fit in memory.
Voxmap to_dense(const SparseVoxmap& voxmap);
/// Volume enclosed by the 0.5 isosurface (see enclosed_volume(const Voxmap&)), world units cubed; the same
/// sum, block by block (deterministic).
double enclosed_volume(const SparseVoxmap& voxmap);

} // namespace voxwarp
