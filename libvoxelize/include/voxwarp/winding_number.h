/// @file winding_number.h
/// @brief Generalized winding number of a triangle soup (Jacobson et al. 2013), fast hierarchical
///        evaluation with a dipole far-field (after Barill et al. 2018, "Fast Winding Numbers").
///
/// w(q) is 1 inside a closed, outward-oriented surface, 0 outside, and varies smoothly across holes, so
/// thresholding it at 0.5 gives a robust inside/outside for scans with holes, cracks and non-manifold spots.
/// Everything is in world units; the result is dimensionless.
#pragma once

#include <voxwarp/triangle_mesh.h>

#include <memory>

namespace voxwarp {

/// Precomputed hierarchy over a mesh's triangles (the libigl precompute / query split): build once, query
/// many points from any number of threads.
class WindingNumber {
public:
    /// Build the hierarchy. O(T log T). `mesh` must outlive nothing: data is copied.
    /// @param beta  far-field acceptance: a cluster of radius r is summed as one dipole when the query is
    ///              farther than beta * r from its centre (second-order expansion). Larger = more
    ///              exact, slower. Default 3: worst error about 0.02 on a closed sphere.
    explicit WindingNumber(const TriangleMesh& mesh, double beta = 3.0);
    ~WindingNumber();
    WindingNumber(WindingNumber&&) noexcept;
    WindingNumber& operator=(WindingNumber&&) noexcept;

    /// Winding number at world point q. Thread-safe.
    double operator()(const Eigen::Vector3d& q) const;

    /// Exact O(T) sum over all triangles, for testing the hierarchy against.
    double exact(const Eigen::Vector3d& q) const;

    /// Where the segment p -> q passes through the triangles (the same hierarchy, its clusters' bounding boxes
    /// culling): how many it passes through, and the parameters in [0, 1] along it of the first and the last
    /// (both 0 when there is none). Thread-safe.
    struct Crossings {
        int count = 0;
        double first = 0, last = 0;
    };
    Crossings crossings(const Eigen::Vector3d& p, const Eigen::Vector3d& q) const;

private:
    struct Tree;
    std::unique_ptr<Tree> tree_;
};

} // namespace voxwarp
