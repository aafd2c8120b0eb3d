/// @file lattice.h
/// @brief The lattice: a trivariate uniform cubic B-spline map from parameter space (s, t, u) to world space.
///
/// nx x ny x nz control points (each >= 4) in world coordinates; the parameter domain is the closed box
/// [0, nx-3] x [0, ny-3] x [0, nz-3]; region (a, b, c) = floor of (s, t, u) (clamped so the far faces
/// belong to the last region) is shaped by control points a..a+3, b..b+3, c..c+3 (True & Hughes eq. 2).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <string>
#include <vector>

namespace voxwarp {

/// How the undeformed control points are laid out.
enum class Placement {
    uniform, ///< evenly spaced, one spacing beyond the domain: the undeformed map is an affine identity (thesis 5.5)
    clamped, ///< end points tripled, the rest evenly spaced: the image is exactly the data box (paper section 7)
};

std::string to_string(Placement placement);
/// "uniform" or "clamped". @throw InvalidInput otherwise.
Placement placement_from_string(const std::string& name);

class Lattice {
public:
    Lattice() = default;

    /// Uniform placement: P_ijk = origin + ((i-1) sx, (j-1) sy, (k-1) sz), so B(s,t,u) = origin + (s sx, t sy, u sz).
    /// @param size     control points per axis, each in [4, 1024]
    /// @param origin   world position of parameter (0, 0, 0)
    /// @param spacing  world distance between neighbouring control points per axis (> 0)
    /// @throw InvalidInput for sizes or spacings out of range
    static Lattice uniform(const std::array<int, 3>& size, const Eigen::Vector3d& origin, const Eigen::Vector3d& spacing);

    /// Clamped placement: along each axis the first three and last three control points coincide with the box's
    /// faces and the n-4 distinct positions between are evenly spaced, so B maps the parameter box onto [lo, hi].
    /// @param size  control points per axis, each in [6, 1024] (fewer leave no distinct interior point)
    /// @throw InvalidInput for sizes out of range or an empty box
    static Lattice clamped(const std::array<int, 3>& size, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi);

    const std::array<int, 3>& size() const { return size_; }
    std::array<int, 3> regions() const { return {size_[0] - 3, size_[1] - 3, size_[2] - 3}; }
    Placement placement() const { return placement_; }
    std::size_t control_point_count() const { return points_.size(); }
    std::size_t flat_index(int i, int j, int k) const { return std::size_t(i) + std::size_t(size_[0]) * (std::size_t(j) + std::size_t(size_[1]) * std::size_t(k)); }

    /// Control point (i, j, k), world units.
    const Eigen::Vector3d& point(int i, int j, int k) const { return points_[flat_index(i, j, k)]; }
    void set_point(int i, int j, int k, const Eigen::Vector3d& p) { points_[flat_index(i, j, k)] = p; }
    const std::vector<Eigen::Vector3d>& points() const { return points_; }
    std::vector<Eigen::Vector3d>& points() { return points_; }
    /// The undeformed control points the lattice was built with (world units).
    const std::vector<Eigen::Vector3d>& rest_points() const { return rest_points_; }
    /// Undeformed world distance per parameter unit along each axis (the control-point spacing).
    const Eigen::Vector3d& spacing() const { return spacing_; }
    /// Undeformed world position of parameter (0, 0, 0): parameter_of an undeformed uniform lattice is
    /// (world - rest_origin()) / spacing().
    const Eigen::Vector3d& rest_origin() const { return origin_; }

    /// B(s, t, u): world position of a parameter point. Parameters outside the domain extrapolate the
    /// boundary region's polynomial.
    Eigen::Vector3d evaluate(const Eigen::Vector3d& stu) const;
    /// dB/d(s,t,u): columns are the derivatives along s, t, u (world units per parameter unit).
    Eigen::Matrix3d jacobian(const Eigen::Vector3d& stu) const;
    /// B(s, t, u) and its Jacobian in one pass over the 64 control points (what a Newton step needs).
    Eigen::Vector3d evaluate(const Eigen::Vector3d& stu, Eigen::Matrix3d& jacobian) const;
    /// The 64 basis weights of the control points that shape B at stu, and the region they belong to.
    /// weights[i + 4 (j + 4 k)] multiplies point(a+i, b+j, c+k).
    void weights(const Eigen::Vector3d& stu, std::array<int, 3>& region, std::array<double, 64>& weights) const;
    /// The 64 weights of B's derivative at stu along the parameter direction `dstu`: sum_i w_i P_i = J(stu) dstu.
    void derivative_weights(const Eigen::Vector3d& stu, const Eigen::Vector3d& dstu, std::array<int, 3>& region, std::array<double, 64>& weights) const;
    /// The 64 control points of `region` weighted by `weights` (as weights() and its kin give them) and summed: a
    /// point, a derivative or a second derivative of B, by the weights.
    Eigen::Vector3d combine(const std::array<int, 3>& region, const std::array<double, 64>& weights) const;
    /// The 64 weights of B's second derivative at stu along the parameter directions `a` and `b`:
    /// sum_i w_i P_i = sum_pq a_p b_q d^2 B / d(stu)_p d(stu)_q.
    void second_derivative_weights(const Eigen::Vector3d& stu, const Eigen::Vector3d& a, const Eigen::Vector3d& b, std::array<int, 3>& region,
                                   std::array<double, 64>& weights) const;

    /// Parameter of a world point: exact (affine inverse) for an undeformed uniform lattice, Newton's method
    /// with the Jacobian otherwise, started from the undeformed guess. @throw SolverFailure when Newton does not
    /// converge to within 1e-9 of the parameter box's size.
    Eigen::Vector3d parameter_of(const Eigen::Vector3d& world) const;
    /// True when `stu` lies in the closed parameter domain (within `tolerance` parameter units).
    bool contains_parameter(const Eigen::Vector3d& stu, double tolerance = 1e-9) const;

private:
    std::array<int, 3> size_{0, 0, 0};
    Placement placement_ = Placement::uniform;
    std::vector<Eigen::Vector3d> points_;
    // Undeformed layout, for parameter_of's initial guess and exact affine inverse.
    Eigen::Vector3d origin_ = Eigen::Vector3d::Zero(), spacing_ = Eigen::Vector3d::Ones();
    std::vector<Eigen::Vector3d> rest_points_;
    friend class Warp;
};

} // namespace voxwarp
