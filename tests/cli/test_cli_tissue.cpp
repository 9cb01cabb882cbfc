// `sonotrace tissue` end to end, run as a subprocess: outputs, sidecar, determinism on
// 1 and 2 threads, and bad input (message names file/field, non-zero exit, no output).
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "tests/test_util.h"
#include "tissue/image_io.h"
#include "tissue/nifti_io.h"

namespace sonotrace {
namespace {

using test::ScratchDir;

using test::files_in;
using test::run;
using test::RunResult;
using test::slurp;

TEST(CliTissue, DefaultVolumeWritesEveryFieldAndASidecar) {
    ScratchDir dir;
    const RunResult r = run(dir, "tissue --resolution 0.5 --out " + (dir / "out") + " --nifti");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const char* f :
         {"slice", "speed_of_sound", "density", "impedance", "attenuation", "backscatter",
          "scatterer_density", "roughness", "impedance_gradient", "refractive_index_gradient"}) {
        EXPECT_TRUE(std::filesystem::exists(dir / ("out/" + std::string(f) + ".png"))) << f;
        EXPECT_TRUE(std::filesystem::exists(dir / ("out/" + std::string(f) + ".nii.gz"))) << f;
    }
    EXPECT_TRUE(std::filesystem::exists(dir / "out/overview.png"));
    const auto sidecar = nlohmann::json::parse(slurp(dir / "out/tissue.json"));
    EXPECT_EQ(sidecar["transfer_function"]["name"], "mri-t1-head");
    EXPECT_EQ(sidecar["grid"]["geometry"]["dims"][0], 280);  // 140 mm / 0.5 mm
    EXPECT_EQ(sidecar["grid"]["geometry"]["dims"][1], 320);  // 160 mm / 0.5 mm
    EXPECT_TRUE(sidecar["timings_s"].is_object());
    EXPECT_EQ(sidecar["software"]["name"], "sonotrace");
    // The speed map holds skull (> 3000 m/s) and soft tissue (~1500-1570 m/s).
    const tissue::Volume speed = tissue::read_nifti(dir / "out/speed_of_sound.nii.gz").volume;
    const auto [lo, hi] = speed.value_range();
    EXPECT_GT(hi, 3000.0f);
    EXPECT_LT(lo, 400.0f);  // air outside the head
    // The NIfTI carries the slice's world geometry: pixel (0,0) centre per the sidecar.
    const auto& origin = sidecar["grid"]["geometry"]["origin_mm"];
    EXPECT_NEAR(speed.geometry().origin.x, origin[0].get<double>(), 1e-3);
}

TEST(CliTissue, ByteIdenticalOnOneAndTwoThreads) {
    ScratchDir dir;
    ASSERT_EQ(run(dir, "tissue -q --threads 1 --elevation 2 --nifti --resolution 0.5 --out " +
                           (dir / "a"))
                  .exit_code,
              0);
    ASSERT_EQ(run(dir, "tissue -q --threads 2 --elevation 2 --nifti --resolution 0.5 --out " +
                           (dir / "b"))
                  .exit_code,
              0);
    int compared = 0;
    for (const auto& e : std::filesystem::directory_iterator(dir / "a")) {
        const std::string name = e.path().filename().string();
        if (name == "tissue.json") continue;  // holds timings
        EXPECT_EQ(slurp(e.path().string()), slurp(dir / ("b/" + name))) << name;
        ++compared;
    }
    EXPECT_GE(compared, 20);
    auto a = nlohmann::json::parse(slurp(dir / "a/tissue.json")),
         b = nlohmann::json::parse(slurp(dir / "b/tissue.json"));
    a.erase("timings_s"), b.erase("timings_s");
    for (auto* j : {&a, &b}) {
        for (auto& o : (*j)["outputs"]) o.erase("png"), o.erase("nifti");
        j->erase("overview");
    }
    EXPECT_EQ(a, b);
}

TEST(CliTissue, ImageInputWithSpacingAndDefaultPose) {
    ScratchDir dir;
    std::vector<float> pixels(64 * 48);
    for (int j = 0; j < 48; ++j)
        for (int i = 0; i < 64; ++i) pixels[j * 64 + i] = float(j < 24 ? 60 : 200);  // two layers
    tissue::write_gray_image(dir / "layers.png", 64, 48, pixels, 8);
    const RunResult r = run(dir, "tissue -q --volume " + (dir / "layers.png") +
                                     " --spacing 0.5,0.5 --out " + (dir / "out") + " --json -");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto record = nlohmann::json::parse(r.out);
    EXPECT_EQ(record["transfer_function"]["name"], "generic-soft-tissue");
    EXPECT_NEAR(record["grid"]["width_mm"].get<double>(), 32.0, 1e-9);
    EXPECT_NEAR(record["grid"]["depth_mm"].get<double>(), 24.0, 1e-9);
}

TEST(CliTissue, HelpAndVersion) {
    ScratchDir dir;
    RunResult r = run(dir, "--version");
    EXPECT_EQ(r.exit_code, 0);
    EXPECT_NE(r.out.find("sonotrace 0."), std::string::npos);
    r = run(dir, "tissue --help");
    EXPECT_EQ(r.exit_code, 0);
    EXPECT_NE(r.out.find("[mm/pixel]"), std::string::npos) << "units in help";
    r = run(dir, "tissue --list-tissues");
    EXPECT_EQ(r.exit_code, 0);
    EXPECT_NE(r.out.find("cortical_bone"), std::string::npos);
}

struct BadInput {
    std::string name, args, must_mention;
};

void PrintTo(const BadInput& b, std::ostream* os) {
    *os << b.name;
}

class CliTissueBadInput : public ::testing::TestWithParam<BadInput> {};

TEST_P(CliTissueBadInput, FailsWithMessageAndLeavesNoOutput) {
    ScratchDir dir;
    std::ofstream(dir / "corrupt.nii") << std::string(400, 'x');
    std::ofstream(dir / "unknown_key.json")
        << R"({"points": [{"intensity": 0, "tissue": "fat"}, {"intensity": 1, "tissue": "liver", "sped": 1}]})";
    std::ofstream(dir / "decreasing.json")
        << R"({"points": [{"intensity": 1, "tissue": "fat"}, {"intensity": 0, "tissue": "liver"}]})";
    {  // 67 bytes declaring 65535 x 30000 grey pixels (1.8 GiB): a decompression bomb
        const unsigned char bomb[] = {
            0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48,
            0x44, 0x52, 0x00, 0x00, 0xff, 0xff, 0x00, 0x00, 0x75, 0x30, 0x08, 0x00, 0x00, 0x00,
            0x00, 0x5f, 0xb6, 0x9f, 0x51, 0x00, 0x00, 0x00, 0x0a, 0x49, 0x44, 0x41, 0x54, 0x78,
            0x9c, 0x63, 0x48, 0x01, 0x00, 0x00, 0x66, 0x00, 0x65, 0x7a, 0xa0, 0xc6, 0x92, 0x00,
            0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};
        std::ofstream(dir / "bomb.png", std::ios::binary)
            .write(reinterpret_cast<const char*>(bomb), sizeof bomb);
    }
    std::string args = GetParam().args;
    for (std::size_t p; (p = args.find("{dir}")) != std::string::npos;)
        args.replace(p, 5, dir.path().string());
    const RunResult r = run(dir, "tissue " + args + " --out " + (dir / "out"));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find(GetParam().must_mention), std::string::npos) << r.err;
    EXPECT_TRUE(files_in(dir / "out").empty()) << "partial output left behind";
}

INSTANTIATE_TEST_SUITE_P(
    Cases, CliTissueBadInput,
    ::testing::Values(
        BadInput{"missing", "--volume {dir}/nothing.nii.gz", "nothing.nii.gz: file not found"},
        BadInput{"corrupt", "--volume {dir}/corrupt.nii", "corrupt.nii: field 'sizeof_hdr'"},
        BadInput{"tf_unknown_key", "--tf {dir}/unknown_key.json", "field 'points[1].sped'"},
        BadInput{"tf_decreasing", "--tf {dir}/decreasing.json", "field 'points[1].intensity'"},
        BadInput{"tf_unknown_preset", "--tf no-such-preset", "not a preset"},
        BadInput{"pose", "--pose 'at=1,2 beam=1,0,0'", "--pose: field 'at'"},
        BadInput{"resolution", "--resolution 0", "--resolution"},
        BadInput{"nan_width", "--width nan", "--width"},
        BadInput{"one_sample_wide", "--width 1e-308", "field 'width'"},
        BadInput{"png_bomb", "--volume {dir}/bomb.png --spacing 1,1", "bomb.png: field 'size'"},
        BadInput{"spacing", "--volume {dir}/corrupt.png --spacing 1,-1", "--spacing"},
        BadInput{"unknown_option", "--colour red", "colour"}),
    [](const auto& test_case) { return test_case.param.name; });

}  // namespace
}  // namespace sonotrace

#include "ui/cli/tissue_command.h"

namespace sonotrace {
namespace {

TEST(Docs, TheTissueGuideCarriesTheCurrentTissueTables) {
    const std::string readme = slurp(std::string(SONOTRACE_SOURCE_DIR) + "/docs/guide/tissue.md");
    const std::string open = "<!-- tissue-tables", close = "<!-- /tissue-tables -->";
    const auto begin = readme.find('\n', readme.find(open));
    const auto end = readme.find(close);
    ASSERT_NE(begin, std::string::npos);
    ASSERT_NE(end, std::string::npos);
    EXPECT_EQ(readme.substr(begin + 1, end - begin - 1), ui::tissue_tables_markdown())
        << "docs/guide/tissue.md is out of date: paste the output of `sonotrace tissue "
           "--list-tissues`";
}

}  // namespace
}  // namespace sonotrace
