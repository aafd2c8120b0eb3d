// The command line as a user meets it: exit codes, one-line messages naming the file, no half-written output.
#include "test_helpers.h"

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace voxwarp {
namespace {

namespace fs = std::filesystem;

struct Outcome {
    int code = -1;
    std::string err;
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
        const std::string err = file("stderr.txt");
        const int status = std::system((std::string(VOXWARP_CLI) + " " + args + " > /dev/null 2> " + err).c_str());
        std::ifstream in(err);
        std::stringstream text;
        text << in.rdbuf();
        return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text.str()};
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
    const Outcome big = run("voxelize " + test::data_path("bunny.obj") + " -o " + file("x.vdb") + " --resolution 4000 --max-memory 0.5");
    EXPECT_EQ(big.code, 3);
    EXPECT_NE(big.err.find("needs about"), std::string::npos) << big.err;
    EXPECT_FALSE(fs::exists(file("x.vdb")));
}

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
}

TEST_F(Cli, DeformIsByteIdenticalForAnyThreadCount) {
    const std::string args = " deform " + test::data_path("bunny.obj") + " " + test::data_path("bunny_ear.json") + " -r 64 -q -o ";
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

TEST_F(Cli, CompareReportsJson) {
    const Outcome r = run("compare " + test::data_path("bunny.obj") + " " + test::data_path("bunny.obj") + " --json --samples 1000");
    EXPECT_EQ(r.code, 0) << r.err;
}

} // namespace
} // namespace voxwarp
