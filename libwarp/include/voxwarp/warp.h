/// @file warp.h
/// @brief The volume warp (True & Hughes 1992, sections 3-7): push a domain voxmap forward through a lattice
///        into a target voxmap, with box filtering, fast tabulated evaluation and incremental updates.
///
/// Frames: the *domain* voxmap is aligned with the lattice's regions: domain voxel (e, f, g) sits at parameter
/// (e / Gx, f / Gy, g / Gz), G = granularity per axis (voxels per region edge, an integer). The *target*
/// voxmap is in world space with the domain's voxel size, its grid aligned with the input voxmap's, and covers
/// the warped domain.
///
/// Filtering (paper section 6): every target voxel a domain voxel's image overlaps receives weight = overlap
/// volume / voxel volume and weighted value = weight * density. The image is approximated by the bounding box
/// of the parallelepiped spanned by the map's Jacobian columns (per voxel step), each overlap scaled by
/// |det| / box volume (the paper's box of six face centres loses a quarter of the density under a 30 degree
/// rotation; this one deposits each voxel's image volume exactly and equals the paper's box for translations
/// and axis scalings). Finally density = wv / weight for any weight: the uncovered part of a voxel takes the
/// covered part's mean (the paper keeps wv where weight < 1, treating uncovered space as empty, which leaves
/// dips inside the solid and lowers a fog volume's inside). Only the narrow band within 2 voxels of a
/// fractional density is splatted; target voxels no splat reaches take the side (inside or outside) of the last
/// reached voxel along their x row, which is what the skipped voxels would have given them. Parts of either side
/// thinner than three voxels (a scan's one-voxel walls, a gap one voxel wide) are also carried: the cells their
/// voxels' image boxes hold are put back on their side where the box filter left them on the other, so a warp
/// keeps them closed (src/resolve.h says how). Weights are accumulated in 32-bit fixed point (2^-22), so sums do not depend on order:
/// the result is the same for any thread count, and an incremental update (subtract a region's old
/// contribution, add its new one) is bit-identical to a full recompute.
#pragma once

#include <voxwarp/lattice.h>
#include <voxwarp/progress.h>
#include <voxwarp/sparse_voxmap.h>
#include <voxwarp/surface_samples.h>
#include <voxwarp/voxmap.h>

#include <array>
#include <cstdint>
#include <memory>

namespace voxwarp {

/// What the user chooses about the lattice; everything else (granularity, domain size) follows from the voxmap.
struct LatticeSpec {
    std::array<int, 3> size{9, 9, 9};       ///< control points per axis (>= 4 uniform, >= 6 clamped); the papers' default 9^3
    Placement placement = Placement::uniform;
    double padding = 0.25;                  ///< uniform: the lattice reaches this fraction of the data's extent beyond it on each side
                                            ///< (further along an axis whose regions would otherwise be under half another's)
};

/// A domain aligned with a lattice's regions, ready to warp. Domain voxel (e, f, g) sits at parameter
/// (e/Gx, f/Gy, g/Gz) and holds voxmap voxel (e, f, g) - offset, or 0 outside the voxmap: the zero padding the
/// lattice needs around the data is never stored.
struct WarpDomain {
    SparseVoxmap voxmap;               ///< the data (uniform: the input itself; clamped: its capture, offset 0)
    std::array<std::int64_t, 3> offset{}; ///< domain index of voxmap voxel (0, 0, 0)
    std::array<std::int64_t, 3> dims{};   ///< domain voxels per axis: G * (n - 3)
    Lattice lattice;                   ///< the undeformed lattice
    std::array<int, 3> granularity{};  ///< G per axis: domain voxels per region edge
    Eigen::Vector3d target_origin;     ///< a world point on the target grid (the input voxmap's voxel (0,0,0) centre)
    double target_voxel_size = 1;      ///< target voxel size, world units (the input's)

    /// Density of domain voxel (e, f, g); 0 in the padding.
    float density(std::int64_t e, std::int64_t f, std::int64_t g) const { return voxmap.at(e - offset[0], f - offset[1], g - offset[2]); }
};

/// Build the domain for a voxmap. Uniform placement: a grid of G * (n - 3) voxels per axis aligned with the
/// input's voxels, the input centred in it (no copy, no resampling: the undeformed warp is the identity); G per
/// axis fits the data and its padding, raised where needed so that no axis's G is under half another's.
/// Clamped placement: the input is *captured* (pulled back through the undeformed clamped map, paper section 5)
/// into a domain of about twice the input's resolution per axis.
/// @throw InvalidInput for an empty voxmap or a bad spec; ResourceLimit when the domain would exceed max_memory_bytes
///        (0 = 90 % of available memory).
WarpDomain make_domain(SparseVoxmap input, const LatticeSpec& spec, std::uint64_t max_memory_bytes = 0);
/// The same for a dense voxmap (stored block-sparse in the domain).
WarpDomain make_domain(const Voxmap& input, const LatticeSpec& spec, std::uint64_t max_memory_bytes = 0);

struct WarpOptions {
    bool preview = false; ///< the paper's "map and round off": each voxel centre lands in one target voxel (fast, aliased)
    /// Refuse (ResourceLimit) a target whose block tables, or whose splatted band as it grows, would take more than
    /// this many bytes; 0 = 90 % of the memory available when the warp starts. A map that stretches space far can
    /// ask for far more than its input took.
    std::uint64_t max_memory_bytes = 0;
    ProgressCallback progress;
};

/// Full warp of a domain through `lattice` (the domain's lattice, with moved control points) into a target voxmap
/// covering the warped domain (block-sparse; to_dense() for a dense copy). Parallel (oneTBB), deterministic.
/// @throw Cancelled, ResourceLimit.
SparseVoxmap warp(const WarpDomain& domain, const Lattice& lattice, const WarpOptions& options = {});

/// The same, consuming the domain: its voxmap is freed as soon as it has been splatted, before the target is
/// built, so the two never take memory together. The domain's voxmap is empty afterwards.
SparseVoxmap warp(WarpDomain&& domain, const Lattice& lattice, const WarpOptions& options = {});

/// The same warp computed the slow, obvious way: the 64-term basis sum evaluated directly at every voxel, no
/// tables, one thread. For tests and the BM_WarpNaive benchmark only.
Voxmap warp_reference(const WarpDomain& domain, const Lattice& lattice);

/// Carry world points through the map: each to where `moved` takes the parameter `rest` gives it (`rest` is the
/// undeformed lattice `moved` came from). E.g. a FeatureSurface's vertices. Parallel.
void push_points(const Lattice& rest, const Lattice& moved, std::vector<Eigen::Vector3d>& points);
/// The same for a feature surface's face vertices and edge ends.
void push_feature_surface(const Lattice& rest, const Lattice& moved, FeatureSurface& surface);

/// A warp in progress (paper section 7's main loop): precompute once, then move control points and read the
/// target back. Each move re-splats only the <= 4^3 regions the point supports.
class Warp {
public:
    /// Splats the whole domain once through `lattice` (usually domain.lattice).
    Warp(WarpDomain domain, const Lattice& lattice, const WarpOptions& options = {});
    ~Warp();
    Warp(Warp&&) noexcept;
    Warp& operator=(Warp&&) noexcept;

    /// Move control point (i, j, k) to `position` (world units) and update the target incrementally: the 64 regions
    /// the point supports are splatted again, their last splat taken out first. Moving the same point again (a
    /// drag) keeps, from its second move, the other regions' sums around it (at most an eighth of the memory limit)
    /// and puts them back instead of taking the last splat out: about half the work a move. The target is the full
    /// warp's, bit for bit, either way.
    /// If the moved regions now reach outside the target's bounds, the target grows and is recomputed in full.
    /// @throw InvalidInput for an index outside the lattice or a non-finite position; ResourceLimit when the target
    ///        would outgrow WarpOptions::max_memory_bytes (the warp is then spoilt: build a new one).
    void move_control_point(int i, int j, int k, const Eigen::Vector3d& position);

    const Lattice& lattice() const;
    const WarpDomain& domain() const;
    /// The target voxmap as it stands now.
    const SparseVoxmap& target() const;

private:
    Warp(std::shared_ptr<const WarpDomain> domain, const Lattice& lattice, const WarpOptions& options, WarpDomain* consumed);
    friend SparseVoxmap warp(const WarpDomain&, const Lattice&, const WarpOptions&);
    friend SparseVoxmap warp(WarpDomain&&, const Lattice&, const WarpOptions&);
    struct State;
    std::unique_ptr<State> state_;
};

} // namespace voxwarp
