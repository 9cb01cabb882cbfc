// Receiver noise (imaging/electronic_noise.h): its power is the frame's mean RF power over
// 10^(SNR/10), it lies in the pulse's band, it is Gaussian, and it is the same on any
// thread count. The references are the definitions: the power by the sample variance of
// what was added, the band by a periodogram against white noise's flat share.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <numbers>

#include <opencv2/core.hpp>

#include "imaging/electronic_noise.h"
#include "probe/transducer.h"

namespace sonotrace::imaging {
namespace {

// RF lines holding a slowly varying echo-like signal of mean power P = 0.5 a^2.
LineData signal_lines(const probe::Transducer& t, int lines, int samples, double a) {
    LineData rf;
    rf.lines = lines, rf.samples = samples, rf.fs_hz = 4.0 * t.frequency_mhz * 1e6;
    rf.values.resize(std::size_t(lines) * std::size_t(samples));
    for (int l = 0; l < lines; ++l)
        for (int i = 0; i < samples; ++i)
            rf.at(l, i) = float(a * std::cos(2.0 * std::numbers::pi * 0.25 * i + 0.1 * l));
    return rf;
}

double mean_power(const std::vector<float>& v) {
    double s = 0.0;
    for (float x : v) s += double(x) * x;
    return s / double(v.size());
}

TEST(ElectronicNoise, HasTheStatedPowerAGaussianLawAndThePulsesBand) {
    const probe::Transducer t = probe::find_transducer("linear", "test");
    const int lines = 64, samples = 4096;
    const LineData clean = signal_lines(t, lines, samples, 2.0);
    const double signal_power = mean_power(clean.values);
    for (const double snr_db : {0.0, 10.0, 25.0}) {
        LineData noisy = clean;
        const double variance = add_electronic_noise(noisy, t, snr_db, 7);
        // The variance it reports is the definition's, exactly.
        EXPECT_NEAR(variance, signal_power / std::pow(10.0, snr_db / 10.0), 1e-9 * variance);
        std::vector<float> noise(noisy.values.size());
        for (std::size_t k = 0; k < noise.size(); ++k) noise[k] = noisy.values[k] - clean.values[k];
        // 262,144 samples correlated over the pulse (~10 samples): some 25,000 independent,
        // so the sample variance is within 1 % (1 sigma) of the true one; 5 % is 5 sigma.
        const double measured = mean_power(noise);
        EXPECT_NEAR(measured / variance, 1.0, 0.05) << snr_db;
        // Kurtosis of a Gaussian: 3; its estimate's sigma sqrt(24 / 25,000) = 0.03.
        double m4 = 0.0;
        for (float x : noise) m4 += std::pow(double(x), 4);
        m4 /= double(noise.size());
        EXPECT_NEAR(m4 / (measured * measured), 3.0, 0.15) << snr_db;
        if (snr_db != 10.0) continue;
        // The band: the mean periodogram's share within [0.5, 1.5] f0 (fs = 4 f0, so
        // [0, 2 f0] is the whole spectrum): white noise would put 50 % there; noise in the
        // pulse's band (B6 of the preset about f0) nearly all, and peaks near f0.
        std::vector<double> spectrum(std::size_t(samples / 2 + 1), 0.0);
        for (int l = 0; l < lines; ++l) {
            cv::Mat row(1, samples, CV_64F), out;
            for (int i = 0; i < samples; ++i)
                row.at<double>(i) = noise[std::size_t(l * samples + i)];
            cv::dft(row, out, cv::DFT_COMPLEX_OUTPUT);
            for (std::size_t k = 0; k < spectrum.size(); ++k) {
                const cv::Vec2d c = out.at<cv::Vec2d>(int(k));
                spectrum[k] += c[0] * c[0] + c[1] * c[1];
            }
        }
        double total = 0.0, in_band = 0.0;
        std::size_t peak = 0;
        for (std::size_t k = 0; k < spectrum.size(); ++k) {
            const double f = double(k) / samples * 4.0;  // in units of f0
            total += spectrum[k];
            if (f >= 0.5 && f <= 1.5) in_band += spectrum[k];
            if (spectrum[k] > spectrum[peak]) peak = k;
        }
        EXPECT_GT(in_band / total, 0.9);
        EXPECT_NEAR(double(peak) / samples * 4.0, 1.0, 0.15);
    }
}

TEST(ElectronicNoise, IsTheSameOnOneAndTwoThreadsDiffersBySeedAndSparesASilentFrame) {
    const probe::Transducer t = probe::find_transducer("convex", "test");
    const LineData clean = signal_lines(t, 16, 1000, 1.0);
    auto noisy = [&](int threads, uint64_t seed) {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        LineData rf = clean;
        add_electronic_noise(rf, t, 20.0, seed);
        return rf.values;
    };
    EXPECT_EQ(noisy(1, 3), noisy(2, 3));
    EXPECT_NE(noisy(2, 3), noisy(2, 4));
    LineData silent = clean;
    std::fill(silent.values.begin(), silent.values.end(), 0.0f);
    EXPECT_EQ(add_electronic_noise(silent, t, 20.0, 3), 0.0);
    EXPECT_EQ(mean_power(silent.values), 0.0);
}

}  // namespace
}  // namespace sonotrace::imaging
