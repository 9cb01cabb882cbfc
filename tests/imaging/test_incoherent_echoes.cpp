// imaging::incoherent_intensity and add_incoherent_speckle against what an adaptive kernel
// density estimate and circular Gaussian speckle must give: each echo's intensity kept,
// Gaussian kernels whose width follows the k-th nearest echo of another path, a uniform
// sample's density recovered, and speckle of the mean's variance, correlated across lines
// as Gaussian weights of the beam's width correlate.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "imaging/incoherent_echoes.h"
#include "probe/transducer.h"
#include "tissue/base/fast_math.h"

namespace sonotrace::imaging {
namespace {

struct Scene {
    explicit Scene(const std::string& preset = "linear")
        : t(probe::find_transducer(preset, "test")) {}
    probe::Transducer t;
    probe::ScanGeometry geometry{t};
    LineData layout = rf_layout(t, ImagingSettings{});
    // Lines are parallel (linear array): a line's lateral position and a sample's depth.
    double x(int l) const { return geometry.line(l).origin.x; }
    double mm_per_sample() const { return layout.depth_mm(1) - layout.depth_mm(0); }
    double at(const std::vector<float>& mean, int l, int i) const {
        return mean[std::size_t(l) * std::size_t(layout.samples) + std::size_t(i)];
    }
};

// Intensity-weighted rms spread of `mean` about (x0, z0), across lines and along them.
std::pair<double, double> spread_about(const Scene& s, const std::vector<float>& mean, double x0,
                                       double z0) {
    double sum = 0.0, xx = 0.0, zz = 0.0;
    for (int l = 0; l < s.layout.lines; ++l)
        for (int i = 0; i < s.layout.samples; ++i) {
            const double m = s.at(mean, l, i), dx = s.x(l) - x0, dz = s.layout.depth_mm(i) - z0;
            sum += m, xx += m * dx * dx, zz += m * dz * dz;
        }
    return {std::sqrt(xx / sum), std::sqrt(zz / sum)};
}

double total(const std::vector<float>& mean) {
    return std::accumulate(mean.begin(), mean.end(), 0.0);
}

// An echo's kernel is normalised over the lines and samples it reaches: the image holds
// exactly the intensities it was given (to float rounding), wherever they lie.
TEST(IncoherentEchoes, EachEchoKeepsItsIntensity) {
    const Scene s;
    const int mid = s.layout.lines / 2;
    const std::vector<IncoherentEcho> echoes = {
        {mid, 20.0, 1.0, 0}, {mid + 3, 21.0, 0.5, 1}, {2, 35.0, 2.0, 2}, {0, 0.3, 0.25, 3}};
    const std::vector<float> mean = incoherent_intensity(s.geometry, s.layout, echoes);
    EXPECT_NEAR(total(mean), 3.75, 3.75 * 1e-5);
}

// The kernel is a Gaussian of sigma = half the distance to the k-th nearest echo of
// another path, within [min, max]: a lone echo spreads over the widest, an echo amid many
// close paths over the narrowest, and one path's own cluster of echoes counts as lone.
// The intensity-weighted rms of a Gaussian sampled at the lines (spacing d) and in bins
// of b is sqrt(sigma^2 + d^2 / 12) across and sqrt(sigma^2 + b^2 / 12) along (the grid's
// uniform rounding), within a few per cent for sigma >= 2 d.
TEST(IncoherentEchoes, KernelsFollowTheDensityOfOtherPaths) {
    const Scene s;
    const IncoherentSpread spread;
    const int mid = s.layout.lines / 2;
    const double d = std::abs(s.x(mid + 1) - s.x(mid)), b = spread.bin_mm;
    auto expected = [&](double sigma, double step) {
        return std::sqrt(sigma * sigma + step * step / 12.0);
    };
    {  // lone
        const auto mean = incoherent_intensity(s.geometry, s.layout, {{mid, 25.0, 1.0, 0}});
        const auto [across, along] = spread_about(s, mean, s.x(mid), 25.0);
        EXPECT_NEAR(across, expected(spread.max_sigma_mm, d), 0.05 * spread.max_sigma_mm);
        EXPECT_NEAR(along, expected(spread.max_sigma_mm, b), 0.05 * spread.max_sigma_mm);
    }
    {  // one path's 40 echoes within 0.2 mm: still lone
        std::vector<IncoherentEcho> one_path;
        for (int n = 0; n < 40; ++n) one_path.push_back({mid, 25.0 + 0.005 * n, 1.0 / 40, 7});
        const auto mean = incoherent_intensity(s.geometry, s.layout, one_path);
        const auto [across, along] = spread_about(s, mean, s.x(mid), 25.1);
        EXPECT_NEAR(across, expected(spread.max_sigma_mm, d), 0.05 * spread.max_sigma_mm);
    }
    {  // 40 paths within 0.2 mm: the narrowest kernel
        std::vector<IncoherentEcho> paths;
        for (uint32_t n = 0; n < 40; ++n) paths.push_back({mid, 25.0 + 0.005 * n, 1.0 / 40, n});
        const auto mean = incoherent_intensity(s.geometry, s.layout, paths);
        const auto [across, along] = spread_about(s, mean, s.x(mid), 25.1);
        EXPECT_NEAR(across, expected(spread.min_sigma_mm, d), 0.07 * spread.min_sigma_mm);
        EXPECT_NEAR(along, expected(spread.min_sigma_mm, b), 0.07 * spread.min_sigma_mm);
    }
}

// Echoes of total intensity A drawn uniformly over a W x H rectangle (fixed seed, 4000
// paths): inside it, 2.5 mm (one widest kernel) clear of its edges, the estimate's mean
// intensity per mm^2 is A / (W H). The box holds about 1,100 echoes, so its count varies
// by 3 %; 10 % is beyond 3 standard errors.
TEST(IncoherentEchoes, AUniformSampleGivesItsDensity) {
    const Scene s;
    const int first = s.layout.lines / 4, last = 3 * s.layout.lines / 4;  // lines, inclusive
    const double x0 = s.x(first), x1 = s.x(last), z0 = 15.0, z1 = 35.0;
    std::mt19937_64 random(20261129);
    std::uniform_real_distribution<double> depth(z0, z1);
    std::uniform_int_distribution<int> line(first, last);
    constexpr int kPaths = 4000;
    std::vector<IncoherentEcho> echoes;
    for (int n = 0; n < kPaths; ++n)
        echoes.push_back({line(random), depth(random), 1.0 / kPaths, uint32_t(n)});
    const auto mean = incoherent_intensity(s.geometry, s.layout, echoes);
    // The lines stand for strips of their spacing: the rectangle is one spacing wider.
    const double d = std::abs(s.x(first + 1) - s.x(first));
    const double area = (std::abs(x1 - x0) + d) * (z1 - z0);
    const double margin = IncoherentSpread{}.max_sigma_mm;
    double inside = 0.0;
    int lines_inside = 0, samples_inside = 0;
    for (int l = first; l <= last; ++l) {
        if (std::abs(s.x(l) - x0) < margin || std::abs(s.x(l) - x1) < margin) continue;
        ++lines_inside;
        samples_inside = 0;
        for (int i = 0; i < s.layout.samples; ++i) {
            const double z = s.layout.depth_mm(i);
            if (z < z0 + margin || z > z1 - margin) continue;
            inside += s.at(mean, l, i);
            ++samples_inside;
        }
    }
    ASSERT_GT(lines_inside, 10);
    const double per_mm2 =
        inside / (double(lines_inside) * d * double(samples_inside) * s.mm_per_sample());
    EXPECT_NEAR(per_mm2 * area, 1.0, 0.10);
}

TEST(IncoherentEchoes, TheSameOnOneAndTwoThreads) {
    const Scene s;
    std::mt19937_64 random(7);
    std::uniform_real_distribution<double> depth(5.0, 45.0);
    std::uniform_int_distribution<int> line(0, s.layout.lines - 1);
    std::vector<IncoherentEcho> echoes;
    for (uint32_t n = 0; n < 500; ++n) echoes.push_back({line(random), depth(random), 1e-3, n});
    std::vector<float> one, two;
    {
        tbb::global_control threads(tbb::global_control::max_allowed_parallelism, 1);
        one = incoherent_intensity(s.geometry, s.layout, echoes);
    }
    {
        tbb::global_control threads(tbb::global_control::max_allowed_parallelism, 2);
        two = incoherent_intensity(s.geometry, s.layout, echoes);
    }
    EXPECT_EQ(one, two);
}

// Speckle of a uniform mean M: in-phase and quadrature each of variance M / 2 (over
// ~400k samples, correlated over a few lines: standard error below 1 %; 3 % allowed), and
// neighbouring lines correlated as two Gaussian-weighted sums of the same white numbers
// one line apart: exp(-1 / (4 sigma^2)), sigma the receive beam's in lines (lambda x the
// receive F-number FWHM), to 0.03 (about 4 standard errors of the 40 rows' mean). The
// phased preset, whose lines part as its beam widens: about one line of sigma at 60 mm.
TEST(IncoherentEchoes, SpeckleHasTheMeansVarianceAndTheBeamsCorrelation) {
    const Scene s("phased");
    const int L = s.layout.lines, N = s.layout.samples;
    constexpr float kMean = 2.0f;
    const std::vector<float> mean(std::size_t(L) * std::size_t(N), kMean);
    std::vector<float> in_phase(mean.size(), 0.0f), quadrature(mean.size(), 0.0f);
    add_incoherent_speckle(mean, s.layout, s.t, s.geometry, 11, in_phase.data(), quadrature.data());
    double ii = 0.0, qq = 0.0;
    for (std::size_t k = 0; k < mean.size(); ++k)
        ii += double(in_phase[k]) * in_phase[k], qq += double(quadrature[k]) * quadrature[k];
    EXPECT_NEAR(ii / double(mean.size()), kMean / 2.0, 0.03 * kMean / 2.0);
    EXPECT_NEAR(qq / double(mean.size()), kMean / 2.0, 0.03 * kMean / 2.0);
    // Rows at 60 mm: the correlation of line l with l + 1 (lines away from the ends).
    const int i0 = int(60.0 / s.mm_per_sample());
    double product = 0.0, power = 0.0;
    for (int i = i0; i < i0 + 40; ++i)
        for (int l = 10; l < L - 11; ++l) {
            const std::size_t a = std::size_t(l) * std::size_t(N) + std::size_t(i);
            const std::size_t b = a + std::size_t(N);
            product += double(in_phase[a]) * in_phase[b] + double(quadrature[a]) * quadrature[b];
            power += double(in_phase[a]) * in_phase[a] + double(quadrature[a]) * quadrature[a];
        }
    const double range = s.layout.depth_mm(i0);
    const double sigma = s.t.wavelength_mm() * range / s.t.receive_aperture_mm(range) /
                         base::kFwhmPerSigma / s.geometry.line_spacing_mm(range);
    ASSERT_GT(sigma, 0.5);  // the case this measures: correlated neighbours
    EXPECT_NEAR(product / power, std::exp(-1.0 / (4.0 * sigma * sigma)), 0.03);
}

}  // namespace
}  // namespace sonotrace::imaging
