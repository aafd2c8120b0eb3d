// The rotation-aware solve (rigid.h): BM_SolveRigid, its local/global iterations on a 9^3 lattice, against
// BM_SolveRigidGraphCeres, the control-point-graph ARAP baseline in Ceres; and the whole deform with it
// (BM_DeformRigid/N) beside BM_RoundTripOpenVDB/N in the same run.
#include "bench_common.h"
#include "test_helpers.h"

#include <voxwarp/deform.h>
#include <voxwarp/rigid.h>

#include <benchmark/benchmark.h>

#include <numbers>

namespace voxwarp::bench {

namespace {

/// A solve's inputs, prepared outside the timed loop: the domain's lattice, its material and the constraints.
struct RigidCase {
    Lattice rest;
    LatticeMaterial material;
    std::vector<Constraint> constraints;
};

RigidCase bar_case(bool twist) {
    const test::Bar bar{4, 1};
    const TriangleMesh box = test::box_mesh(bar.lo(), bar.hi(), 1);
    const WarpDomain domain = make_domain(voxelize_sparse(box, {.voxel_size = 1.0 / 32}), LatticeSpec{});
    const auto map = twist ? bar.twist(std::numbers::pi / 2) : bar.bend(std::numbers::pi / 2);
    return {domain.lattice, lattice_material(domain), bar.end_constraints(map, Solver::rigid).constraints};
}

RigidCase bunny_case() {
    const WarpDomain domain = make_domain(voxelize_sparse(bunny_mesh(), {.resolution = 128}), LatticeSpec{});
    return {domain.lattice, lattice_material(domain), read_edit_file(std::string(VOXWARP_DATA_DIR) + "/bunny_ear.json").edits[0].constraints};
}

const RigidCase& rigid_case(int which) {
    static const RigidCase bend = bar_case(false), twist = bar_case(true), ear = bunny_case();
    return which == 0 ? bend : which == 1 ? twist : ear;
}

} // namespace

/// Times `solve` on one case, and records its iterations.
template <class Solve>
void time_solve(benchmark::State& state, int which, Solve solve) {
    const RigidCase& c = rigid_case(which);
    int iterations = 0;
    for (auto _ : state) {
        const RigidSolution s = solve(c);
        iterations = s.iterations;
        benchmark::DoNotOptimize(s.lattice.points().data());
    }
    state.counters["iterations"] = iterations;
}

static void BM_SolveRigid(benchmark::State& state, int which) {
    time_solve(state, which, [](const RigidCase& c) { return solve_rigid(c.rest, c.constraints, c.material); });
}
BENCHMARK_CAPTURE(BM_SolveRigid, bar_bend, 0)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_SolveRigid, bar_twist, 1)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_SolveRigid, bunny_ear, 2)->Unit(benchmark::kMillisecond)->UseRealTime();

static void BM_SolveRigidGraphCeres(benchmark::State& state, int which) {
    time_solve(state, which, [](const RigidCase& c) { return solve_rigid_graph_ceres(c.rest, c.constraints, c.material); });
}
BENCHMARK_CAPTURE(BM_SolveRigidGraphCeres, bar_bend, 0)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

static void BM_DeformRigid(benchmark::State& state) {
    const TriangleMesh& bunny = bunny_mesh();
    static const EditScript script = [] {
        EditScript s = read_edit_file(std::string(VOXWARP_DATA_DIR) + "/bunny_ear.json");
        s.edits[0].solver = Solver::rigid;
        return s;
    }();
    DeformOptions options;
    options.voxelize.resolution = int(state.range(0));
    for (auto _ : state) {
        DeformReport report;
        benchmark::DoNotOptimize(deform_mesh(bunny, script, options, report));
    }
}
BENCHMARK(BM_DeformRigid)->Arg(128)->Arg(256)->Arg(512)->Unit(benchmark::kMillisecond)->UseRealTime();

} // namespace voxwarp::bench
