// Every case of the validation suite (phantoms/validation, `sonotrace validate`) as a
// test: each measured quantity must lie within its stated tolerance of the value physics
// or geometry predicts. The cases hold the expectations and justify the tolerances.
#include <gtest/gtest.h>

#include <algorithm>

#include "phantoms/validation/validation.h"

namespace sonotrace {
namespace {

class ValidationCase : public testing::TestWithParam<std::string> {};

TEST_P(ValidationCase, EveryQuantityWithinItsTolerance) {
    const auto& all = validation::cases();
    const auto found = std::find_if(all.begin(), all.end(),
                                    [](const validation::Case& c) { return c.name == GetParam(); });
    ASSERT_NE(found, all.end()) << "no case " << GetParam();
    validation::CaseContext ctx;
    ctx.phantom_dir = SONOTRACE_SOURCE_DIR "/phantoms";
    ctx.pictures = false;
    const validation::CaseResult r = found->run(ctx);
    ASSERT_FALSE(r.measurements.empty());
    for (const auto& m : r.measurements) {
        EXPECT_TRUE(m.pass()) << m.quantity << ": measured " << m.measured << " " << m.unit
                              << ", expected " << m.expected << " +- " << m.tolerance;
    }
}

// Every registered case, by name (ctest shows one test per case).
std::vector<std::string> case_names() {
    std::vector<std::string> names;
    for (const auto& c : validation::cases()) names.push_back(c.name);
    return names;
}

INSTANTIATE_TEST_SUITE_P(Suite, ValidationCase, testing::ValuesIn(case_names()),
                         [](const testing::TestParamInfo<std::string>& p) { return p.param; });

}  // namespace
}  // namespace sonotrace
