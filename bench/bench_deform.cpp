// End to end: the bundled ear-stretch edit on the bunny (voxelize + solve + warp + extract), beside
// OpenVDB's plain round trip (BM_RoundTripOpenVDB in bench_roundtrip.cpp) in the same run.
#include "bench_common.h"
#include <voxwarp/deform.h>
#include <voxwarp/mesh_io.h>

#include <benchmark/benchmark.h>

namespace voxwarp::bench {

/// With snap (the default) or without: the difference is what finding source points and snapping cost. With the
/// default mesher (marching cubes) or the feature mesher: the difference is what restoring sharp features costs.
static void deform_bunny_ear(benchmark::State& state, bool snap, Mesher mesher = ExtractOptions{}.mesher) {
    const TriangleMesh& bunny = bunny_mesh();
    static const EditScript script = read_edit_file(std::string(VOXWARP_DATA_DIR) + "/bunny_ear.json");
    DeformOptions options;
    options.voxelize.resolution = int(state.range(0));
    options.snap = snap;
    options.extract.mesher = mesher;
    for (auto _ : state) {
        DeformReport report;
        benchmark::DoNotOptimize(deform_mesh(bunny, script, options, report));
    }
}
static void BM_Deform(benchmark::State& state) { deform_bunny_ear(state, true); }
static void BM_DeformNoSnap(benchmark::State& state) { deform_bunny_ear(state, false); }
static void BM_DeformFeatures(benchmark::State& state) { deform_bunny_ear(state, true, Mesher::features); }
BENCHMARK(BM_Deform)->Arg(128)->Arg(256)->Arg(512)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_DeformNoSnap)->Arg(128)->Arg(256)->Arg(512)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_DeformFeatures)->Arg(128)->Arg(256)->Arg(512)->Unit(benchmark::kMillisecond)->UseRealTime();

/// Spot's head turned (data/spot_head.json), with its texture coordinates and material carried or dropped: the
/// difference is what the transfer costs (source points are found for snapping either way).
static void deform_spot_head(benchmark::State& state, bool attributes) {
    static const TriangleMesh spot = read_mesh(std::string(VOXWARP_DATA_DIR) + "/spot_triangulated.obj");
    static const TriangleMesh plain = [] {
        TriangleMesh m;
        m.vertices = spot.vertices, m.triangles = spot.triangles;
        return m;
    }();
    static const EditScript script = read_edit_file(std::string(VOXWARP_DATA_DIR) + "/spot_head.json");
    DeformOptions options;
    options.voxelize.resolution = int(state.range(0));
    for (auto _ : state) {
        DeformReport report;
        benchmark::DoNotOptimize(deform_mesh(attributes ? spot : plain, script, options, report));
    }
}
static void BM_DeformSpotTextured(benchmark::State& state) { deform_spot_head(state, true); }
static void BM_DeformSpotPlain(benchmark::State& state) { deform_spot_head(state, false); }
BENCHMARK(BM_DeformSpotTextured)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_DeformSpotPlain)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime();

} // namespace voxwarp::bench
