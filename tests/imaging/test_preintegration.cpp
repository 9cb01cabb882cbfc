// Pre-integration tables and the opacity-CDF depth of fused rendering (eqs. 17-26)
// against numerical integration of the transfer function, and chi-square tests of the
// sampled depths.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "imaging/pbvr/preintegration.h"
#include "tests/test_util.h"

namespace sonotrace::imaging::pbvr {
namespace {

// The head preset: transparent stretches (air, CSF) between opaque ones.
const ColourTransferFunction& head_tf() {
    static const ColourTransferFunction tf = load_colour_tf("head");
    return tf;
}

// integral_0^s sigma by the midpoint rule on 200 000 points.
double numerical_integral(double s) {
    const int n = 200000;
    double sum = 0.0;
    for (int i = 0; i < n; ++i) sum += head_tf().extinction(float((i + 0.5) * s / n));
    return sum * s / n;
}

// Optical depth of a segment whose value runs linearly from a to b over l mm.
double numerical_depth(double a, double b, double l) {
    const int n = 200000;
    double sum = 0.0;
    for (int i = 0; i < n; ++i) {
        const double x = (i + 0.5) / n;
        sum += head_tf().extinction(float(a + (b - a) * x));
    }
    return sum * l / n;
}

TEST(PreIntegration, TableMatchesNumericalIntegration) {
    const PreIntegration pre(head_tf());
    for (double s : {0.05, 0.1, 0.37, 0.5, 0.93, 1.0}) {
        // The table is exact for the piecewise-linear extinction; the midpoint rule errs
        // by ~1e-11 relative at 200 000 points: 1e-6 covers float extinction values.
        EXPECT_NEAR(pre.integral(s), numerical_integral(s), 1e-6 * numerical_integral(1.0))
            << "s = " << s;
    }
}

TEST(PreIntegration, SegmentOpacityMatchesNumericalIntegration) {
    const PreIntegration pre(head_tf());
    struct Segment {
        double front, back, length;
    };
    for (const Segment& g :
         {Segment{0.1, 0.9, 2.0}, Segment{0.9, 0.1, 2.0}, Segment{0.3, 0.5, 0.7},
          Segment{0.12, 0.14, 5.0}, Segment{0.6, 0.6, 1.5}, Segment{0.0, 0.04, 3.0}}) {
        const double expected = 1.0 - std::exp(-numerical_depth(g.front, g.back, g.length));
        EXPECT_NEAR(pre.opacity(g.front, g.back, g.length), expected, 1e-6)
            << g.front << " -> " << g.back << " over " << g.length;
    }
}

TEST(PreIntegration, InverseRoundTrips) {
    const PreIntegration pre(head_tf());
    struct Segment {
        double front, back, length;
    };
    for (const Segment& g : {Segment{0.1, 0.9, 2.0}, Segment{0.9, 0.1, 2.0}, Segment{0.6, 0.6, 1.5},
                             Segment{0.05, 0.5, 4.0}, Segment{0.5, 0.05, 4.0}}) {
        const double total = pre.opacity(g.front, g.back, g.length);
        ASSERT_GT(total, 0.05);
        for (int i = 0; i < 100; ++i) {
            const double r = total * (i + 0.5) / 100.0;
            const double w = pre.inverse(r, g.front, g.back, g.length);
            EXPECT_NEAR(pre.opacity_to(w, g.front, g.back, g.length), r, 1e-9)
                << g.front << " -> " << g.back << ", R = " << r;
        }
    }
}

TEST(PreIntegration, InverseRoundTripsOnRandomSegments) {
    // 20 000 random segments and R: the inverse table's bracket must never miss.
    const PreIntegration pre(head_tf());
    std::mt19937 rng(23);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    int checked = 0;
    for (int n = 0; n < 20000; ++n) {
        const double a = u(rng), b = u(rng), l = 0.1 + 5.0 * u(rng);
        const double total = pre.opacity(a, b, l);
        if (total < 1e-6) continue;
        const double r = total * u(rng);
        const double w = pre.inverse(r, a, b, l);
        ASSERT_NEAR(pre.opacity_to(w, a, b, l), r, 1e-9) << a << " -> " << b << " over " << l;
        ++checked;
    }
    EXPECT_GT(checked, 10000);
}

TEST(PreIntegration, SampledDepthsFollowTheOpacityCdf) {
    // R uniform in [0, alpha): w = alpha^-1(R) has the CDF alpha(w) / alpha (eq. 17).
    // 20 000 samples in 20 equal-width bins of w; chi-square at p = 0.001, both for
    // s_f != s_b (eq. 24, rising and falling) and s_f = s_b (eq. 25).
    const PreIntegration pre(head_tf());
    std::mt19937 rng(17);
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    struct Segment {
        double front, back, length;
    };
    for (const Segment& g :
         {Segment{0.05, 0.95, 3.0}, Segment{0.95, 0.05, 3.0}, Segment{0.6, 0.6, 2.0}}) {
        const double total = pre.opacity(g.front, g.back, g.length);
        const int n = 20000, bins = 20;
        std::vector<int> counts(bins, 0);
        for (int i = 0; i < n; ++i) {
            const double w = pre.inverse(uniform(rng) * total, g.front, g.back, g.length);
            counts[std::size_t(std::min(int(w * bins), bins - 1))]++;
        }
        std::vector<double> p(bins);
        for (int b = 0; b < bins; ++b)
            p[std::size_t(b)] = (pre.opacity_to(double(b + 1) / bins, g.front, g.back, g.length) -
                                 pre.opacity_to(double(b) / bins, g.front, g.back, g.length)) /
                                total;
        // Bins the CDF gives (almost) nothing must get nothing; the rest enter the test.
        std::vector<int> kept_counts;
        std::vector<double> kept_p;
        for (int b = 0; b < bins; ++b) {
            if (p[std::size_t(b)] * n < 5.0) {
                EXPECT_LE(counts[std::size_t(b)], 10) << "bin " << b;
                continue;
            }
            kept_counts.push_back(counts[std::size_t(b)]);
            kept_p.push_back(p[std::size_t(b)]);
        }
        double kept_total = 0.0;
        int kept_n = 0;
        for (std::size_t b = 0; b < kept_p.size(); ++b)
            kept_total += kept_p[b], kept_n += kept_counts[b];
        for (double& v : kept_p) v /= kept_total;
        ASSERT_GE(kept_p.size(), 5u);
        EXPECT_LT(test::chi_square(kept_counts, kept_p, kept_n),
                  test::chi_square_critical_001(int(kept_p.size()) - 1))
            << g.front << " -> " << g.back;
    }
}

}  // namespace
}  // namespace sonotrace::imaging::pbvr
