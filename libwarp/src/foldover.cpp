#include <voxwarp/errors.h>
#include <voxwarp/foldover.h>

#include <Eigen/LU>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <mutex>

namespace voxwarp {

std::vector<Fold> find_folds(const Lattice& lattice, int samples, double threshold) {
    if (samples < 1 || samples > 64) throw InvalidInput("find_folds: samples per region " + std::to_string(samples) + " outside [1, 64]");
    const auto r = lattice.regions();
    const std::size_t count = std::size_t(r[0]) * std::size_t(r[1]) * std::size_t(r[2]);
    // Scale: the undeformed uniform determinant is the product of the spacings; use the lattice's own spread.
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
    for (const auto& p : lattice.points()) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
    const Eigen::Vector3d spacing = (hi - lo).cwiseQuotient(Eigen::Vector3d(r[0] + 2, r[1] + 2, r[2] + 2));
    const double scale = std::abs(spacing.prod());
    const bool clamped = lattice.placement() == Placement::clamped;
    std::vector<Fold> folds;
    std::mutex mutex;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count), [&](const auto& range) {
        for (std::size_t q = range.begin(); q != range.end(); ++q) {
            const int a = int(q % std::size_t(r[0])), b = int((q / std::size_t(r[0])) % std::size_t(r[1])), c = int(q / (std::size_t(r[0]) * std::size_t(r[1])));
            Fold worst{{a, b, c}, std::numeric_limits<double>::infinity(), Eigen::Vector3d::Zero()};
            for (int z = 0; z <= samples; ++z)
                for (int y = 0; y <= samples; ++y)
                    for (int x = 0; x <= samples; ++x) {
                        const Eigen::Vector3d stu(a + double(x) / samples, b + double(y) / samples, c + double(z) / samples);
                        if (clamped) {
                            bool on_face = false;
                            for (int i = 0; i < 3; ++i) on_face |= stu[i] <= 0 || stu[i] >= r[std::size_t(i)];
                            if (on_face) continue;
                        }
                        const double det = lattice.jacobian(stu).determinant();
                        if (det < worst.min_determinant) worst.min_determinant = det, worst.parameter = stu;
                    }
            if (worst.min_determinant <= threshold * scale) {
                std::lock_guard lock(mutex);
                folds.push_back(worst);
            }
        }
    });
    std::sort(folds.begin(), folds.end(), [](const Fold& x, const Fold& y) { return x.region < y.region; });
    return folds;
}

} // namespace voxwarp
