#include "imaging/delay_and_sum.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <tbb/parallel_for.h>
#include <opencv2/core.hpp>

#include "probe/transmit.h"

namespace sonotrace::imaging {
namespace {

constexpr double kTurn = 2.0 * std::numbers::pi;

// Catmull-Rom interpolation of v at fractional position p (0 outside [0, n - 1]).
std::complex<float> interpolate(const std::complex<float>* v, int n, double p) {
    const int i = int(std::floor(p));
    if (i < 1 || i + 2 >= n) {
        if (i < 0 || i + 1 >= n) return 0.0f;
        const float u = float(p - i);
        return v[i] * (1.0f - u) + v[i + 1] * u;
    }
    const float u = float(p - i), u2 = u * u, u3 = u2 * u;
    return v[i - 1] * (-0.5f * u3 + u2 - 0.5f * u) + v[i] * (1.5f * u3 - 2.5f * u2 + 1.0f) +
           v[i + 1] * (-1.5f * u3 + 2.0f * u2 + 0.5f * u) + v[i + 2] * (0.5f * u3 - 0.5f * u2);
}

}  // namespace

PixelGrid pixel_grid(const probe::Transducer& t, double from_mm, double to_mm, double pixel_mm) {
    PixelGrid g;
    g.dx_mm = g.dz_mm = pixel_mm;
    const double half = 0.5 * t.array_length_mm();
    g.nx = std::max(1, int(std::floor(2.0 * half / pixel_mm)) + 1);
    g.x0_mm = -0.5 * (g.nx - 1) * pixel_mm;
    g.z0_mm = from_mm;
    g.nz = std::max(1, int(std::floor((to_mm - from_mm) / pixel_mm)) + 1);
    return g;
}

std::vector<std::complex<float>> analytic_signal(const float* x, int n) {
    const int padded = cv::getOptimalDFTSize(n + n / 8 + 16);
    cv::Mat spectrum(1, padded, CV_32FC2, cv::Scalar::all(0));
    for (int k = 0; k < n; ++k) spectrum.at<cv::Vec2f>(0, k)[0] = x[k];
    cv::dft(spectrum, spectrum);
    // Keep DC and Nyquist, double the positive half, clear the negative one.
    for (int k = 1; k < padded; ++k) {
        cv::Vec2f& s = spectrum.at<cv::Vec2f>(0, k);
        if (2 * k < padded) {
            s *= 2.0f;
        } else if (2 * k > padded) {
            s = cv::Vec2f(0.0f, 0.0f);
        }
    }
    cv::dft(spectrum, spectrum, cv::DFT_INVERSE | cv::DFT_SCALE);
    std::vector<std::complex<float>> out(static_cast<std::size_t>(n));
    for (int k = 0; k < n; ++k) {
        const cv::Vec2f& s = spectrum.at<cv::Vec2f>(0, k);
        out[std::size_t(k)] = {s[0], s[1]};
    }
    return out;
}

BeamformedImage delay_and_sum(const ChannelData& c, const probe::Transducer& t,
                              const PixelGrid& grid, const DasSettings& settings, int first,
                              int last) {
    if (last < 0) last = c.transmits;
    BeamformedImage image;
    image.grid = grid;
    image.values.assign(std::size_t(grid.nx) * std::size_t(grid.nz), 0.0f);
    image.weights.assign(image.values.size(), 0.0f);
    const int S = c.samples, E = c.elements;
    const double f0 = c.frequency_hz, fs = c.fs_hz, c0 = c.speed_m_s * 1e3;  // mm/s
    std::vector<std::complex<float>> baseband(std::size_t(E) * std::size_t(S));
    // Each pixel's receive aperture (header), the same under every transmit: at least two
    // pitches across (a narrower apodized aperture leaves pixels between elements with no
    // weight: a comb along the face).
    struct Aperture {
        double centre, half_width;
        int lo, hi;  // the elements within it, [lo, hi)
    };
    std::vector<Aperture> apertures(image.values.size());
    const probe::ScanGeometry geometry(t);
    tbb::parallel_for(0, grid.nz, [&](int j) {
        for (int i = 0; i < grid.nx; ++i) {
            const glm::dvec2 line = geometry.line_and_depth({grid.x(i), grid.z(j)});
            Aperture& a = apertures[std::size_t(j) * std::size_t(grid.nx) + std::size_t(i)];
            a.centre = geometry.array().arc_length(geometry.point(line.x, 0.0));
            a.half_width = std::max(0.5 * std::abs(line.y) / settings.f_number, t.pitch_mm);
            const auto& s = c.element_s_mm;
            a.lo = int(std::lower_bound(s.begin(), s.end(), a.centre - a.half_width) - s.begin());
            a.hi = int(std::upper_bound(s.begin(), s.end(), a.centre + a.half_width) - s.begin());
        }
    });
    for (int w = first; w < last; ++w) {
        // Each channel's analytic signal at baseband.
        tbb::parallel_for(0, E, [&](int e) {
            const std::vector<std::complex<float>> a = analytic_signal(c.channel(w, e), S);
            std::complex<float>* out = baseband.data() + std::size_t(e) * std::size_t(S);
            for (int n = 0; n < S; ++n)
                out[n] = a[std::size_t(n)] *
                         std::complex<float>(std::polar(1.0, -kTurn * f0 * c.time_s(n)));
        });
        const probe::TransmitField field(t, c.waves[std::size_t(w)]);
        tbb::parallel_for(0, grid.nz, [&](int j) {
            const double z = grid.z(j);
            for (int i = 0; i < grid.nx; ++i) {
                const double x = grid.x(i);
                const std::size_t at = std::size_t(j) * std::size_t(grid.nx) + std::size_t(i);
                const Aperture& aperture = apertures[at];
                const double transmit_time = field.at({x, z}).time_s;
                std::complex<double> sum = 0.0;
                double weights = 0.0;
                for (int e = aperture.lo; e < aperture.hi; ++e) {
                    const double weight = probe::apodization_weight(
                        settings.apodization,
                        0.5 + (c.element_s_mm[std::size_t(e)] - aperture.centre) /
                                  (2.0 * aperture.half_width));
                    if (!(weight > 0.0)) continue;
                    weights += weight;
                    const glm::dvec2 element = c.element_points[std::size_t(e)].position;
                    const double delay =
                        transmit_time + std::hypot(x - element.x, z - element.y) / c0;
                    const double position = (delay - c.start_s) * fs;
                    const std::complex<float> v =
                        interpolate(baseband.data() + std::size_t(e) * std::size_t(S), S, position);
                    sum += weight * std::complex<double>(v) * std::polar(1.0, kTurn * f0 * delay);
                }
                image.values[at] += std::complex<float>(sum);
                image.weights[at] += float(weights);
            }
        });
    }
    return image;
}

}  // namespace sonotrace::imaging
