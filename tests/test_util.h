#pragma once
// Helpers shared by the tests: scratch directories and checks on InputError messages.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <functional>
#include <string>

#include "tissue/error.h"

namespace sonotrace::test {

// A fresh directory under the system temp dir, removed with the fixture.
class ScratchDir {
  public:
    ScratchDir() {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        path_ = std::filesystem::temp_directory_path() /
                ("sonotrace-test-" + std::to_string(getpid()) + "-" +
                 (info ? std::string(info->test_suite_name()) + "." + info->name() : "x"));
        std::filesystem::remove_all(path_);
        std::filesystem::create_directories(path_);
    }
    ~ScratchDir() { std::filesystem::remove_all(path_); }
    std::string operator/(const std::string& name) const { return (path_ / name).string(); }
    const std::filesystem::path& path() const { return path_; }

  private:
    std::filesystem::path path_;
};

// Asserts that `action` throws InputError whose message names `source_part` and
// `field_part` (substrings; empty = not checked).
inline void expect_input_error(const std::function<void()>& action, const std::string& source_part,
                               const std::string& field_part, const std::string& text_part = "") {
    try {
        action();
        ADD_FAILURE() << "expected an InputError naming " << source_part << " / " << field_part;
    } catch (const tissue::InputError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(source_part), std::string::npos) << "message: " << what;
        EXPECT_NE(e.field().find(field_part), std::string::npos)
            << "field '" << e.field() << "' lacks '" << field_part << "'; message: " << what;
        EXPECT_NE(what.find(text_part), std::string::npos) << "message: " << what;
    }
}

}  // namespace sonotrace::test
