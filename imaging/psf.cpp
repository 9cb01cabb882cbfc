#include "imaging/psf.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <numbers>

#include "imaging/psf_row_store.h"
#include "probe/aperture.h"
#include "probe/array_geometry.h"

namespace sonotrace::imaging {

namespace {
constexpr int kHalfRow = PsfTable::kHalfRow;
}  // namespace

double PsfTable::reach_mm(const probe::Transducer& t, double z) {
    return kHalfRow * 0.25 * t.wavelength_mm() * std::max(z / t.receive_aperture_mm(z), 0.5);
}

double PsfTable::point_reach_mm(const probe::Transducer& t, double z) {
    return 3.0 * reach_mm(t, z) + 0.5 * t.active_aperture_mm();
}

int RowLattice::near_depths(const probe::Transducer& t, double dz) const {
    if (!(near_elements < 1e9)) return std::numeric_limits<int>::max();
    int i = 1;
    while (t.receive_aperture_mm(i * dz) < near_elements * t.pitch_mm &&
           i * dz < t.depth_mm + 2.0 * dz)
        ++i;
    return i;
}

probe::LineFields PsfTable::fields_of_line(const probe::Transducer& t, int l) {
    return probe::LineFields(t, probe::line_array(t, l, RowStore::kSnapFraction * t.pitch_mm));
}

double PsfTable::largest_sin_tilt(double z) const {
    z = std::max(z, 1e-3);
    const double d_tx = t_.active_aperture_mm(), d_rx = t_.receive_aperture_mm(z);
    const double theta =
        0.5 * std::atan(0.25 * (d_tx + d_rx) / z) + t_.wavelength_mm() / std::min(d_tx, d_rx);
    return std::sin(std::min(2.0 * theta, 0.5 * std::numbers::pi));
}

namespace {
constexpr double kTiltSteps = 2000.0;
}

int PsfTable::depth_index(double z) const {
    return std::clamp(int(std::lround(z / dz_)), 0, depths_ - 1);
}

std::complex<double> PsfTable::plane_echo(int l, double z, double sin_tilt) const {
    if (std::abs(sin_tilt) > largest_sin_tilt(z)) return 0.0;
    return plane_echo_at(l, depth_index(z),
                         int(std::lround(std::clamp(sin_tilt, -1.0, 1.0) * kTiltSteps)));
}

std::complex<double> PsfTable::plane_echo_at(int l, int i, int tilt) const {
    const int row = row_id(l, i), id = row;
    const uint64_t key = (uint64_t(uint32_t(id)) << 32) | uint32_t(tilt + 1000000);
    if (auto it = store_->plane_echoes.find(key); it != store_->plane_echoes.end())
        return it->second;
    std::shared_ptr<const probe::LineFields> fields;
    const int line = row_line_[std::size_t(row)];
    {
        const std::lock_guard<std::mutex> lock(store_->fields_mutex);
        auto& slot = store_->fields[line];
        if (!slot) slot = std::make_shared<probe::LineFields>(fields_of_line(t_, line));
        fields = slot;
    }
    // Computed outside the lock (two threads may both compute one: the same value).
    const std::complex<double> value = fields->plane_echo(row_depth_mm(i), tilt / kTiltSteps);
    if (store_->plane_echoes.size() < kMaxPlaneEchoes) store_->plane_echoes.emplace(key, value);
    return value;
}

int PsfTable::row_id(int l, int i) const {
    l = std::clamp(l, 0, lines_ - 1);
    i = std::clamp(i, 0, depths_ - 1);
    return row_of_[std::size_t(l) * std::size_t(depths_) + std::size_t(i)];
}

const PsfTable::Row& PsfTable::row(int l, int i) const {
    l = std::clamp(l, 0, lines_ - 1);
    i = std::clamp(i, 0, depths_ - 1);
    return *rows_[std::size_t(row_of_[std::size_t(l) * std::size_t(depths_) + std::size_t(i)])];
}

namespace {
std::complex<float> across(const PsfTable::Row& r, double x) {
    const double u = x / r.dx + r.half;
    if (!(u >= 0.0) || u >= double(2 * r.half)) return {0.0f, 0.0f};
    const auto j = std::size_t(u);
    const float f = float(u - double(j));
    return r.h[j] + f * (r.h[j + 1] - r.h[j]);
}
}  // namespace

std::complex<float> PsfTable::at(int l, double x, double z) const {
    const double u = std::clamp(z / dz_, 0.0, double(depths_ - 1));
    const int i = std::min(int(u), depths_ - 2);
    const float f = float(u - i);
    return (1.0f - f) * across(row(l, i), x) + f * across(row(l, i + 1), x);
}

std::complex<float> PsfTable::at_row(int l, int i, double x) const {
    return across(row(l, i), x);
}

std::shared_ptr<const PsfTable::SubLineWeights> PsfTable::sub_line_weights(int K) const {
    {
        const std::lock_guard<std::mutex> lock(cache_mutex_);
        if (auto it = sub_line_weights_.find(K); it != sub_line_weights_.end()) return it->second;
    }
    auto w = std::make_shared<SubLineWeights>();
    w->reach = 8 * K;
    w->depths = depths_;
    const int width = 2 * w->reach + 1;
    w->slot_of.resize(std::size_t(lines_) * std::size_t(depths_ + 1));
    std::vector<std::pair<int, int>> slots;  // (a line, depth index) of each slot's row
    std::vector<int> slot_of_row(rows_.size(), -1);
    for (int i = 0; i <= depths_; ++i) {
        const std::size_t first_slot = slots.size();
        for (int l = 0; l < lines_; ++l) {
            int& slot = slot_of_row[std::size_t(row_id(l, i))];
            if (slot < int(first_slot)) slot = int(slots.size()), slots.emplace_back(l, i);
            w->slot_of[std::size_t(l) * std::size_t(depths_ + 1) + std::size_t(i)] = slot;
        }
    }
    w->values.resize(slots.size() * std::size_t(width));
    w->significant.resize(slots.size());
    const probe::ScanGeometry geometry(t_);
    tbb::parallel_for(0, int(slots.size()), [&](int s) {
        const auto [l, i] = slots[std::size_t(s)];
        const double d = std::max(geometry.line_spacing_mm(i * dz_), 1e-6) / K;
        std::complex<float>* row = w->values.data() + std::size_t(s) * std::size_t(width);
        for (int j = -w->reach; j <= w->reach; ++j) row[j + w->reach] = at_row(l, i, j * d);
        float peak = 0.0f;
        for (int j = 0; j < width; ++j) peak = std::max(peak, std::norm(row[j]));
        int significant = 0;
        for (int j = -w->reach; j <= w->reach; ++j)
            if (std::norm(row[j + w->reach]) >= SubLineWeights::kSpeckleFloor * peak)
                significant = std::max(significant, std::abs(j));
        w->significant[std::size_t(s)] = significant;
    });
    const std::lock_guard<std::mutex> lock(cache_mutex_);
    return sub_line_weights_.try_emplace(K, std::move(w)).first->second;
}

double PsfTable::power(int l, double z) const {
    const double u = std::clamp(z / dz_, 0.0, double(depths_ - 1));
    const int i = std::min(int(u), depths_ - 2);
    const double f = u - i;
    return (1.0 - f) * row(l, i).power + f * row(l, i + 1).power;
}

PsfTable::LineReceive::LineReceive(const PsfTable& table, int l)
    : inverse_dz_(1.0 / table.dz_), depths_(table.depths_), rows_(std::size_t(table.depths_)) {
    for (int i = 0; i < depths_; ++i) {
        const Row& r = table.row(l, i);
        rows_[std::size_t(i)] = {1.0 / r.dx, double(r.half), double(2 * r.half),
                                 r.receive_power.data()};
    }
}

}  // namespace sonotrace::imaging
