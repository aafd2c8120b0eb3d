// The command line as a user meets it: exit codes, one-line messages naming the file, no half-written output.
#include "test_helpers.h"

#include <voxwarp/mesh_io.h>

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <tuple>
#include <vector>

namespace voxwarp {
namespace {

namespace fs = std::filesystem;

struct Outcome {
    int code = -1;
    std::string err, out;
};

class Cli : public ::testing::Test {
protected:
    fs::path dir;
    void SetUp() override {
        dir = fs::temp_directory_path() / ("voxwarp_cli_" + std::to_string(::getpid()) + "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::create_directories(dir);
    }
    void TearDown() override { fs::remove_all(dir); }
    std::string file(const std::string& name) const { return (dir / name).string(); }
    std::string write(const std::string& name, const std::string& text) const {
        std::ofstream(file(name)) << text;
        return file(name);
    }
    Outcome run(const std::string& args) const {
        const std::string err = file("stderr.txt"), out = file("stdout.txt");
        const int status = std::system((std::string(VOXWARP_CLI) + " " + args + " > " + out + " 2> " + err).c_str());
        auto text_of = [](const std::string& path) {
            std::ifstream in(path);
            std::stringstream text;
            text << in.rdbuf();
            return text.str();
        };
        return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text_of(err), text_of(out)};
    }
    static int lines(const std::string& s) { return int(std::count(s.begin(), s.end(), '\n')); }
};

TEST_F(Cli, MalformedEditFileFailsWithOneLineAndNoOutput) {
    const std::string edits = write("bad.json", R"({"edits": [{"constraints": [{"move": [0, 0, "x"], "to": [0, 1, 0]}]}]})");
    const Outcome r = run("deform " + test::data_path("bunny.obj") + " " + edits + " -o " + file("out.obj") + " -q");
    EXPECT_EQ(r.code, 2);
    EXPECT_EQ(lines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find("bad.json"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("edits[0].constraints[0].move[2]"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(file("out.obj")));
}

TEST_F(Cli, FailedRunLeavesAnExistingOutputUntouched) {
    const std::string out = write("out.obj", "# precious\n");
    const std::string edits = write("far.json", R"({"edits": [{"constraints": [{"move": [500, 0, 0], "to": [501, 0, 0]}]}]})");
    const Outcome r = run("deform " + test::data_path("bunny.obj") + " " + edits + " -o " + out + " -q");
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find("far outside the model"), std::string::npos) << r.err;
    std::ifstream in(out);
    std::stringstream text;
    text << in.rdbuf();
    EXPECT_EQ(text.str(), "# precious\n");
    for (const auto& entry : fs::directory_iterator(dir)) EXPECT_EQ(entry.path().string().find(".tmp"), std::string::npos) << entry.path();
}

TEST_F(Cli, BadMeshIsNamedWithItsProblem) {
    const std::string mesh = write("broken.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
    const Outcome r = run("voxelize " + mesh + " -o " + file("out.vdb"));
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find("broken.obj"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("vertex 9"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(file("out.vdb")));
}

TEST_F(Cli, ExitCodesForMissingFilesUsageAndResourceLimits) {
    EXPECT_EQ(run("voxelize " + file("missing.obj") + " -o " + file("x.vdb")).code, 5);
    EXPECT_EQ(run("deform " + test::data_path("bunny.obj")).code, 1);
    EXPECT_EQ(run("voxelize " + test::data_path("bunny.obj") + " -o " + file("x.vdb") + " --resolution 100000").code, 2);
    // A voxel size of 0 once meant "use --resolution" without a word.
    for (const std::string size : {"0", "-1", "abc"}) {
        const Outcome zero = run("deform " + test::data_path("bunny.obj") + " " + test::data_path("bunny_ear.json") + " -o " + file("x.obj") + " --voxel-size " + size);
        EXPECT_EQ(zero.code, 1) << size;
        EXPECT_NE(zero.err.find("--voxel-size: expected a number above 0, got " + size), std::string::npos) << zero.err;
    }
    EXPECT_EQ(run("voxelize " + test::data_path("bunny.obj") + " -o " + file("x.vdb") + " --voxel-size 0").code, 1);
    // A negative memory limit was cast to an unsigned byte count, and the run went on as if unlimited.
    for (const std::string& command : {"voxelize " + test::data_path("bunny.obj") + " -o " + file("x.vdb"),
                                      "deform " + test::data_path("bunny.obj") + " " + test::data_path("bunny_ear.json") + " -o " + file("x.obj"),
                                      "remesh " + test::data_path("bunny.obj") + " -o " + file("x.obj")})
        for (const std::string limit : {"0", "-1"}) {
            const Outcome refused = run(command + " -r 16 --max-memory " + limit);
            EXPECT_EQ(refused.code, 1) << command << limit;
            EXPECT_NE(refused.err.find("--max-memory: expected a number above 0, got " + limit), std::string::npos) << refused.err;
        }
    EXPECT_FALSE(fs::exists(file("x.vdb")));
    EXPECT_FALSE(fs::exists(file("x.obj")));
    const Outcome big = run("voxelize " + test::data_path("bunny.obj") + " -o " + file("x.vdb") + " --resolution 4000 --max-memory 0.5");
    EXPECT_EQ(big.code, 3);
    EXPECT_NE(big.err.find("needs about"), std::string::npos) << big.err;
    EXPECT_FALSE(fs::exists(file("x.vdb")));
    // The deform estimate adds the warp's sums to the sparse voxmap: about 1.2 GiB at 1024 for the bunny.
    const Outcome deform = run("deform " + test::data_path("bunny.obj") + " " + test::data_path("bunny_ear.json") + " -o " + file("x.obj") +
                               " --resolution 1024 --max-memory 0.5");
    EXPECT_EQ(deform.code, 3);
    EXPECT_NE(deform.err.find("deforming at"), std::string::npos) << deform.err;
    EXPECT_FALSE(fs::exists(file("x.obj")));
}

#ifndef VOXWARP_SANITIZED // (built without it in the sanitizers' suite: see tests/CMakeLists.txt)
TEST_F(Cli, TheMemoryEstimateCoversThePeak) {
    // The estimate a request is refused on must not fall short of what the run then takes: the snapping added
    // since it was first fitted took the bunny at 128 to 1.7 times it, the scan with the feature mesher to 1.5.
    // Each run's own peak over its resident memory at the start (both in its report) against its estimate.
    const std::vector<std::string> cases{"bunny.obj bunny_ear.json -r 128", "bunny.obj bunny_ear.json -r 128 --no-snap",
                                         "snowden_lo.obj snowden_nose.json -r 128", "snowden_lo.obj snowden_nose.json -r 128 --mesher features"};
    for (const std::string& c : cases) {
        std::istringstream words(c);
        std::string mesh, edits, rest, word;
        words >> mesh >> edits;
        while (words >> word) rest += " " + word;
        const Outcome r = run("deform " + test::data_path(mesh) + " " + test::data_path(edits) + rest + " -o " + file("m.obj") + " -q --report " + file("m.json"));
        ASSERT_EQ(r.code, 0) << c << ": " << r.err;
        std::ifstream in(file("m.json"));
        const nlohmann::json j = nlohmann::json::parse(in);
        const double estimate = j.at("memory_estimate_bytes").get<double>(), used = j.at("peak_resident_bytes").get<double>() - j.at("resident_bytes_at_start").get<double>();
        std::printf("%s: estimate %.1f MiB, peak over the start %.1f MiB (%.2f x)\n", c.c_str(), estimate / 1048576, used / 1048576, estimate / used);
        // Measured 1.14-1.49 x; at most twice, so that a request that fits is not refused.
        EXPECT_GE(estimate, used) << c;
        EXPECT_LE(estimate, 2 * used) << c;
    }
}
#endif

TEST_F(Cli, DeformWritesMeshAndReport) {
    const Outcome r = run("deform " + test::data_path("bunny.obj") + " " + test::data_path("bunny_ear.json") + " -o " + file("ear.ply") + " -r 64 --report " +
                      file("report.json") + " -q");
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(fs::exists(file("ear.ply")));
    std::ifstream in(file("report.json"));
    std::stringstream text;
    text << in.rdbuf();
    EXPECT_NE(text.str().find("\"residual_voxels\""), std::string::npos);
    EXPECT_NE(text.str().find("\"volume_before\""), std::string::npos);
    EXPECT_NE(text.str().find("\"peak_resident_bytes\""), std::string::npos);
    EXPECT_NE(text.str().find("\"snap\": true"), std::string::npos);
    // --no-snap: the vertices extraction gives, and the report says so.
    const Outcome plain = run("deform " + test::data_path("bunny.obj") + " " + test::data_path("bunny_ear.json") + " -o " + file("plain.ply") +
                              " -r 64 --no-snap --report " + file("plain.json") + " -q");
    EXPECT_EQ(plain.code, 0) << plain.err;
    std::ifstream plain_in(file("plain.json"));
    std::stringstream plain_text;
    plain_text << plain_in.rdbuf();
    EXPECT_NE(plain_text.str().find("\"snap\": false"), std::string::npos);
    EXPECT_NE(plain_text.str().find("\"snapped_vertices\": 0"), std::string::npos);
    // Snapped: the same vertices moved, then those refinement put on edges across the bunny's creases.
    const TriangleMesh snapped = read_mesh(file("ear.ply")), extracted = read_mesh(file("plain.ply"));
    ASSERT_GT(snapped.vertices.size(), extracted.vertices.size());
    EXPECT_NE(text.str().find("\"refined_vertices\": " + std::to_string(snapped.vertices.size() - extracted.vertices.size())), std::string::npos);
    double moved = 0;
    for (std::size_t v = 0; v < extracted.vertices.size(); ++v) moved = std::max(moved, (snapped.vertices[v] - extracted.vertices[v]).norm());
    EXPECT_GT(moved, 0.0);
}

// Every class of bad input, through the command line: exit code 2, one line naming the file, no output.
TEST_F(Cli, EveryClassOfBadInputIsRefusedCleanly) {
    std::string lying_stl(80, ' ');
    const std::uint32_t lying = 1000;
    lying_stl.append(reinterpret_cast<const char*>(&lying), 4);
    lying_stl.append(50, '\0');
    const std::vector<std::tuple<std::string, std::string, std::string>> cases{
        // file name, content, expected words in the message
        {"empty.obj", "", "file is empty"},
        {"garbage.off", "this is not an OFF file\n", "garbage.off"},
        {"nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite"},
        {"index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "refers to vertex 9"},
        {"negative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -9\n", "negative.obj"},
        {"short.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "short.obj"},
        {"degenerate.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "zero area"},
        {"billion.ply", "ply\nformat ascii 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\n"
                        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n", "header declares 1000000000 vertices"},
        {"billion.off", "OFF\n1000000000 1 0\n0 0 0\n", "header declares 1000000000 vertices"},
        {"lying.stl", lying_stl, "declares 1000 triangles"},
        {"far.obj", "v 1e12 0 0\nv 1e12 1 0\nv 1e12 0 1\nv 1e12 1 1\nf 1 2 3\nf 2 4 3\nf 1 3 4\nf 1 4 2\n", "double precision"},
    };
    for (const auto& [name, content, expected] : cases) {
        const std::string input = write(name, content);
        const Outcome r = run("voxelize " + input + " -o " + file("out.vdb") + " -q");
        EXPECT_EQ(r.code, 2) << name << ": " << r.err;
        EXPECT_EQ(lines(r.err), 1) << name << ": " << r.err;
        EXPECT_NE(r.err.find(name), std::string::npos) << name << ": " << r.err;
        EXPECT_NE(r.err.find(expected), std::string::npos) << name << ": " << r.err;
        EXPECT_FALSE(fs::exists(file("out.vdb"))) << name;
    }
    // Volumes: not a .vdb, a .vdb without a float grid, a float grid full of NaN.
    const Outcome junk = run("extract " + write("junk.vdb", "not a vdb") + " -o " + file("out.obj") + " -q");
    EXPECT_EQ(junk.code, 2) << junk.err;
    EXPECT_NE(junk.err.find("junk.vdb"), std::string::npos) << junk.err;
    EXPECT_FALSE(fs::exists(file("out.obj")));
}

TEST_F(Cli, DeformIsByteIdenticalForAnyThreadCount) {
    // At 200 the output has enough vertices (130 K) for the scheduler to split them differently for one thread and
    // two, which once changed the snapped vertices in their last bits (a warm start carried across its ranges).
    const std::string args = " deform " + test::data_path("bunny.obj") + " " + test::data_path("bunny_ear.json") + " -r 200 -q -o ";
    ASSERT_EQ(run("--threads 1" + args + file("one.obj")).code, 0);
    ASSERT_EQ(run("--threads 2" + args + file("two.obj")).code, 0);
    auto bytes = [](const std::string& path) {
        std::ifstream in(path, std::ios::binary);
        std::stringstream text;
        text << in.rdbuf();
        return text.str();
    };
    const std::string one = bytes(file("one.obj"));
    EXPECT_GT(one.size(), 1000u);
    EXPECT_TRUE(one == bytes(file("two.obj")));
}

TEST_F(Cli, RigidDeformIsByteIdenticalForAnyThreadCountAndReportsItsSolver) {
    const std::string args = " deform " + test::data_path("box.obj") + " " + test::data_path("box_twist.json") + " -r 48 -q -o ";
    ASSERT_EQ(run("--threads 1" + args + file("one.ply") + " --report " + file("report.json")).code, 0);
    ASSERT_EQ(run("--threads 2" + args + file("two.ply")).code, 0);
    auto bytes = [](const std::string& path) {
        std::ifstream in(path, std::ios::binary);
        std::stringstream text;
        text << in.rdbuf();
        return text.str();
    };
    EXPECT_GT(bytes(file("one.ply")).size(), 1000u);
    EXPECT_TRUE(bytes(file("one.ply")) == bytes(file("two.ply")));
    const std::string report = bytes(file("report.json"));
    EXPECT_NE(report.find("\"solver\": \"rigid\""), std::string::npos) << report;
    EXPECT_NE(report.find("\"surface_miss_voxels\""), std::string::npos) << report;
}

TEST_F(Cli, RemeshCarriesTheTextureAndItsLibrary) {
    // Spot copied into a folder of its own; the output goes to another, whose .mtl must still find the texture.
    fs::create_directories(dir / "in");
    fs::create_directories(dir / "out");
    for (const char* name : {"spot_triangulated.obj", "spot.mtl", "spot_texture.png"}) fs::copy_file(test::data_path(name), dir / "in" / name);
    const Outcome r = run("remesh " + file("in/spot_triangulated.obj") + " -o " + file("out/cow.obj") + " -r 48 --report " + file("report.json") + " -q");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(r.err.empty()) << r.err; // no warning: the library and its texture were found
    std::ifstream library(dir / "out" / "cow.mtl");
    std::stringstream text;
    text << library.rdbuf();
    EXPECT_NE(text.str().find("newmtl Spot\n"), std::string::npos) << text.str();
    EXPECT_NE(text.str().find("map_Kd ../in/spot_texture.png\n"), std::string::npos) << text.str();
    std::vector<std::string> warnings;
    const TriangleMesh out = read_mesh(file("out/cow.obj"), &warnings);
    EXPECT_TRUE(warnings.empty());
    EXPECT_EQ(out.triangle_uvs.size(), out.triangles.size());
    ASSERT_EQ(out.materials.size(), 1u);
    EXPECT_TRUE(fs::equivalent(out.materials[0].texture, dir / "in" / "spot_texture.png"));
    std::ifstream report(file("report.json"));
    std::stringstream json;
    json << report.rdbuf();
    EXPECT_NE(json.str().find("\"attributes\": true"), std::string::npos) << json.str();
    // `info` names what the input carries (Spot: 3225 texture coordinates, no normals) and what a plain mesh does not.
    const Outcome info = run("info " + file("in/spot_triangulated.obj"));
    ASSERT_EQ(info.code, 0) << info.err;
    EXPECT_NE(info.out.find("attributes: 3225 texture coordinates, 1 material\n"), std::string::npos) << info.out;
    EXPECT_NE(run("info " + test::data_path("bunny.obj")).out.find("attributes: none\n"), std::string::npos);

    // An output named like the input's library never overwrites it: its own library takes another name.
    std::ifstream before(dir / "in" / "spot.mtl");
    const std::string input_library((std::istreambuf_iterator<char>(before)), std::istreambuf_iterator<char>());
    ASSERT_EQ(run("remesh " + file("in/spot_triangulated.obj") + " -o " + file("in/spot.obj") + " -r 32 -q").code, 0);
    std::ifstream after(dir / "in" / "spot.mtl");
    EXPECT_EQ(std::string((std::istreambuf_iterator<char>(after)), std::istreambuf_iterator<char>()), input_library);
    EXPECT_TRUE(fs::exists(dir / "in" / "spot_voxwarp.mtl"));
    EXPECT_EQ(read_mesh(file("in/spot.obj")).materials.at(0).texture, (dir / "in" / "spot_texture.png").string());

    // Broken references: a missing texture is a warning and the run goes on; a texture coordinate index out of
    // range is refused with the file and line, and nothing is written.
    fs::remove(dir / "in" / "spot_texture.png");
    const Outcome warned = run("remesh " + file("in/spot_triangulated.obj") + " -o " + file("out/warned.obj") + " -r 32 -q");
    EXPECT_EQ(warned.code, 0) << warned.err;
    EXPECT_NE(warned.err.find("warning: " + file("in/spot.mtl") + ": material 'Spot': texture"), std::string::npos) << warned.err;
    const std::string bad = write("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nf 1/1 3/1 2/1\nf 1/1 2/1 4/1\nf 1/1 4/1 3/1\nf 2/1 3/1 4/2\n");
    const Outcome refused = run("remesh " + bad + " -o " + file("out/bad.obj") + " -q");
    EXPECT_EQ(refused.code, 2);
    EXPECT_EQ(lines(refused.err), 1) << refused.err;
    EXPECT_NE(refused.err.find("bad.obj: line 9: face refers to texture coordinate 2, file has 1"), std::string::npos) << refused.err;
    EXPECT_FALSE(fs::exists(file("out/bad.obj")));
}

TEST_F(Cli, AnInputWithNoVolumeOfItsOwnHasNoVolumeChange) {
    // Two octahedra, one wound inside out: their volumes cancel, and the remesh (two solids) has nothing to be a
    // percentage of. It read "volume 0 -> 2.67 (+0.00%)".
    TriangleMesh wrong = test::inverted(test::octahedron_mesh());
    for (auto& v : wrong.vertices) v.x() += 3;
    write_mesh(test::joined(test::octahedron_mesh(), wrong), file("pair.obj"));
    const Outcome r = run("remesh " + file("pair.obj") + " -r 48 -o " + file("out.obj") + " --report " + file("report.json"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("(no input volume to compare)"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("+0.00%"), std::string::npos) << r.err;
    std::ifstream in(file("report.json"));
    const nlohmann::json j = nlohmann::json::parse(in);
    EXPECT_TRUE(j["volume_change_percent"].is_null()) << j["volume_change_percent"];
    EXPECT_NEAR(j["volume_after"].get<double>(), 8.0 / 3.0, 0.03 * 8.0 / 3.0);
}

TEST_F(Cli, RemeshWithoutSnappingKeepsAcuteTips) {
    // Through the command line (the feature surface made at the remesh's own voxel size, no snapping to put the
    // input's corners in): a tetrahedron's corners, thinner than a voxel for about a voxel, are lost by voxelizing
    // and came back only where a fan happened to reach them: 5 of 24 such runs missed a corner by 0.9-1.6 voxels
    // before lost tips were put back (2026-12-07); none since.
    std::mt19937 rng(17);
    std::uniform_real_distribution<double> angle(0, 2 * M_PI);
    for (const int resolution : {32, 48})
        for (int trial = 0; trial < 6; ++trial) {
            const double a = angle(rng), b = angle(rng), c = angle(rng); // drawn in this order, on any compiler
            SCOPED_TRACE("at " + std::to_string(resolution) + ", turn " + std::to_string(trial));
            const Eigen::Matrix3d turn = test::turn_zxy(a, b, c);
            TriangleMesh tetrahedron = test::tetrahedron_mesh();
            for (auto& p : tetrahedron.vertices) p = turn * p;
            write_mesh(tetrahedron, file("tetrahedron.obj"));
            const Outcome r = run("remesh " + file("tetrahedron.obj") + " -o " + file("out.ply") + " -r " + std::to_string(resolution) +
                                  " --mesher features --no-snap --report " + file("report.json") + " -q");
            ASSERT_EQ(r.code, 0) << r.err;
            std::ifstream in(file("report.json"));
            const double h = nlohmann::json::parse(in)["voxel_size"].get<double>();
            const TriangleMesh out = read_mesh(file("out.ply"));
            for (const auto& corner : tetrahedron.vertices) {
                double nearest = std::numeric_limits<double>::infinity();
                for (const auto& v : out.vertices) nearest = std::min(nearest, (v - corner).norm());
                EXPECT_LE(nearest / h, 0.3);
            }
        }
}

TEST_F(Cli, CompareReportsJson) {
    // The bunny against itself moved by 0.05 along x (a hundredth of its size): every point of either lies within
    // 0.05 of the other, and the facts of both are the bunny's.
    TriangleMesh moved = read_mesh(test::data_path("bunny.obj"));
    for (auto& v : moved.vertices) v.x() += 0.05;
    write_mesh(moved, file("moved.obj"));
    const Outcome r = run("compare " + test::data_path("bunny.obj") + " " + file("moved.obj") + " --json --samples 1000 > " + file("compare.json") + " #");
    ASSERT_EQ(r.code, 0) << r.err;
    std::ifstream in(file("compare.json"));
    const nlohmann::json j = nlohmann::json::parse(in);
    for (const char* side : {"a", "b"}) {
        EXPECT_EQ(j[side]["faces"], 3674);
        EXPECT_EQ(j[side]["euler"], 2);
        EXPECT_EQ(j[side]["components"], 1);
        EXPECT_TRUE(j[side]["closed"].get<bool>() && j[side]["manifold"].get<bool>());
        EXPECT_NEAR(j[side]["enclosed_volume"].get<double>(), enclosed_volume(moved), 1e-9 * enclosed_volume(moved));
    }
    for (const char* way : {"a_to_b", "b_to_a"}) {
        const auto& d = j["distance"][way];
        EXPECT_GT(d["mean"].get<double>(), 0.0);
        EXPECT_LE(d["mean"].get<double>(), d["p99"].get<double>());
        EXPECT_LE(d["p99"].get<double>(), d["max"].get<double>());
        EXPECT_LE(d["max"].get<double>(), 0.05 + 1e-9);
        EXPECT_GE(d["samples"].get<int>(), 1000);
    }
}

} // namespace
} // namespace voxwarp
