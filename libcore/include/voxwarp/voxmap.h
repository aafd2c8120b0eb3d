/// @file voxmap.h
/// @brief The voxmap: a dense, sampled density volume, the papers' central data structure.
///
/// Density is in [0, 1]: 1 = material, 0 = empty, the surface is the 0.5 isosurface (127 of 255 for byte
/// volumes). Voxels straddling the surface hold fractional values (antialiasing), so the surface lands
/// between voxel centres. Frames: voxel (i, j, k) has its centre at world position origin + h * (i, j, k)
/// (OpenVDB's convention); h = voxel_size in world units. Storage is x-fastest: index = i + nx * (j + ny * k).
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

namespace voxwarp {

/// Memory for big arrays (>= 4 MiB): 2 MiB-aligned and marked for transparent huge pages, because first-touch
/// page faults at 4 KiB dominated filling a 512^3 voxmap on a virtual machine. Smaller requests use operator new.
/// Pair every call with release_large(p, bytes) of the same size. @throw std::bad_alloc.
void* allocate_large(std::size_t bytes);
void release_large(void* p, std::size_t bytes) noexcept;

/// Allocator that leaves new floats uninitialised: a voxmap of 10^8 voxels is filled by the parallel loop
/// that computes it (or zeroed in parallel by Voxmap's constructor), not memset on one core first.
template <class T>
struct DefaultInitAllocator : std::allocator<T> {
    using value_type = T;
    T* allocate(std::size_t n) { return static_cast<T*>(allocate_large(n * sizeof(T))); }
    void deallocate(T* p, std::size_t n) noexcept { release_large(p, n * sizeof(T)); }
    template <class U>
    struct rebind {
        using other = DefaultInitAllocator<U>;
    };
    DefaultInitAllocator() = default;
    template <class U>
    DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}
    template <class U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
        ::new (static_cast<void*>(p)) U;
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

/// Dense density storage; `resize` leaves new values uninitialised.
using DensityArray = std::vector<float, DefaultInitAllocator<float>>;

struct Voxmap {
    std::array<std::int64_t, 3> dims{0, 0, 0}; ///< voxel counts along x, y, z (64-bit: products overflow 32 bits)
    Eigen::Vector3d origin = Eigen::Vector3d::Zero(); ///< world position of the centre of voxel (0, 0, 0)
    double voxel_size = 1.0;                          ///< h, world units per voxel edge
    DensityArray density;                             ///< dims[0]*dims[1]*dims[2] values in [0, 1], x fastest

    Voxmap() = default;
    /// A zero-filled voxmap (zeroed in parallel). @throw InvalidInput for non-positive dims or voxel size.
    Voxmap(std::array<std::int64_t, 3> dims, const Eigen::Vector3d& origin, double voxel_size);

    std::int64_t voxel_count() const { return dims[0] * dims[1] * dims[2]; }
    std::int64_t index(std::int64_t i, std::int64_t j, std::int64_t k) const { return i + dims[0] * (j + dims[1] * k); }
    float& at(std::int64_t i, std::int64_t j, std::int64_t k) { return density[std::size_t(index(i, j, k))]; }
    float at(std::int64_t i, std::int64_t j, std::int64_t k) const { return density[std::size_t(index(i, j, k))]; }
    /// World position of a voxel centre (index space -> world space).
    Eigen::Vector3d world(double i, double j, double k) const { return origin + voxel_size * Eigen::Vector3d(i, j, k); }
    /// Continuous index-space position of a world point (world space -> index space).
    Eigen::Vector3d index_of(const Eigen::Vector3d& p) const { return (p - origin) / voxel_size; }
    /// Trilinear density at a continuous index-space position; 0 outside the voxmap.
    float sample(const Eigen::Vector3d& index_pos) const;
};

/// Volume enclosed by the 0.5 isosurface, in world units cubed: sum of density times voxel volume.
/// For an antialiased voxmap whose ramp is linear across the surface this equals the enclosed volume
/// to second order in h.
double enclosed_volume(const Voxmap& voxmap);

/// Bytes a dense voxmap of these dimensions needs (the density array only).
std::uint64_t voxmap_bytes(const std::array<std::int64_t, 3>& dims);

} // namespace voxwarp
