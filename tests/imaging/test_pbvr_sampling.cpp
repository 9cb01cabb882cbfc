// PBVR's particle sampling against closed forms: particle counts per cell are Poisson with
// the density's integral, and positions follow the density (chi-square), for uniform
// thinning, stratified numbers across repetitions and Metropolis sampling.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <numbers>

#include "imaging/pbvr/pbvr.h"
#include "tests/imaging/pbvr_test_volumes.h"
#include "tests/test_util.h"

namespace sonotrace::imaging::pbvr {
namespace {

using test::chi_square;
using test::chi_square_critical_001;

// Poisson pmf of k for mean mu.
double poisson_pmf(int k, double mu) {
    return std::exp(-mu + k * std::log(mu) - std::lgamma(k + 1.0));
}

TEST(PbvrSampling, CellCountsArePoissonWithTheDensityIntegral) {
    // One cell with corner values 0..1 and a non-linear opacity ramp: eq. 14's integral of
    // rho = sigma(s(x)) / (pi r^2) by a 64^3 midpoint rule, against 6000 generated cells.
    const float corners[8] = {0.0f, 1.0f, 0.3f, 0.8f, 0.5f, 0.1f, 0.9f, 0.6f};
    const auto volume_data = make_volume(
        {2, 2, 2}, 1.0, [&](int i, int j, int k) { return corners[i + 2 * j + 4 * k]; });
    ColourTransferFunction tf = ramp(0.9);
    tf.bind(volume_data);
    const RenderVolume volume(volume_data, tf);
    const float inverse_area = 2.5f;  // 1 / (pi r^2), mm^-2
    double integral = 0.0;
    const int q = 64;
    for (int k = 0; k < q; ++k)
        for (int j = 0; j < q; ++j)
            for (int i = 0; i < q; ++i) {
                const glm::vec3 x((i + 0.5f) / q, (j + 0.5f) / q, (k + 0.5f) / q);
                integral += tf.extinction(volume.sample(x).value) * inverse_area;
            }
    integral /= double(q) * q * q;
    const float majorant = tf.max_extinction(0.0f, 1.0f) * inverse_area;
    auto density = [&](const glm::vec3& x) {
        return std::pair{tf.extinction(volume.sample(x).value) * inverse_area, 0};
    };
    const int trials = 6000, max_bin = 8;
    std::vector<int> counts(max_bin + 1, 0);
    double sum = 0.0;
    for (int t = 0; t < trials; ++t) {
        CellRandom random(7, uint32_t(t), 0);
        int n = 0;
        sample_cell_uniform(glm::vec3(0.0f), glm::vec3(1.0f), majorant, density, random,
                            [&](const glm::vec3&, int) { ++n; });
        counts[std::size_t(std::min(n, max_bin))]++;
        sum += n;
    }
    std::vector<double> p(max_bin + 1);
    double below = 0.0;
    for (int k = 0; k < max_bin; ++k) below += p[std::size_t(k)] = poisson_pmf(k, integral);
    p[max_bin] = 1.0 - below;
    ASSERT_GT(integral, 1.0);
    ASSERT_LT(integral, 4.0);
    // Mean within 4 standard errors (Poisson variance = mean); chi-square at p = 0.001.
    EXPECT_NEAR(sum / trials, integral, 4.0 * std::sqrt(integral / trials));
    EXPECT_LT(chi_square(counts, p, trials), chi_square_critical_001(max_bin));
}

// rho(x, y, z) on the unit cube, its integral over a bin box by the midpoint rule.
double box_integral(const std::function<double(glm::dvec3)>& rho, glm::dvec3 lo, glm::dvec3 hi) {
    const int q = 12;
    double sum = 0.0;
    for (int k = 0; k < q; ++k)
        for (int j = 0; j < q; ++j)
            for (int i = 0; i < q; ++i)
                sum += rho(lo + (hi - lo) * (glm::dvec3(i, j, k) + 0.5) / double(q));
    return sum * (hi.x - lo.x) * (hi.y - lo.y) * (hi.z - lo.z) / (double(q) * q * q);
}

// Positions histogrammed on bins^3 boxes against the normalized density.
void expect_positions_follow(const std::vector<glm::vec3>& samples,
                             const std::function<double(glm::dvec3)>& rho, int bins) {
    std::vector<int> counts(std::size_t(bins * bins * bins), 0);
    for (const glm::vec3& x : samples) {
        const glm::ivec3 b = glm::min(glm::ivec3(x * float(bins)), bins - 1);
        counts[std::size_t((b.z * bins + b.y) * bins + b.x)]++;
    }
    std::vector<double> p(counts.size());
    double total = 0.0;
    for (int k = 0; k < bins; ++k)
        for (int j = 0; j < bins; ++j)
            for (int i = 0; i < bins; ++i) {
                const glm::dvec3 lo = glm::dvec3(i, j, k) / double(bins);
                total += p[std::size_t((k * bins + j) * bins + i)] =
                    box_integral(rho, lo, lo + 1.0 / bins);
            }
    for (double& v : p) v /= total;
    EXPECT_LT(chi_square(counts, p, int(samples.size())),
              chi_square_critical_001(int(counts.size()) - 1));
}

double rho_3d(glm::dvec3 x) {
    return (1.0 + 0.5 * x.x) * (1.0 + 0.5 * x.y * x.y) * (1.25 - 0.5 * x.z);
}

TEST(PbvrSampling, UniformThinningPositionsFollowTheDensity) {
    // Independent particles of 20000 cells, 4x4x4 bins.
    auto density = [](const glm::vec3& x) { return std::pair{float(rho_3d(x)), 0}; };
    std::vector<glm::vec3> samples;
    for (uint32_t c = 0; samples.size() < 40000; ++c) {
        CellRandom random(3, 0, c);
        sample_cell_uniform(glm::vec3(0.0f), glm::vec3(1.0f), 1.5f * 1.5f * 1.25f, density, random,
                            [&](const glm::vec3& x, int) { samples.push_back(x); });
    }
    expect_positions_follow(samples, rho_3d, 4);
}

TEST(PbvrSampling, StratifiedNumbersAreIndependentUniformsWithinARepetition) {
    // Within one repetition, over 20000 cells: the count's uniform and candidate 0's four
    // numbers on 16 bins each, candidate 0's position on 4x4x4 boxes, and candidates 0
    // and 1 jointly on 8x8 bins (independence of draws); chi-square at p = 0.001 each.
    const int cells = 20000;
    for (const uint32_t repetition : {0u, 1u, 7u, 100u}) {
        std::vector<std::vector<int>> marginal(5, std::vector<int>(16, 0));
        std::vector<int> box(64, 0), joint(64, 0);
        for (uint32_t c = 0; c < uint32_t(cells); ++c) {
            const CellSequence sequence(11, repetition, c);
            const glm::vec4 a = sequence.candidate(0), b = sequence.candidate(1);
            const float numbers[5] = {sequence.count_uniform(), a.x, a.y, a.z, a.w};
            for (int d = 0; d < 5; ++d) marginal[std::size_t(d)][std::size_t(numbers[d] * 16)]++;
            const glm::ivec3 q(glm::vec3(a) * 4.0f);
            box[std::size_t((q.z * 4 + q.y) * 4 + q.x)]++;
            joint[std::size_t(int(a.x * 8) * 8 + int(b.x * 8))]++;
        }
        for (int d = 0; d < 5; ++d)
            EXPECT_LT(
                chi_square(marginal[std::size_t(d)], std::vector<double>(16, 1.0 / 16), cells),
                chi_square_critical_001(15))
                << "repetition " << repetition << ", number " << d;
        EXPECT_LT(chi_square(box, std::vector<double>(64, 1.0 / 64), cells),
                  chi_square_critical_001(63))
            << "repetition " << repetition;
        EXPECT_LT(chi_square(joint, std::vector<double>(64, 1.0 / 64), cells),
                  chi_square_critical_001(63))
            << "repetition " << repetition;
    }
}

TEST(PbvrSampling, StratifiedNumbersAreStratifiedAcrossRepetitions) {
    // Over the first 64 repetitions each of a cell's numbers falls once into each 1/64 of
    // [0, 1) (independent uniforms would do so with probability 64!/64^64 ~ 1e-27); the
    // candidates' first three numbers share a point per repetition, a net in 3D: every
    // box of 1/4 x 1/4 x 1/4 holds one of the 64 positions, up to the t = 1 of Sobol's
    // first three dimensions (at most two per box).
    for (uint32_t c = 0; c < 50; ++c) {
        std::vector<std::vector<int>> strata(5, std::vector<int>(64, 0));
        std::vector<int> box(64, 0);
        for (uint32_t r = 0; r < 64; ++r) {
            const CellSequence sequence(5, r, c);
            const glm::vec4 a = sequence.candidate(3);
            const float numbers[5] = {sequence.count_uniform(), a.x, a.y, a.z, a.w};
            for (int d = 0; d < 5; ++d) strata[std::size_t(d)][std::size_t(numbers[d] * 64)]++;
            const glm::ivec3 q(glm::vec3(a) * 4.0f);
            box[std::size_t((q.z * 4 + q.y) * 4 + q.x)]++;
        }
        for (int d = 0; d < 5; ++d)
            EXPECT_EQ(
                *std::max_element(strata[std::size_t(d)].begin(), strata[std::size_t(d)].end()), 1)
                << "cell " << c << ", number " << d;
        EXPECT_LE(*std::max_element(box.begin(), box.end()), 2) << "cell " << c;
    }
    // So a cell's total count over 64 repetitions hardly varies: Poisson(0.7) counts, 1000
    // cells; independent counts would give the variance 64 * 0.7 = 44.8.
    double sum = 0.0, squares = 0.0;
    for (uint32_t c = 0; c < 1000; ++c) {
        int total = 0;
        for (uint32_t r = 0; r < 64; ++r)
            total += poisson_count_inversion(0.7, std::exp(-0.7),
                                             double(CellSequence(9, r, c).count_uniform()));
        sum += total, squares += double(total) * total;
    }
    const double mean = sum / 1000.0, variance = squares / 1000.0 - mean * mean;
    EXPECT_NEAR(mean, 64 * 0.7, 0.5);
    EXPECT_LT(variance, 0.1 * 64 * 0.7);
}

TEST(PbvrSampling, StratifiedThinningPositionsFollowTheDensity) {
    // thin_stratified in one repetition over many cells, as in the uniform thinning test.
    auto density = [](const glm::vec3& x) { return std::pair{float(rho_3d(x)), 0}; };
    const float majorant = 1.5f * 1.5f * 1.25f;
    std::vector<glm::vec3> samples;
    for (uint32_t c = 0; samples.size() < 40000; ++c) {
        const CellSequence sequence(3, 5, c);
        thin_stratified(glm::vec3(0.0f), glm::vec3(1.0f), majorant, double(majorant),
                        std::exp(-double(majorant)), density, sequence,
                        [&](const glm::vec3& x, int) { samples.push_back(x); });
    }
    expect_positions_follow(samples, rho_3d, 4);
}

TEST(PbvrSampling, MetropolisSamplesFollowTheDensity1DAnd3D) {
    // One sample per chain (the first after 24 burn-in proposals), so samples are
    // independent: the chi-square's assumptions hold. The independence sampler with
    // uniform proposals converges at rate 1 - min rho / mean rho (0.49 here): after 24
    // steps the distance to the target is below 1e-7.
    auto run = [](const std::function<double(glm::dvec3)>& rho) {
        auto density = [&](const glm::vec3& x) { return std::pair{float(rho(glm::dvec3(x))), 0}; };
        std::vector<glm::vec3> samples;
        for (uint32_t c = 0; samples.size() < 30000; ++c) {
            CellRandom random(11, 1, c);
            bool first = true;
            sample_cell_metropolis(
                glm::vec3(0.0f), glm::vec3(1.0f), density, random,
                [&](const glm::vec3& x, int) {
                    if (first) samples.push_back(x);
                    first = false;
                },
                24);
        }
        return samples;
    };
    auto rho_1d = [](glm::dvec3 x) { return 1.0 + x.x; };
    expect_positions_follow(run(rho_1d), rho_1d, 4);
    expect_positions_follow(run(rho_3d), rho_3d, 4);
}

}  // namespace
}  // namespace sonotrace::imaging::pbvr
