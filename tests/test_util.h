#pragma once
// Helpers shared by the tests: scratch directories, checks on InputError messages, peak
// widths.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include "tissue/base/error.h"
#include "tissue/base/half_maximum.h"

namespace sonotrace::test {

// The index of v's largest value (the first, if several).
inline int argmax(const std::vector<double>& v) {
    return int(std::max_element(v.begin(), v.end()) - v.begin());
}
// The full width at half maximum, in samples, of the peak of v at its maximum: the
// half-maximum crossings either side, linearly interpolated (base::half_maximum).
inline double peak_width_samples(const std::vector<double>& v) {
    return base::half_maximum(int(v.size()), argmax(v), [&](int i) { return v[std::size_t(i)]; })
        .width();
}

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

// The message of the InputError `action` throws ("" if it throws none).
inline std::string input_error_message(const std::function<void()>& action) {
    try {
        action();
    } catch (const base::InputError& e) {
        return e.what();
    }
    return "";
}

// Asserts that `action` throws InputError whose message names `source_part` and
// `field_part` (substrings; empty = not checked).
inline void expect_input_error(const std::function<void()>& action, const std::string& source_part,
                               const std::string& field_part, const std::string& text_part = "") {
    try {
        action();
        ADD_FAILURE() << "expected an InputError naming " << source_part << " / " << field_part;
    } catch (const base::InputError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(source_part), std::string::npos) << "message: " << what;
        EXPECT_NE(e.field().find(field_part), std::string::npos)
            << "field '" << e.field() << "' lacks '" << field_part << "'; message: " << what;
        EXPECT_NE(what.find(text_part), std::string::npos) << "message: " << what;
    }
}

// ---- statistics ----

// Pearson's chi-square statistic of `counts` against expected probabilities (n samples).
inline double chi_square(const std::vector<int>& counts, const std::vector<double>& probabilities,
                         int n) {
    double chi2 = 0.0;
    for (std::size_t b = 0; b < counts.size(); ++b) {
        const double e = probabilities[b] * n;
        chi2 += (counts[b] - e) * (counts[b] - e) / e;
    }
    return chi2;
}

// The chi-square value exceeded with probability 0.001 for `df` degrees of freedom
// (Wilson-Hilferty: within 1 % for df >= 5; z = 3.0902 is the normal 0.999 quantile).
inline double chi_square_critical_001(int df) {
    const double k = 2.0 / (9.0 * df), z = 3.0902;
    const double c = 1.0 - k + z * std::sqrt(k);
    return df * c * c * c;
}

// ---- running the sonotrace binary (SONOTRACE_BINARY, set by tests/CMakeLists.txt) ----

struct RunResult {
    int exit_code;
    std::string out, err;
};

inline std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

inline RunResult run(const ScratchDir& dir, const std::string& args) {
    const std::string cmd = std::string(SONOTRACE_BINARY) + " " + args + " > " +
                            (dir / "stdout.txt") + " 2> " + (dir / "stderr.txt");
    const int status = std::system(cmd.c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(dir / "stdout.txt"),
            slurp(dir / "stderr.txt")};
}

// Files in `dir` (recursively), hidden partial files included.
inline std::vector<std::string> files_in(const std::string& dir) {
    std::vector<std::string> names;
    if (!std::filesystem::exists(dir)) return names;
    for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) {
        if (e.is_regular_file()) names.push_back(e.path().filename().string());
    }
    return names;
}

}  // namespace sonotrace::test
