// The warp engine: the paper's set-up, 256^3, one incremental control-point move, and the naive reference.
#include "bench_common.h"

#include <voxwarp/voxelize.h>
#include <voxwarp/warp.h>

#include <benchmark/benchmark.h>

#include <cmath>
#include <map>

namespace voxwarp::bench {

namespace {

/// A voxelized bunny of about `n` voxels per side, its lattice domain, and a smooth deformation moving the
/// interior control points by up to `amplitude` voxels (a sine field, so neighbours move coherently).
struct WarpCase {
    WarpDomain domain;
    Lattice deformed;
};

const WarpCase& warp_case(int n, double padding, double amplitude) {
    static std::map<int, WarpCase> cases;
    auto it = cases.find(n);
    if (it != cases.end()) return it->second;
    // voxelize pads by 3 voxels each side: resolution n - 7 gives an n-voxel longest side.
    const Voxmap voxmap = voxelize(bunny_mesh(), {.resolution = n - 7});
    WarpCase c{make_domain(voxmap, {.size = {9, 9, 9}, .padding = padding}), {}};
    c.deformed = c.domain.lattice;
    const double h = voxmap.voxel_size;
    for (int k = 1; k < 8; ++k)
        for (int j = 1; j < 8; ++j)
            for (int i = 1; i < 8; ++i)
                c.deformed.set_point(i, j, k, c.deformed.point(i, j, k) + amplitude * h * Eigen::Vector3d(std::sin(0.9 * j + 0.3 * k), std::cos(0.7 * i), std::sin(0.8 * i + 0.5 * j)));
    return cases.emplace(n, std::move(c)).first->second;
}

} // namespace

// True & Hughes' set-up: ISIZE = 30 data in a 60^3 domain (G = 10 with a 9^3 lattice), target ~38^3.
static void BM_WarpPaperConfig(benchmark::State& state) {
    const WarpCase& c = warp_case(30, 0.5, 2.0);
    for (auto _ : state) benchmark::DoNotOptimize(warp(c.domain, c.deformed));
    state.counters["domain_voxels"] = double(c.domain.dims[0] * c.domain.dims[1] * c.domain.dims[2]);
}
BENCHMARK(BM_WarpPaperConfig)->Unit(benchmark::kMillisecond)->UseRealTime();

static void BM_Warp(benchmark::State& state) {
    const WarpCase& c = warp_case(int(state.range(0)), 0.0, 3.0);
    for (auto _ : state) benchmark::DoNotOptimize(warp(c.domain, c.deformed));
    state.counters["domain_voxels"] = double(c.domain.dims[0] * c.domain.dims[1] * c.domain.dims[2]);
}
BENCHMARK(BM_Warp)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime();

static void BM_IncrementalControlPoint(benchmark::State& state) {
    const WarpCase& c = warp_case(int(state.range(0)), 0.0, 3.0);
    Warp progressive(c.domain, c.deformed);
    const Eigen::Vector3d rest = progressive.lattice().point(4, 4, 4);
    const double h = c.domain.target_voxel_size;
    int flip = 0;
    for (auto _ : state) progressive.move_control_point(4, 4, 4, rest + ((flip++ & 1) ? 2.0 : -2.0) * h * Eigen::Vector3d(1, 0.5, 0));
}
BENCHMARK(BM_IncrementalControlPoint)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime();

// Two control points moved in turn: each move is the first of its point's drag (its last splat taken out, the
// rest kept for the next), the cost a one-off move of any point pays.
static void BM_IncrementalTwoPoints(benchmark::State& state) {
    const WarpCase& c = warp_case(int(state.range(0)), 0.0, 3.0);
    Warp progressive(c.domain, c.deformed);
    const Eigen::Vector3d rest[2] = {progressive.lattice().point(4, 4, 4), progressive.lattice().point(3, 4, 4)};
    const double h = c.domain.target_voxel_size;
    int flip = 0;
    for (auto _ : state) {
        const int which = flip & 1;
        progressive.move_control_point(4 - which, 4, 4, rest[which] + (((flip++ >> 1) & 1) ? 2.0 : -2.0) * h * Eigen::Vector3d(1, 0.5, 0));
    }
}
BENCHMARK(BM_IncrementalTwoPoints)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime();

static void BM_WarpNaive(benchmark::State& state) {
    const int n = int(state.range(0));
    const WarpCase& c = n == 60 ? warp_case(30, 0.5, 2.0) : warp_case(n, 0.0, 3.0);
    for (auto _ : state) benchmark::DoNotOptimize(warp_reference(c.domain, c.deformed));
}
BENCHMARK(BM_WarpNaive)->Arg(60)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1)->Repetitions(3);

} // namespace voxwarp::bench
