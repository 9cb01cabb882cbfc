#pragma once
// The two-way point-spread functions of a transducer's scan lines (probe/aperture.h),
// tabulated once per probe set-up: for every line, rows at depths dz apart of
// H(x, z) = T R across the line, x = j dx(z) for |j| <= J, where dx(z) is a quarter of
// the receive beam's main lobe lambda max(F_rx(z), 1/2) (so every row holds +-6 lobes).
// Lines whose array looks the same from them (linear and convex lines at the same
// sub-element offset, with the same clipping by the array's ends) share rows.
//
// H is what the speckle takes of the broadband response (LineFields::speckle): |H|^2 is
// the echo's energy over the pulse's, sum_m |s_m H_m|^2 / sum_m |s_m|^2, whose lateral
// integral sets the mean speckle level at each depth (brighter at the focus, where the
// two-way beam is narrowest), and its phase H's at f0; |R|^2 the same of the receive.
//
// The image formation reads from it the lateral weights of the speckle, the response of
// planar reflectors and the lateral power integral.
#include <algorithm>
#include <array>
#include <complex>
#include <limits>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include <tbb/concurrent_unordered_map.h>

#include "probe/aperture.h"
#include "probe/transducer.h"
#include "tissue/base/hash.h"

namespace sonotrace::imaging {

// Which rows of a table are computed from the fields (LineFields::speckle at each of a
// row's samples: a transmit and a receive element sum on the energy band) and which are
// interpolated from computed ones. A new probe setting pays for the computed rows alone.
//   near_elements  (elements, default 8): the near zone, where the receive aperture is
//                  narrower than this many elements. Its beam is a few elements wide and
//                  turns with the line's sub-element offset and the aperture's growth by
//                  one element: every row there is computed (interpolating every second
//                  depth missed the row's power by 2 dB).
//   depth_step     (rows, default 8): beyond it, depth rows `depth_step` apart are computed
//                  (8 dz: 3.5 mm on the convex preset, against a transmit depth of field
//                  of about 7 lambda F^2 = 12 mm).
//   line_step      (lines, default 8): and lines at most this far apart, denser towards
//                  the ends of the scan (1 apart at the end, d / 3 at d lines from it),
//                  where the apertures are clipped by the array and the beam turns
//                  fastest from line to line. Beyond the near zone lines are snapped to
//                  whole elements (so that lines inside the array share one row).
//   snap_fraction  (pitches, default 1/8): lines share rows at sub-element offsets this
//                  far apart (0: each line its own geometry).
// The rows between are bilinear in line and depth, sample by sample (every row samples
// its own receive lobe, so sample j of neighbours is the same place in the beam), and so
// is their lateral power. Their error against a table of every row computed, each line
// unsnapped: Psf.InterpolatedRowsFollowComputedOnes.
struct RowLattice {
    double near_elements = 8.0;
    int depth_step = 8, line_step = 8;
    double snap_fraction = 0.125;
    // Depth indices (rows dz apart) of the near zone.
    int near_depths(const probe::Transducer& t, double dz) const;
    static RowLattice every_row() { return {std::numeric_limits<double>::infinity(), 1, 1, 0.0}; }
};

class PsfTable {
  public:
    // The table of `t` (computed on first use, kept for the next frames of the same
    // probe set-up).
    static std::shared_ptr<const PsfTable> of(const probe::Transducer& t);
    // The table of `t` computed afresh, sharing no rows, and not kept (benchmarks, tests).
    static std::shared_ptr<const PsfTable> build(const probe::Transducer& t,
                                                 RowLattice lattice = RowLattice{});
    struct RowStore;  // rows shared between tables (psf_row_store.h)

    // Every row holds +-6 lobes at a quarter lobe per sample: J = 24. Fixed arrays: a
    // table is some ten thousand rows, and allocating each was a tenth of its build.
    static constexpr int kHalfRow = 24;
    struct Row {
        double dx = 0.0;                                        // lateral spacing (mm)
        int half = kHalfRow;                                    // J: samples j = -J .. J
        std::array<std::complex<float>, 2 * kHalfRow + 1> h{};  // H at x = j dx, index j + J
        std::array<float, 2 * kHalfRow + 1> receive_power{};    // |R|^2 at the same x
        double power = 0.0;                                     // sum |H|^2 dx (1/mm)
    };

    // How far across a line its row reaches at depth z (mm): +-6 main lobes of the
    // receive, lambda max(F_rx(z), 1/2) each.
    static double reach_mm(const probe::Transducer& t, double z);
    // How far across a line a point target's echo is drawn (mm): three times the reach,
    // and half the transmit aperture more (near the face the transmit beam is as wide as
    // its aperture): beyond, its broadband echo is 45 dB and more below its peak.
    static double point_reach_mm(const probe::Transducer& t, double z);
    double dz() const { return dz_; }
    // Lines share rows: the row of line l at depth index i.
    int row_id(int l, int i) const;
    // The line whose fields made the row of line l at depth index i.
    int line_of_row(int l, int i) const { return row_line_[std::size_t(row_id(l, i))]; }
    double row_depth_mm(int i) const { return std::max(i * dz_, 0.5 * dz_); }
    // The fields of the line that made a row, with the table's snapping (t: the table's).
    static probe::LineFields fields_of_line(const probe::Transducer& t, int l);
    int depths() const { return depths_; }
    int row_count() const { return int(rows_.size()); }
    // Rows computed from the fields when the table was made (the rest interpolated or
    // shared).
    int computed_rows() const { return computed_rows_; }
    // The row of line l at depth index i (z = i dz), i clamped to the table.
    const Row& row(int l, int i) const;
    // H of line l at (x, z) (line frame, mm): linear in depth between rows and across
    // within them; 0 beyond a row's reach.
    std::complex<float> at(int l, double x, double z) const;
    // H of line l on its row at depth index i (z = i dz), linear across.
    std::complex<float> at_row(int l, int i, double x) const;
    // Lateral power integral at depth z (1/mm), linear between rows.
    double power(int l, double z) const;
    // The receive sensitivity |R|^2 of line l at (x, z) (1/mm; linear between rows and
    // samples, 0 beyond a row's reach): power(x, z). The line's rows are looked up once,
    // when it is made: the receive weights ask millions of times per frame.
    class LineReceive {
      public:
        LineReceive(const PsfTable& table, int l);
        // Reciprocals of the spacings, not divisions: the receive weights ask here for
        // every particle at every bin of range, and three divisions were most of its cost.
        double power(double x, double z) const {
            const double u = std::clamp(z * inverse_dz_, 0.0, double(depths_ - 1));
            const int i = std::min(int(u), depths_ - 2);
            const double f = u - i;
            return (1.0 - f) * across(rows_[std::size_t(i)], x) +
                   f * across(rows_[std::size_t(i) + 1], x);
        }

      private:
        // What power() reads of a row, side by side (one load less than through Row).
        struct RowView {
            double inverse_dx, half, end;  // 1 / Row::dx, Row::half, 2 Row::half
            const float* receive_power;
        };
        static double across(const RowView& r, double x) {
            const double v = x * r.inverse_dx + r.half;
            if (!(v >= 0.0) || v >= r.end) return 0.0;
            const auto j = std::size_t(v);
            const double g = v - double(j);
            return double(r.receive_power[j]) * (1.0 - g) + double(r.receive_power[j + 1]) * g;
        }
        double inverse_dz_;
        int depths_;
        std::vector<RowView> rows_;  // by depth index
    };
    // The echo of a planar reflector through depth z on line l whose normal, pointing away
    // from the probe, is tilted by theta from the line (probe::LineFields::plane_echo),
    // at the nearest of the table's depth rows (lambda or less apart: the echo's phase is
    // referenced to 2 z / c0, what is left changes over millimetres) and of tilt steps of
    // 1/2000 in sin(theta) (a tenth of the tilt response's finest lobe, lambda / (2 x
    // aperture), or finer). 0 beyond the apertures' angular span (largest_sin_tilt).
    // Kept once computed, for the next events and frames of the same probe set-up.
    std::complex<double> plane_echo(int l, double z, double sin_tilt) const;
    // The nearest depth row to depth z (mm), as plane_echo() takes it.
    int depth_index(double z) const;
    // Beyond this tilt a plane at depth z sends its mirror image of the transmit aperture
    // past the receive aperture: the reflected beam lands 2 z tan(2 theta) aside, so it
    // misses once that exceeds (D_tx + D_rx) / 2, and diffraction widens the span by
    // lambda / D; taken twice as wide, what is left is the apertures' side-lobe level.
    double largest_sin_tilt(double z) const;
    // H at the speckle's sub-lines: for sub-lines K per line gap (spacing d_i = the line
    // spacing at z_i = i dz over K), at(l, i)[j] = at_row(l, i, j d_i) for |j| <= reach =
    // 8 K and i = 0 .. depths (the last clamped to the table). Lines share rows, so each
    // is evaluated once per row; kept for the next frames of the same set-up and K.
    struct SubLineWeights {
        int reach = 0, depths = 0;
        std::vector<int> slot_of;                 // [l * (depths + 1) + i] -> slot
        std::vector<std::complex<float>> values;  // [slot * (2 reach + 1) + j + reach]
        // Per slot: the largest |j| whose |H|^2 is within kSpeckleFloor (50 dB) of the
        // slot's peak. The speckle sums stop there: what lies beyond holds a few 1e-5 of
        // the row's power (test: Speckle.SubLinesBeyondTheFloorHoldNoVisiblePower).
        std::vector<int> significant;
        static constexpr float kSpeckleFloor = 1e-5f;
        std::size_t slot(int l, int i) const {
            return std::size_t(slot_of[std::size_t(l) * std::size_t(depths + 1) + std::size_t(i)]);
        }
        const std::complex<float>* at(int l, int i) const {
            return values.data() + slot(l, i) * std::size_t(2 * reach + 1) + std::size_t(reach);
        }
        int significant_reach(int l, int i) const { return significant[slot(l, i)]; }
    };
    std::shared_ptr<const SubLineWeights> sub_line_weights(int K) const;
    // The lateral power integral on the central line at the transmit focus: speckle is
    // calibrated there (its level at other depths follows the ratio).
    double focal_power() const { return focal_power_; }

  private:
    friend struct PsfTableBuilder;
    // plane_echo() at depth index i and tilt step round(2000 sin(theta)), with no check
    // of the angular span.
    std::complex<double> plane_echo_at(int l, int i, int tilt_step) const;
    double dz_ = 1.0, k_ = 0.0;
    int lines_ = 0, depths_ = 0, computed_rows_ = 0;
    double focal_power_ = 1.0;
    std::shared_ptr<RowStore> store_;
    std::vector<const Row*> rows_;  // the store's rows when the table was made, numbered as there
    std::vector<int> row_line_;     // rows_ -> the line that made it (its fields: plane echoes)
    std::vector<int> row_of_;       // [line * depths + i] -> rows_
    probe::Transducer t_;
    // Plane echoes (in the store, by its row and tilt step) are read by every reflection
    // of every frame from all threads at once, so without a lock (behind one mutex the
    // threads queued at every reflection). Filled up to kMaxPlaneEchoes, computed afresh
    // beyond.
    static constexpr std::size_t kMaxPlaneEchoes = std::size_t(1) << 22;  // ~100 MB
    // The sub-line weights.
    mutable std::mutex cache_mutex_;
    mutable std::unordered_map<int, std::shared_ptr<const SubLineWeights>> sub_line_weights_;

  public:
    // Mixed keys: the plane echoes' buckets are a power of two, and the row sits in the
    // key's high half.
    struct MixedKey {
        std::size_t operator()(uint64_t key) const { return std::size_t(base::mix64(key)); }
    };
};

}  // namespace sonotrace::imaging
