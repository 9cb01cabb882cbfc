// The one JSON reader every input goes through: syntax errors with line and column,
// duplicate keys, and the limits that keep hostile files from crashing or stalling a run
// (size, nesting depth, numbers no double holds, files that are not regular files).
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "tests/test_util.h"
#include "tissue/base/error.h"
#include "tissue/base/json_util.h"

namespace sonotrace {
namespace {

using base::jsonio::kMaxJsonDepth;

std::string nested(int levels) {
    return std::string(std::size_t(levels), '[') + std::string(std::size_t(levels), ']');
}

TEST(JsonInput, NestingUpToTheLimitParsesOneMoreIsRefused) {
    EXPECT_NO_THROW(base::jsonio::parse(nested(kMaxJsonDepth), "a.json"));
    // Objects and arrays count alike: kMaxJsonDepth - 1 arrays inside one object.
    EXPECT_NO_THROW(base::jsonio::parse("{\"k\": " + nested(kMaxJsonDepth - 1) + "}", "b.json"));
    for (const std::string& text :
         {nested(kMaxJsonDepth + 1), "{\"k\": " + nested(kMaxJsonDepth) + "}", nested(100000)}) {
        const std::string m =
            test::input_error_message([&] { base::jsonio::parse(text, "deep.json"); });
        EXPECT_NE(m.find("deep.json"), std::string::npos) << m;
        EXPECT_NE(m.find("levels deep"), std::string::npos) << m;
        EXPECT_LT(m.size(), 200u) << m;
    }
}

TEST(JsonInput, NumbersBeyondDoubleAndSyntaxErrorsNameTheFile) {
    std::string m =
        test::input_error_message([] { base::jsonio::parse("{\"a\": -1e400}", "n.json"); });
    EXPECT_NE(m.find("n.json"), std::string::npos) << m;
    EXPECT_NE(m.find("number overflow"), std::string::npos) << m;
    // 1e-400 underflows to zero, which is a number: not an error.
    EXPECT_EQ(base::jsonio::parse("{\"a\": 1e-400}", "u.json")["a"].get<double>(), 0.0);
    m = test::input_error_message([] { base::jsonio::parse("{\n  \"a\": 1,\n  b}", "s.json"); });
    EXPECT_NE(m.find("s.json: invalid JSON at line 3"), std::string::npos) << m;
    m = test::input_error_message([] { base::jsonio::parse(R"({"a": 1, "a": 2})", "d.json"); });
    EXPECT_NE(m.find("field 'a'"), std::string::npos) << m;
}

TEST(JsonInput, OnlyRegularFilesWithinTheSizeLimitAreRead) {
    test::ScratchDir dir;
    std::string m = test::input_error_message([] { base::jsonio::read_file("/dev/zero"); });
    EXPECT_NE(m.find("/dev/zero: is not a regular file"), std::string::npos) << m;
    m = test::input_error_message([&] { base::jsonio::read_file(dir / "missing.json"); });
    EXPECT_NE(m.find("file not found"), std::string::npos) << m;
    m = test::input_error_message([&] { base::jsonio::read_file(dir.path().string()); });
    EXPECT_NE(m.find("is not a regular file"), std::string::npos) << m;
    // A FIFO with no writer: opening it to read would wait for ever.
    ASSERT_EQ(::mkfifo((dir / "fifo.json").c_str(), 0600), 0);
    m = test::input_error_message([&] { base::jsonio::read_file(dir / "fifo.json"); });
    EXPECT_NE(m.find("fifo.json: is not a regular file"), std::string::npos) << m;
    // One byte over the limit (a sparse file: nothing is written, nothing is read).
    const std::filesystem::path big = dir / "big.json";
    std::ofstream(big) << "{}";
    std::filesystem::resize_file(big, base::jsonio::kMaxJsonBytes + 1);
    m = test::input_error_message([&] { base::jsonio::read_file(big.string()); });
    EXPECT_NE(m.find("limited to"), std::string::npos) << m;
    // At the limit the file is read: "{}" after white space up to exactly the limit.
    std::ofstream(big) << std::string(base::jsonio::kMaxJsonBytes - 2, ' ') << "{}";
    ASSERT_EQ(std::filesystem::file_size(big), base::jsonio::kMaxJsonBytes);
    EXPECT_TRUE(base::jsonio::read_file(big.string()).empty());
    std::ofstream(dir / "ok.json") << R"({"a": [1, 2]})";
    EXPECT_EQ(base::jsonio::read_file(dir / "ok.json")["a"][1].get<int>(), 2);
}

}  // namespace
}  // namespace sonotrace
