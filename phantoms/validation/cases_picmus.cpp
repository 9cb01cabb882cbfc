// The PICMUS measures on the PICMUS-like phantom imaged with 75 plane waves over +-16
// degrees (docs/guide/channel-data.md), on the beamformed envelope (imaging::Frame::
// beamformed: linear, before TGC and compression).
#include <algorithm>
#include <cmath>
#include <numbers>

#include "phantoms/validation/cases_imaging.h"
#include "phantoms/validation/phantom_frames.h"
#include "probe/pulse.h"
#include "tissue/base/half_maximum.h"

namespace sonotrace::validation {

CaseResult picmus(const CaseContext& ctx) {
    PhantomFrame f =
        image_phantom(catalogue(ctx, "picmus"), {0.0, 0, imaging::Quality::standard, true, 0.0},
                      ctx.seed, "plane:-16:16:75");
    const cv::Mat& env = f.frame.beamformed;
    const imaging::ScanConverted& im = f.frame.image;
    auto position = [&](int r, int c) { return im.origin + glm::dvec2(c, r) * im.pixel_mm; };
    // The envelope's pixels whose probe-plane position satisfies `inside`.
    auto samples = [&](auto inside) {
        std::vector<double> out;
        for (int r = 0; r < env.rows; ++r)
            for (int c = 0; c < env.cols; ++c)
                if (inside(position(r, c)) && im.inside.at<uint8_t>(r, c))
                    out.push_back(env.at<float>(r, c));
        return out;
    };
    CaseResult result;
    const double lambda = f.transducer.wavelength_mm();

    // Speckle: Rayleigh, mean / std = sqrt(pi / (4 - pi)) = 1.913 (the bound 0.15). The
    // region x -18..-4, depth 8..17 mm holds no wire and no cyst; each 2 mm band of depth
    // is normalised to its mean (the attenuation and the growing receive aperture change
    // the level by some dB over the region).
    std::vector<double> speckle;
    for (double z = 8.0; z < 17.0; z += 2.0) {
        std::vector<double> band = samples(
            [&](glm::dvec2 p) { return p.x >= -18.0 && p.x <= -4.0 && p.y >= z && p.y < z + 2.0; });
        const double m = mean(band);
        for (double& v : band) speckle.push_back(v / m);
    }
    result.measurements.push_back(
        {"speckle SNR (envelope mean / std)", mean(speckle) / stddev(speckle),
         std::sqrt(std::numbers::pi / (4.0 - std::numbers::pi)), 0.15, ""});

    // The anechoic cyst at (-10, 30), radius 3 mm: inside within 2.5 mm, background a ring
    // 3.5..5.5 mm at the same depths. Contrast 20 log10(mean_in / mean_out) below -20 dB;
    // CNR (mu_b - mu_c) / sqrt(sigma_b^2 + sigma_c^2) tends to the background's mu / sigma
    // (1.913, tolerance 0.25 as speckle_cysts); gCNR (1 - the overlap of the two
    // histograms, 100 bins) at least 0.9.
    const glm::dvec2 cyst(-10.0, 30.0);
    const auto inside = samples([&](glm::dvec2 p) { return glm::length(p - cyst) < 2.5; });
    const auto ring = samples([&](glm::dvec2 p) {
        const double d = glm::length(p - cyst);
        return d > 3.5 && d < 5.5 && std::abs(p.y - cyst.y) <= 3.0;
    });
    result.measurements.push_back({"anechoic cyst contrast",
                                   20.0 * std::log10(mean(inside) / mean(ring)), -20.0, 0.0, "dB",
                                   Check::at_most});
    result.measurements.push_back(
        {"anechoic cyst CNR",
         (mean(ring) - mean(inside)) / std::hypot(stddev(ring), stddev(inside)), 1.913, 0.25, ""});
    const double top = std::max(*std::max_element(inside.begin(), inside.end()),
                                *std::max_element(ring.begin(), ring.end()));
    std::vector<double> h_in(100, 0.0), h_out(100, 0.0);
    for (double v : inside)
        h_in[std::min<std::size_t>(99, std::size_t(v / top * 100.0))] +=
            1.0 / double(inside.size());
    for (double v : ring)
        h_out[std::min<std::size_t>(99, std::size_t(v / top * 100.0))] += 1.0 / double(ring.size());
    double overlap = 0.0;
    for (int k = 0; k < 100; ++k) overlap += std::min(h_in[std::size_t(k)], h_out[std::size_t(k)]);
    result.measurements.push_back(
        {"anechoic cyst gCNR", 1.0 - overlap, 0.9, 0.0, "", Check::at_least});

    // The wire at (0, 20): its axial FWHM against the pulse-echo envelope's (c0/2 times the
    // waveform's FWHM, probe/pulse.h; within 15 %: the transmit's half-integration
    // lengthens the echo a little), its lateral FWHM at most the receive aperture's alone
    // (a Hann aperture at F: 1.44 lambda F), which compounding the transmits narrows.
    int wr = 0, wc = 0;
    float best = -1.0f;
    for (int r = 0; r < env.rows; ++r)
        for (int c = 0; c < env.cols; ++c)
            if (glm::length(position(r, c) - glm::dvec2(0.0, 20.0)) < 1.0 &&
                env.at<float>(r, c) > best)
                best = env.at<float>(r, c), wr = r, wc = c;
    const base::HalfMaximum axial =
        base::half_maximum(env.rows, wr, [&](int r) { return double(env.at<float>(r, wc)); });
    const base::HalfMaximum lateral =
        base::half_maximum(env.cols, wc, [&](int c) { return double(env.at<float>(wr, c)); });
    const double expected_axial = probe::PulseEcho(f.transducer).axial_fwhm_mm();
    result.measurements.push_back({"wire at 20 mm: axial FWHM", axial.width() * im.pixel_mm,
                                   expected_axial, 0.15 * expected_axial, "mm"});
    result.measurements.push_back({"wire at 20 mm: lateral FWHM", lateral.width() * im.pixel_mm,
                                   1.44 * lambda * f.transducer.rx_f_number, 0.0, "mm",
                                   Check::at_most});
    return result;
}

}  // namespace sonotrace::validation
