// Frames without the simulator's own artefacts (issue 52): what the image formation paints
// by accident, measured against what the physics and the statistics of speckle predict.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include <opencv2/core.hpp>

#include "imaging/bmode.h"
#include "imaging/scene/scene.h"
#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "probe/array_geometry.h"
#include "probe/transducer.h"

namespace sonotrace {
namespace {

// The scatterer field is a trilinear blend of independent values: its mean square must be
// 1 wherever in its cell a point lies (the blend's weights change it by up to 27/8 when
// scaled by their average alone). 40,000 points at each of four fixed fractions of the
// cell: the mean square's standard error is below 0.01 (v^2 of a blend of uniforms has a
// variance under 2), so 0.05 is five of them.
TEST(ScattererField, HasUnitMeanSquareWhereverInItsCellAPointLies) {
    const imaging::ScattererField field(7, 1.0);
    for (const glm::dvec3 fraction : {glm::dvec3(0.0), glm::dvec3(0.5), glm::dvec3(0.25, 0.0, 0.5),
                                      glm::dvec3(0.9, 0.1, 0.3)}) {
        double sum = 0.0;
        const int n = 40000;
        for (int k = 0; k < n; ++k) {
            const glm::dvec3 cell(k % 200, (k / 200) % 200, k / 40000 + 3);
            const double v = field.at_lattice(cell + fraction);
            sum += v * v;
        }
        EXPECT_NEAR(sum / n, 1.0, 0.05)
            << "fraction " << fraction.x << ", " << fraction.y << ", " << fraction.z;
    }
}

// spread_over_step: a deposit spreads evenly over the `period` samples from it (the last
// fractional), sums are kept, and a comb of an integer period becomes constant.
TEST(SpreadOverStep, SpreadsADepositEvenlyAndFlattensAComb) {
    std::vector<std::array<double, 4>> v(40, {0.0, 0.0, 0.0, 0.0});
    v[5] = {3.0, 6.0, -3.0, 0.0};
    imaging::spread_over_step(v.data(), int(v.size()), 4.5);
    for (int i = 0; i < int(v.size()); ++i) {
        const double expected = i >= 5 && i < 9 ? 3.0 / 4.5 : i == 9 ? 3.0 * 0.5 / 4.5 : 0.0;
        EXPECT_NEAR(v[std::size_t(i)][0], expected, 1e-12) << i;
        EXPECT_NEAR(v[std::size_t(i)][1], 2.0 * expected, 1e-12) << i;
        EXPECT_NEAR(v[std::size_t(i)][2], -expected, 1e-12) << i;
    }
    std::vector<std::array<double, 4>> comb(64, {0.0, 0.0, 0.0, 0.0});
    for (int i = 0; i < 64; i += 8) comb[std::size_t(i)][0] = 1.0;
    imaging::spread_over_step(comb.data(), 64, 8.0);
    for (int i = 0; i < 64; ++i) EXPECT_NEAR(comb[std::size_t(i)][0], 1.0 / 8.0, 1e-12) << i;
    std::vector<std::array<double, 4>> same = comb;
    imaging::spread_over_step(same.data(), 64, 1.0);  // a step within a sample: unchanged
    EXPECT_EQ(same, comb);
}

// A frame of a homogeneous phantom (liver, no shapes) through the whole pipeline: the
// probe's preset, interactive quality (the dataset's), pixels of `pixel_mm`.
imaging::Frame homogeneous_frame(const char* preset, double pixel_mm) {
    const nlohmann::json j = {{"name", "homogeneous"},
                              {"size", {100, 100, 10}},
                              {"smoothing", 0.3},
                              {"background", {{"tissue", "liver"}}},
                              {"shapes", nlohmann::json::array()},
                              {"probe", {{"preset", preset}}}};
    const phantoms::Phantom ph = phantoms::parse_phantom(j, "test");
    imaging::SimulationSettings s;
    s.transducer = probe::find_transducer(preset, "test");
    s.quality = imaging::Quality::interactive;
    s.imaging.pixel_mm = pixel_mm;
    s.imaging.gain_db = imaging::kDefaultGainDb;  // as `sonotrace simulate` images it
    s.imaging.tgc = {{0.0, 0.0},
                     {s.transducer.depth_mm, imaging::automatic_tgc_db(s.transducer.frequency_mhz,
                                                                       s.transducer.depth_mm)}};
    imaging::ScenePlacement scene;
    scene.pose = ph.pose;
    const imaging::PlaneMapper mapper = [&ph](const tissue::VolumeGeometry& grid,
                                              tissue::Volume* labels) {
        return phantoms::rasterise(ph, grid, labels);
    };
    return imaging::simulate_plane(mapper, scene, s, false).frame;
}

// The largest periodogram ordinate of a series (its middle 80 %, less a least-squares
// quadratic, Hann-windowed) over the median of its 16 neighbours, among periods of 2-10
// samples: a periodic artefact stands out of its neighbourhood. Speckle makes the series'
// spectrum smooth but not flat, so each ordinate is compared with its neighbours, not
// with the whole spectrum's median.
struct Peak {
    double ratio = 0.0, period = 0.0;
};
Peak spectral_peak(std::vector<double> m) {
    const int cut = int(m.size()) / 10;
    m = std::vector<double>(m.begin() + cut, m.end() - cut);
    const int n = int(m.size());
    cv::Mat a(n, 3, CV_64F), b(n, 1, CV_64F), x;
    for (int i = 0; i < n; ++i) {
        const double u = 2.0 * i / (n - 1) - 1.0;
        a.at<double>(i, 0) = 1.0, a.at<double>(i, 1) = u, a.at<double>(i, 2) = u * u;
        b.at<double>(i) = m[std::size_t(i)];
    }
    cv::solve(a, b, x, cv::DECOMP_SVD);
    std::vector<double> power(std::size_t(n / 2), 0.0);
    for (int k = 1; k < n / 2; ++k) {
        std::complex<double> sum = 0.0;
        for (int i = 0; i < n; ++i) {
            const double u = 2.0 * i / (n - 1) - 1.0;
            const double d =
                m[std::size_t(i)] - x.at<double>(0) - x.at<double>(1) * u - x.at<double>(2) * u * u;
            const double hann = 0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * (i + 0.5) / n);
            sum += d * hann * std::polar(1.0, -2.0 * std::numbers::pi * k * i / n);
        }
        power[std::size_t(k)] = std::norm(sum);
    }
    Peak peak;
    for (int k = 2; k < n / 2; ++k) {
        if (double(n) / k > 10.0) continue;
        std::vector<double> around;
        for (int q = std::max(2, k - 8); q <= std::min(n / 2 - 1, k + 8); ++q)
            if (q != k) around.push_back(power[std::size_t(q)]);
        std::nth_element(around.begin(), around.begin() + long(around.size() / 2), around.end());
        const double ratio = power[std::size_t(k)] / around[around.size() / 2];
        if (ratio > peak.ratio) peak = {ratio, double(n) / k};
    }
    return peak;
}

// Homogeneous speckle imaged as datasets image it (128 x 128, 256 x 256) and at the
// default pixel shows no stripes: the image's row means and column means have no spectral
// peak above what speckle predicts. Under no artefact each ordinate over its neighbours'
// median is Exp(1) / ln 2, exceeded by x with probability 2^-x; over the ~2,000 ordinates
// tested here, 22 is exceeded by chance with probability 1e-3. The comb of the tracer's
// steps (each step's scatter deposited at its start, 0.5 mm apart at interactive quality)
// made rows at 128 x 128 peak at 158 (period 2.8 pixels); the scatterer field's level,
// which followed the lattice's phase, made columns peak.
TEST(FrameArtefacts, HomogeneousSpeckleShowsNoStripesAtDatasetSizes) {
    for (const char* preset : {"linear", "convex"}) {
        const probe::Transducer t = probe::find_transducer(preset, "test");
        const auto [lo, hi] = probe::ScanGeometry(t).bounds();
        for (const int size : {128, 256, 0}) {
            const double pixel =
                size > 0 ? std::max((hi.x - lo.x) / (size - 1), (hi.y - lo.y) / (size - 1)) *
                               (1.0 + 1e-9)
                         : imaging::ImagingSettings{}.pixel_mm;
            const imaging::Frame f = homogeneous_frame(preset, pixel);
            const cv::Mat& image = f.image.image;
            const cv::Mat& inside = f.image.inside;
            // The means of the scanned pixels of each row (transposed: of each column) that
            // is at least a quarter inside.
            auto means = [](const cv::Mat& values, const cv::Mat& in) {
                std::vector<double> out;
                for (int r = 0; r < values.rows; ++r) {
                    double sum = 0.0;
                    int count = 0;
                    for (int c = 0; c < values.cols; ++c)
                        if (in.at<uint8_t>(r, c)) sum += values.at<float>(r, c), ++count;
                    if (count > values.cols / 4) out.push_back(sum / count);
                }
                return out;
            };
            const std::vector<double> rows = means(image, inside),
                                      columns = means(image.t(), inside.t());
            // The speckle's SNR on the envelope-domain image: display v -> 10^(v DR / 20),
            // each row over its mean (the depth's level), pooled over the middle rows and
            // columns. Reported, not yet held to issue 52's 1.91 +- 0.15: the scan
            // conversion's interpolation between lines (in the log domain) averages
            // partly independent speckle, and the linear probe's frames read 2.08-2.09.
            double sum = 0.0, sum2 = 0.0;
            long count = 0, clipped = 0;
            const double range = imaging::ImagingSettings{}.dynamic_range_db;
            for (int r = image.rows / 5; r < image.rows * 4 / 5; ++r) {
                std::vector<double> e;
                for (int c = image.cols / 5; c < image.cols * 4 / 5; ++c) {
                    if (!inside.at<uint8_t>(r, c)) continue;
                    const float v = image.at<float>(r, c);
                    clipped += v <= 0.0f || v >= 1.0f;
                    e.push_back(std::pow(10.0, v * range / 20.0));
                }
                if (e.size() < 20) continue;
                double mean = 0.0;
                for (double x : e) mean += x;
                mean /= double(e.size());
                for (double x : e) sum += x / mean, sum2 += x * x / (mean * mean), ++count;
            }
            const double mean = sum / count, snr = mean / std::sqrt(sum2 / count - mean * mean);
            std::printf("  SNR %.3f over %ld pixels (%ld clipped)\n", snr, count, clipped);
            const Peak row = spectral_peak(rows), column = spectral_peak(columns);
            std::printf(
                "%s, %d x %d pixels of %.3f mm: rows peak %.1f (period %.1f), columns "
                "%.1f (period %.1f)\n",
                preset, image.cols, image.rows, pixel, row.ratio, row.period, column.ratio,
                column.period);
            EXPECT_LT(row.ratio, 22.0) << preset << " at " << pixel << " mm, period " << row.period;
            EXPECT_LT(column.ratio, 22.0)
                << preset << " at " << pixel << " mm, period " << column.period;
        }
    }
}

}  // namespace
}  // namespace sonotrace
