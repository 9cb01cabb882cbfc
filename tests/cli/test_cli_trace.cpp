// `sonotrace trace` end to end: each built-in figure runs and writes its pictures and a
// balanced energy ledger; outputs are byte-identical on 1 and 2 threads; bad input fails
// cleanly without partial output.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace sonotrace {
namespace {

using test::files_in;
using test::run;
using test::ScratchDir;
using test::slurp;

TEST(CliTrace, EveryFigureConfigurationRuns) {
    ScratchDir dir;
    for (const char* config : {"fig2", "fig4a", "fig4b", "fig6"}) {
        const std::string out = dir / config;
        const auto r = run(dir, std::string("trace -q --config ") + config + " --out " + out);
        ASSERT_EQ(r.exit_code, 0) << config << ": " << r.err;
        for (const char* f :
             {"paths.png", "fluence.png", "medium.png", "overview.png", "trace.json"}) {
            EXPECT_TRUE(std::filesystem::exists(out + "/" + f)) << config << " " << f;
        }
        const auto record = nlohmann::json::parse(slurp(out + "/trace.json"));
        EXPECT_LT(std::abs(record["ledger"]["relative_error"].get<double>()), 1e-6) << config;
        EXPECT_EQ(record["settings"]["mode"], "paper");
    }
    EXPECT_TRUE(std::filesystem::exists(dir / "fig6/profile.png"));
    EXPECT_TRUE(std::filesystem::exists(dir / "fig6/profile.csv"));
}

TEST(CliTrace, VolumeSliceByteIdenticalOnOneAndTwoThreads) {
    ScratchDir dir;
    const std::string common = "trace -q --particles 600 --lines 6 --resolution 0.5 --echoes ";
    ASSERT_EQ(run(dir, common + (dir / "a.csv") + " --threads 1 --out " + (dir / "a")).exit_code,
              0);
    ASSERT_EQ(run(dir, common + (dir / "b.csv") + " --threads 2 --out " + (dir / "b")).exit_code,
              0);
    for (const char* f : {"paths.png", "fluence.png", "absorbed.png", "medium.png"}) {
        EXPECT_EQ(slurp(dir / (std::string("a/") + f)), slurp(dir / (std::string("b/") + f))) << f;
    }
    const std::string echoes = slurp(dir / "a.csv");
    EXPECT_GT(std::count(echoes.begin(), echoes.end(), '\n'), 100);
    EXPECT_EQ(echoes, slurp(dir / "b.csv"));
    const auto record = nlohmann::json::parse(slurp(dir / "a/trace.json"));
    EXPECT_EQ(record["settings"]["mode"], "acoustic");
    EXPECT_LT(std::abs(record["ledger"]["relative_error"].get<double>()), 1e-6);
    EXPECT_GT(record["ledger"]["absorbed"].get<double>(), 0.0);
}

// `trace --disable` takes simulate's switch names and does what simulate's do to the
// tracer (imaging::switch_off): on the default head slice (acoustic mode), with
// attenuation, the shear waves and the lossy rough lobes off nothing is absorbed (the
// ledger's absorbed energy is exactly 0) where it absorbs otherwise, and bounces off
// retires a particle at its first reflection.
TEST(CliTrace, DisableTakesSimulatesSwitchNames) {
    ScratchDir dir;
    auto trace = [&](const std::string& disable) {
        const auto r =
            run(dir, "trace -q --particles 400 --disable " + disable + " --out " + (dir / "out"));
        EXPECT_EQ(r.exit_code, 0) << r.err;
        return nlohmann::json::parse(slurp(dir / "out/trace.json"));
    };
    const auto off = trace("attenuation,shear,diffuse,bounces");
    const auto& physics_off = off["settings"]["physics"];
    EXPECT_FALSE(physics_off["attenuation"].get<bool>());
    EXPECT_FALSE(physics_off["diffuse_reflection"].get<bool>());
    EXPECT_FALSE(physics_off["shear_conversion"].get<bool>());
    EXPECT_FALSE(physics_off["multiple_bounces"].get<bool>());
    EXPECT_TRUE(physics_off["refraction"].get<bool>());
    EXPECT_EQ(off["ledger"]["absorbed"].get<double>(), 0.0);
    // The old name, accepted for a release with a warning that names the new one.
    const auto r = run(dir, "trace -q --particles 400 --disable absorption --out " + (dir / "old"));
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find("physics 'absorption' is now called 'attenuation'"), std::string::npos)
        << r.err;
    EXPECT_FALSE(
        nlohmann::json::parse(slurp(dir / "old/trace.json"))["settings"]["physics"]["attenuation"]
            .get<bool>());
    const auto on = trace("refraction");
    EXPECT_FALSE(on["settings"]["physics"]["refraction"].get<bool>());
    EXPECT_TRUE(on["settings"]["physics"]["multiple_bounces"].get<bool>());
    EXPECT_GT(on["ledger"]["absorbed"].get<double>(), 0.0);
}

TEST(CliTrace, BadInputFailsWithoutPartialOutput) {
    ScratchDir dir;
    const struct {
        const char* args;
        const char* mention;
    } cases[] = {{"--config fig9", "unknown configuration 'fig9'"},
                 {"--disable gravity", "--disable: unknown physics 'gravity'"},
                 // the image's speckle is no trace's
                 {"--disable speckle", "a trace makes no image"},
                 {"--mode wave", "--mode"},
                 {"--step 0", "field 'step'"},
                 {"--injection spiral", "--injection"},
                 {"--volume /no/such.nii", "/no/such.nii: file not found"},
                 // CLI11's ranges compare, and every comparison with NaN is false
                 {"--lobe-scale nan", "--lobe-scale: value nan is not a finite number"},
                 {"--beam-width nan", "--beam-width: value nan is not a finite number"},
                 {"--beam-angle 100", "--beam-angle"},
                 {"--particles -5", "--particles"},
                 {"--no-such-option 3", "--no-such-option"}};
    for (const auto& c : cases) {
        const auto r =
            run(dir, std::string("trace -q ") + c.args + " --particles 10 --out " + (dir / "out"));
        EXPECT_EQ(r.exit_code, 1) << c.args;
        EXPECT_NE(r.err.find(c.mention), std::string::npos) << c.args << ": " << r.err;
        EXPECT_TRUE(files_in(dir / "out").empty()) << c.args;
    }
}

}  // namespace
// Two outputs of one name are refused before anything is written (the echo CSV used to
// be replaced by the record), and a commit that cannot place an output leaves nothing.
TEST(CliTrace, CollidingOrBlockedOutputsLeaveNothing) {
    ScratchDir dir;
    auto r = run(dir, "trace -q --config fig2 --echoes " + (dir / "out/trace.json") + " --out " +
                          (dir / "out"));
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("two outputs of this run have this name"), std::string::npos) << r.err;
    EXPECT_TRUE(files_in(dir / "out").empty());
    std::filesystem::create_directories(dir / "blocked/trace.json");  // the record's name
    r = run(dir, "trace -q --config fig2 --out " + (dir / "blocked"));
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("blocked/trace.json"), std::string::npos) << r.err;
    EXPECT_TRUE(files_in(dir / "blocked").empty()) << "no picture placed before the failure";
}

}  // namespace sonotrace
