// Philox4x32-10: Random123's known-answer vectors, and uniformity by chi-square.
#include <gtest/gtest.h>

#include <vector>

#include "simulator/rng.h"

namespace sonotrace::simulator {
namespace {

TEST(Philox, Random123KnownAnswers) {
    using B = Philox4x32::Block;
    EXPECT_EQ(Philox4x32::generate({0, 0, 0, 0}, 0, 0),
              (B{0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8}));
    EXPECT_EQ(Philox4x32::generate({0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff}, 0xffffffff,
                                   0xffffffff),
              (B{0x408f276d, 0x41c83b0e, 0xa20bc7c6, 0x6d5451fd}));
    EXPECT_EQ(Philox4x32::generate({0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344}, 0xa4093822,
                                   0x299f31d0),
              (B{0xd16cfe09, 0x94fdcceb, 0x5001e420, 0x24126ea1}));
}

// Chi-square statistic of counts against equal expectation.
double chi_square_uniform(const std::vector<int>& counts, double total) {
    const double expected = total / double(counts.size());
    double chi2 = 0.0;
    for (int c : counts) chi2 += (c - expected) * (c - expected) / expected;
    return chi2;
}

TEST(Philox, ParticleStreamsAreUniform) {
    // 400k uniforms from 1000 particles of 10 lines in 100 bins. Critical value of
    // chi-square with 99 degrees of freedom at p = 0.001: 148.2 (fixed seed: the test
    // is deterministic; a correct generator fails it with probability 0.1 %).
    std::vector<int> counts(100, 0);
    int total = 0;
    for (uint32_t line = 0; line < 10; ++line) {
        for (uint32_t p = 0; p < 100; ++p) {
            ParticleRng rng(12345, line, p);
            for (int e = 0; e < 100; ++e) {
                for (float u : rng.draw4()) {
                    ASSERT_GE(u, 0.0f);
                    ASSERT_LT(u, 1.0f);
                    counts[std::size_t(u * 100)]++;
                    ++total;
                }
            }
        }
    }
    EXPECT_LT(chi_square_uniform(counts, total), 148.2);
}

TEST(Philox, NeighbouringKeysAreUncorrelated) {
    // Pairs (u from particle p, u from particle p+1, same event): joint 10x10 histogram
    // must be uniform (chi-square, 99 dof, p = 0.001 -> 148.2).
    std::vector<int> counts(100, 0);
    int total = 0;
    for (uint32_t p = 0; p < 20000; ++p) {
        ParticleRng a(7, 3, p), b(7, 3, p + 1);
        const float u = a.uniform(), v = b.uniform();
        counts[std::size_t(u * 10) * 10 + std::size_t(v * 10)]++;
        ++total;
    }
    EXPECT_LT(chi_square_uniform(counts, total), 148.2);
}

}  // namespace
}  // namespace sonotrace::simulator
