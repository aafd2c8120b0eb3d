// Round trip mesh -> voxmap -> mesh (voxwarp) beside OpenVDB's plain mesh -> level set -> mesh, same run.
#include "bench_common.h"

#include <voxwarp/extract.h>
#include <voxwarp/openvdb_baseline.h>
#include <voxwarp/voxelize.h>

#include <benchmark/benchmark.h>

namespace voxwarp::bench {

static void BM_RoundTripOpenVDB(benchmark::State& state) {
    const TriangleMesh& bunny = bunny_mesh();
    for (auto _ : state) benchmark::DoNotOptimize(openvdb_round_trip(bunny, int(state.range(0))));
}
BENCHMARK(BM_RoundTripOpenVDB)->Arg(128)->Arg(256)->Arg(512)->Unit(benchmark::kMillisecond)->UseRealTime();

static void BM_RoundTrip(benchmark::State& state) {
    const TriangleMesh& bunny = bunny_mesh();
    for (auto _ : state) {
        const SparseVoxmap voxmap = voxelize_sparse(bunny, {.resolution = int(state.range(0))});
        benchmark::DoNotOptimize(extract(voxmap));
    }
}
BENCHMARK(BM_RoundTrip)->Arg(128)->Arg(256)->Arg(512)->Unit(benchmark::kMillisecond)->UseRealTime();

// An open scan voxelized: the sign comes from winding numbers (about half the time at 128), as no flood fill can
// sign an open surface. Compare builds by running both in turn (docs/benchmarks.md).
static void BM_VoxelizeScan(benchmark::State& state) {
    for (auto _ : state) benchmark::DoNotOptimize(voxelize_sparse(scan_mesh(), {.resolution = int(state.range(0)), .sign = SignMethod::winding_number}));
}
BENCHMARK(BM_VoxelizeScan)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime();

} // namespace voxwarp::bench
