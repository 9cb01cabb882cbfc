#include "probe/elevation.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <mutex>
#include <numbers>

namespace sonotrace::probe {

ElevationBeam::ElevationBeam(const Transducer& t)
    : aperture_mm_(t.elevation_aperture_mm()),
      focus_mm_(t.elevation_focus_mm),
      wavelength_mm_(t.wavelength_mm()) {}

std::complex<double> ElevationBeam::field(double e_mm, double z_mm) const {
    const double z = std::max(z_mm, wavelength_mm_);
    const double k = 2.0 * std::numbers::pi / wavelength_mm_;
    const double a = 0.5 * (1.0 / z - 1.0 / focus_mm_), b = e_mm / z;
    const double half = 0.5 * aperture_mm_;
    // Midpoint rule with at most 0.1 rad of phase change per panel: the phase
    // k (a x^2 - b x) changes at most at k (2 |a| H/2 + |b|); the error of |U| is then
    // below 0.1 %.
    const double rate = k * (2.0 * std::abs(a) * half + std::abs(b));
    const int panels = std::clamp(int(std::ceil(aperture_mm_ * rate / 0.1)), 16, 1 << 20);
    const double h = aperture_mm_ / panels;
    std::complex<double> sum = 0.0;
    for (int n = 0; n < panels; ++n) {
        const double x = -half + (n + 0.5) * h;
        sum += std::polar(1.0, k * (a * x * x - b * x));
    }
    return sum * h;
}

double ElevationBeam::profile(double e_mm, double z_mm) const {
    const double z = std::max(z_mm, wavelength_mm_);
    return std::norm(field(e_mm, z)) / (wavelength_mm_ * z * aperture_mm_);
}

double ElevationBeam::reach_mm(double z_mm) const {
    const double z = std::max(z_mm, wavelength_mm_);
    return 0.5 * aperture_mm_ * std::abs(1.0 - z / focus_mm_) +
           10.0 * wavelength_mm_ * z / aperture_mm_;
}

ElevationTable::ElevationTable(const Transducer& t) {
    const ElevationBeam beam(t);
    const double H = beam.aperture_mm(), F = beam.focus_mm(), lambda = beam.wavelength_mm();
    const double depth = t.depth_mm + 2.0;
    for (double z = 0.0; z <= depth; z += 0.5)
        slab_half_mm_ =
            std::max(slab_half_mm_, 0.5 * H * std::abs(1.0 - z / F) + 2.0 * lambda * z / H + 1.0);
    de_ = 0.25 * lambda;
    rows_ = int(std::ceil(depth / dz_)) + 1;
    columns_ = int(std::ceil(slab_half_mm_ / de_)) + 1;
    values_.assign(std::size_t(rows_) * std::size_t(columns_), 0.0f);
    const double peak = H * H;
    tbb::parallel_for(0, rows_, [&](int r) {
        for (int c = 0; c < columns_; ++c)
            values_[std::size_t(r) * std::size_t(columns_) + std::size_t(c)] =
                float(std::norm(beam.field(c * de_, r * dz_)) / peak);
    });
}

double ElevationTable::intensity(double e_mm, double z_mm) const {
    const double u = std::abs(e_mm) / de_;
    if (!(u < columns_ - 1)) return 0.0;
    const double v = std::clamp(z_mm / dz_, 0.0, double(rows_ - 1) - 1e-9);
    const int c = int(u), r = int(v);
    const double fu = u - c, fv = v - r;
    auto at = [&](int row, int column) {
        return double(values_[std::size_t(row) * std::size_t(columns_) + std::size_t(column)]);
    };
    return (1.0 - fv) * ((1.0 - fu) * at(r, c) + fu * at(r, c + 1)) +
           fv * ((1.0 - fu) * at(r + 1, c) + fu * at(r + 1, c + 1));
}

std::shared_ptr<const ElevationTable> ElevationTable::of(const Transducer& t) {
    const std::array<double, 5> key{t.elevation_aperture_mm(), t.elevation_focus_mm,
                                    t.wavelength_mm(), t.depth_mm, 0.0};
    static std::mutex mutex;
    static std::vector<std::pair<std::array<double, 5>, std::shared_ptr<const ElevationTable>>>
        cache;
    {
        const std::lock_guard<std::mutex> lock(mutex);
        for (const auto& [k, table] : cache)
            if (k == key) return table;
    }
    auto table = std::make_shared<const ElevationTable>(t);
    const std::lock_guard<std::mutex> lock(mutex);
    cache.emplace_back(key, table);
    if (cache.size() > 4) cache.erase(cache.begin());
    return table;
}

}  // namespace sonotrace::probe
