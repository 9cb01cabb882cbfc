// `sonotrace validate`: records and report of a quick case, the case list, and bad input
// (unknown case, missing or corrupt catalogue) failing with a message and no output.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace sonotrace::test {
namespace {

const std::string kPhantoms = std::string(SONOTRACE_SOURCE_DIR) + "/phantoms";

TEST(CliValidate, JsonRecordsAndReportOfOneCase) {
    ScratchDir dir;
    const auto r = run(dir, "validate -q --case critical_angle --json " + (dir / "v.json") +
                                " --report " + (dir / "report"));
    ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
    EXPECT_NE(r.out.find("PASS critical_angle"), std::string::npos) << r.out;
    const auto records = nlohmann::json::parse(slurp(dir / "v.json"));
    ASSERT_EQ(records.size(), 7u);  // two bracketing incidences, five reflection angles
    for (const auto& rec : records) {
        EXPECT_EQ(rec.at("case"), "critical_angle");
        EXPECT_EQ(rec.at("unit"), "deg");
        EXPECT_TRUE(rec.at("pass").get<bool>());
        EXPECT_LE(std::abs(rec.at("measured").get<double>() - rec.at("expected").get<double>()),
                  rec.at("tolerance").get<double>());
    }
    for (int i : {0, 1})  // asin(1500/1800)
        EXPECT_NEAR(records[std::size_t(i)].at("expected").get<double>(), 56.44, 0.01);
    const std::string html = slurp(dir / "report/index.html");
    EXPECT_NE(html.find("id='critical_angle'"), std::string::npos);
    EXPECT_NE(html.find("<svg"), std::string::npos) << "the case's plot";
}

TEST(CliValidate, ListNamesEveryCase) {
    ScratchDir dir;
    const auto r = run(dir, "validate --list");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const char* name : {"refraction_angle", "reverberation", "mirror_image", "speckle_cysts"})
        EXPECT_NE(r.out.find(name), std::string::npos) << name;
}

TEST(CliValidate, BadInputFailsWithoutOutput) {
    ScratchDir dir;
    auto r = run(dir, "validate --case no_such_case --json " + (dir / "v.json"));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("--case"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("no_such_case"), std::string::npos) << r.err;
    EXPECT_TRUE(files_in(dir / "v.json").empty());

    r = run(dir, "validate --case wire_depth --phantoms " + (dir / "missing"));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("--phantoms"), std::string::npos) << r.err;

    // A corrupt catalogue file: named in the message, no report left behind.
    std::filesystem::create_directories(dir / "cat");
    std::ofstream(dir / "cat/qa_multipurpose.json") << "{\"name\": \"qa\", \"shapes\": [";
    r = run(dir, "validate --case wire_depth --phantoms " + (dir / "cat") + " --report " +
                     (dir / "report"));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("qa_multipurpose.json"), std::string::npos) << r.err;
    EXPECT_TRUE(files_in(dir / "report").empty());
}

}  // namespace
}  // namespace sonotrace::test
