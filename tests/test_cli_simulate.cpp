// `sonotrace simulate` end to end: the default frame and its sidecar, byte-identical
// frames on 1 and 2 threads, JSON scene files, and bad input that fails cleanly.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "test_util.h"

namespace sonotrace {
namespace {

using test::files_in;
using test::run;
using test::ScratchDir;
using test::slurp;

TEST(CliSimulate, DefaultFrameWithSidecar) {
    ScratchDir dir;
    const auto r = run(
        dir, "simulate -q --quality interactive --formats png8,png16,exr --out " + (dir / "out"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const char* f : {"bmode.png", "bmode_16.png", "bmode.exr", "bmode.json"})
        EXPECT_TRUE(std::filesystem::exists(dir / ("out/" + std::string(f)))) << f;
    const auto record = nlohmann::json::parse(slurp(dir / "out/bmode.json"));
    EXPECT_EQ(record["probe"]["name"], "convex");
    EXPECT_EQ(record["seed"], 1);
    EXPECT_TRUE(record.contains("version"));
    EXPECT_TRUE(record["timings_s"].contains("trace"));
    EXPECT_EQ(record["image"]["pixel_spacing_mm"][0], 0.2);
    EXPECT_LT(std::abs(record["stats"]["energy_balance_error"].get<double>()), 1e-6);
}

TEST(CliSimulate, FramesByteIdenticalOnOneAndTwoThreads) {
    ScratchDir dir;
    const std::string common = "simulate -q --quality interactive --formats png16,png8 ";
    ASSERT_EQ(run(dir, common + "--threads 1 --out " + (dir / "a")).exit_code, 0);
    ASSERT_EQ(run(dir, common + "--threads 2 --out " + (dir / "b")).exit_code, 0);
    for (const char* f : {"bmode_16.png", "bmode.png"})
        EXPECT_TRUE(slurp(dir / ("a/" + std::string(f))) == slurp(dir / ("b/" + std::string(f))))
            << f;
}

TEST(CliSimulate, BadInputFailsWithoutPartialOutput) {
    ScratchDir dir;
    const struct {
        std::string args;
        const char* mention;
    } cases[] = {{"--elements 0", "elements"},
                 {"--focus 200", "beyond the imaging depth"},
                 {"--probe phased --fov 190", "fov"},
                 {"--fov 120", "arc"},
                 {"--probe sector", "unknown transducer preset 'sector'"},
                 {"--frequency nan", "frequency"},
                 {"--tgc 10:0,x", "--tgc"},
                 {"--formats gif", "--formats"},
                 {"--receive echo", "--receive"},
                 {"--pose 'at=1,2'", "--pose"},
                 {"--volume /no/such.nii", "/no/such.nii"}};
    for (const auto& c : cases) {
        const auto r =
            run(dir, "simulate -q --quality interactive " + c.args + " --out " + (dir / "out"));
        EXPECT_NE(r.exit_code, 0) << c.args;
        EXPECT_NE(r.err.find(c.mention), std::string::npos) << c.args << ": " << r.err;
        EXPECT_TRUE(files_in(dir / "out").empty()) << c.args;
    }
    // An output path that cannot be written: a file where the directory should be.
    std::ofstream(dir / "blocked") << "x";
    const auto r = run(dir, "simulate -q --quality interactive --out " + (dir / "blocked/sub"));
    EXPECT_NE(r.exit_code, 0);
    EXPECT_NE(r.err.find("blocked"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace sonotrace
