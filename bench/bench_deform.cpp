// End to end: the bundled ear-stretch edit on the bunny (voxelize + solve + warp + extract), beside
// OpenVDB's plain round trip (BM_RoundTripOpenVDB in bench_roundtrip.cpp) in the same run.
#include "bench_common.h"
#include <voxwarp/deform.h>
#include <voxwarp/mesh_io.h>

#include <benchmark/benchmark.h>

#include <chrono>

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

/// The feature mesher against marching cubes in the same iteration, in turn (which goes first alternates): this
/// VM's speed drifts by 10-20 % over a run, and two benchmarks run one after the other read that drift as a ratio.
/// The iteration's time is the feature mesher's; `ratio` is its total over marching cubes' (#24's goal: 1.1).
static void BM_DeformFeaturesVsMc(benchmark::State& state) {
    const TriangleMesh& bunny = bunny_mesh();
    static const EditScript script = read_edit_file(std::string(VOXWARP_DATA_DIR) + "/bunny_ear.json");
    DeformOptions mc, features;
    mc.voxelize.resolution = features.voxelize.resolution = int(state.range(0));
    mc.extract.mesher = Mesher::marching_cubes, features.extract.mesher = Mesher::features;
    double mc_seconds = 0, features_seconds = 0;
    bool features_first = false;
    auto timed = [&](const DeformOptions& options) {
        DeformReport report;
        const auto start = std::chrono::steady_clock::now();
        benchmark::DoNotOptimize(deform_mesh(bunny, script, options, report));
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
    for (auto _ : state) {
        double f = 0;
        if (features_first) f = timed(features), mc_seconds += timed(mc);
        else mc_seconds += timed(mc), f = timed(features);
        features_first = !features_first;
        features_seconds += f;
        state.SetIterationTime(f);
    }
    state.counters["mc_ms"] = benchmark::Counter(1e3 * mc_seconds / double(state.iterations()));
    state.counters["ratio"] = benchmark::Counter(features_seconds / mc_seconds);
}
BENCHMARK(BM_DeformFeaturesVsMc)->Arg(128)->Arg(256)->Arg(512)->Unit(benchmark::kMillisecond)->UseManualTime();

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
