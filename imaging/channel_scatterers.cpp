#include "imaging/channel_scatterers.h"

#include <cmath>
#include <numbers>

#include "probe/pulse.h"
#include "tissue/base/hash.h"

namespace sonotrace::imaging {
namespace {

// Uniform in (0, 1] from 53 bits of a hash.
double unit(uint64_t bits) {
    return (double(bits >> 11) + 1.0) * 0x1.0p-53;
}

}  // namespace

std::vector<ChannelEcho> channel_scatterers(
    const probe::Transducer& t, const glm::dvec2& lo, const glm::dvec2& hi,
    const ScattererSettings& settings,
    const std::function<double(const glm::dvec2&)>& backscatter) {
    const double cell_area = t.wavelength_mm() * probe::PulseEcho(t).axial_fwhm_mm();
    const double density = settings.per_resolution_cell / cell_area;  // per mm^2
    // Grid cells of about 16 scatterers each: their number is a whole one, so a cell's
    // count rounds the density by at most 1/32.
    const int per_cell = 16;
    const double cell = std::sqrt(per_cell / density);
    const double scale = 1.0 / std::sqrt(per_cell / (cell * cell));
    std::vector<ChannelEcho> out;
    const long i0 = long(std::floor(lo.x / cell)), i1 = long(std::floor(hi.x / cell));
    const long j0 = long(std::floor(lo.y / cell)), j1 = long(std::floor(hi.y / cell));
    const uint64_t seed = base::mix64(settings.seed ^ 0x5ca77e75ull);
    for (long j = j0; j <= j1; ++j)
        for (long i = i0; i <= i1; ++i) {
            const uint64_t key =
                base::mix64(seed ^ base::mix64(uint64_t(i) * 0x9e3779b97f4a7c15ull ^ uint64_t(j)));
            for (int k = 0; k < per_cell; ++k) {
                const uint64_t a = base::mix64(key + 4 * uint64_t(k)),
                               b = base::mix64(key + 4 * uint64_t(k) + 1),
                               c = base::mix64(key + 4 * uint64_t(k) + 2),
                               d = base::mix64(key + 4 * uint64_t(k) + 3);
                const glm::dvec2 r((double(i) + unit(a)) * cell, (double(j) + unit(b)) * cell);
                if (r.x < lo.x || r.x > hi.x || r.y < lo.y || r.y > hi.y) continue;
                const double level = backscatter(r);
                if (!(level > 0.0)) continue;
                // Box-Muller: one Gaussian of the pair.
                const double gaussian = std::sqrt(-2.0 * std::log(unit(c))) *
                                        std::cos(2.0 * std::numbers::pi * unit(d));
                out.push_back({r, gaussian * level * scale, 0.0, std::nullopt});
            }
        }
    return out;
}

}  // namespace sonotrace::imaging
