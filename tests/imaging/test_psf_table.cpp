// The two-way PSF table (imaging/psf.h) as a whole: its lattice of computed and
// interpolated rows against every row computed, rows shared across imaging depths, and
// the look-ups kept per row and line (sub-line weights, receive sensitivity, the
// speckle's floor) against the plain forms they replace.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <variant>
#include <vector>

#include "imaging/psf.h"
#include "probe/aperture.h"
#include "probe/beam.h"
#include "probe/transducer.h"

namespace sonotrace {
namespace {

// Rows shared between the tables of probe settings that differ in depth alone (an
// optimisation that claims to change nothing): a table assembled from a store that a
// shallower and a deeper table filled first equals one computed afresh, bit for bit, in
// every row, its power and its plane echoes.
TEST(Psf, TablesSharingRowsAcrossDepthsEqualFreshOnes) {
    for (const char* preset : {"convex", "linear", "phased"}) {
        probe::Transducer t = probe::find_transducer(preset, "test");
        t.lines = 24;
        t.depth_mm = 0.8 * probe::find_transducer(preset, "test").depth_mm;
        for (const double depth : {0.6 * t.depth_mm, 1.2 * t.depth_mm}) {
            probe::Transducer other = t;
            other.depth_mm = depth;
            imaging::PsfTable::of(other)->plane_echo(t.lines / 3, 0.5 * depth, 0.05);
        }
        const auto shared = imaging::PsfTable::of(t), fresh = imaging::PsfTable::build(t);
        ASSERT_EQ(shared->depths(), fresh->depths()) << preset;
        ASSERT_EQ(shared->dz(), fresh->dz()) << preset;
        long differing = 0;
        for (int l = 0; l < t.lines; ++l)
            for (int i = 0; i < fresh->depths(); ++i) {
                const auto &a = shared->row(l, i), &b = fresh->row(l, i);
                differing += a.dx != b.dx || a.half != b.half || a.power != b.power ||
                             a.h.size() != b.h.size() ||
                             std::memcmp(a.h.data(), b.h.data(), a.h.size() * sizeof a.h[0]) != 0 ||
                             std::memcmp(a.receive_power.data(), b.receive_power.data(),
                                         a.receive_power.size() * sizeof a.receive_power[0]) != 0;
            }
        EXPECT_EQ(differing, 0) << preset;
        EXPECT_EQ(shared->focal_power(), fresh->focal_power()) << preset;
        for (int l : {0, t.lines / 3, t.lines - 1})
            for (const double z : {0.3 * t.depth_mm, 0.5 * t.depth_mm})
                EXPECT_EQ(shared->plane_echo(l, z, 0.05), fresh->plane_echo(l, z, 0.05))
                    << preset << " line " << l << " z " << z;
    }
}

// The row store's key is the parameter rows that shape the PSF
// (TransducerParameterDoc::shapes_psf_rows). Each parameter changed by 10 % (or 2, or to
// another apodization): one that shapes the rows gets a table of its own, equal to one
// built afresh, even right after its neighbour's table was made (a key without it would
// hand back the neighbour's); one that does not leaves a fresh table's row at the focus
// as it was (a parameter marked so wrongly changes it).
TEST(Psf, TheRowStoresKeyHoldsEveryParameterThatShapesTheRows) {
    probe::Transducer base = probe::find_transducer("linear", "test");
    base.lines = 16;
    const auto reference = imaging::PsfTable::build(base);
    auto focal_row = [](const probe::Transducer& t, const imaging::PsfTable& table) {
        const int focus = std::min(int(std::lround(t.focus_mm / table.dz())), table.depths() - 1);
        return table.row(t.lines / 2, focus).power;
    };
    int shaping = 0, not_shaping = 0;
    for (const auto& doc : probe::transducer_parameter_docs()) {
        probe::Transducer t = base;
        const auto value = doc.get(base);
        if (const double* x = std::get_if<double>(&value))
            doc.set(t, std::to_string(*x * 1.1), "test");
        else if (const int* n = std::get_if<int>(&value))
            doc.set(t, std::to_string(*n + 2), "test");
        else if (std::string(doc.key).find("apodization") != std::string::npos)
            doc.set(t, std::get<std::string>(value) == "hann" ? "tukey" : "hann", "test");
        else
            continue;  // the array type: another geometry altogether
        t.validate("test");
        const auto fresh = imaging::PsfTable::build(t);
        if (doc.shapes_psf_rows) {
            imaging::PsfTable::of(base);  // the neighbour's table and rows, just made
            const auto shared = imaging::PsfTable::of(t);
            EXPECT_EQ(shared->focal_power(), fresh->focal_power()) << doc.key;
            EXPECT_EQ(focal_row(t, *shared), focal_row(t, *fresh)) << doc.key;
            ++shaping;
        } else {
            EXPECT_EQ(fresh->dz(), reference->dz()) << doc.key;
            EXPECT_EQ(focal_row(t, *fresh), focal_row(base, *reference)) << doc.key;
            ++not_shaping;
        }
    }
    EXPECT_GE(shaping, 14);
    EXPECT_GE(not_shaping, 4);
}

// The computed rows share element terms between the lines of one depth at one
// sub-element offset (probe/aperture_terms.h), an optimisation that claims to change
// only the rounding: every row the lattice computes (all lines in the near zone; the
// first and last line, always anchors, beyond it) against LineFields::speckle of the
// line's own array and apertures (the plain per-line element sum), within 2e-4 of the
// row's peak in H and in the receive sensitivity and 1e-4 in power (float sums of up to
// 128 elements whose phases are taken against different references).
TEST(Psf, RowsFromSharedTermsEqualEachLinesOwnSums) {
    for (const char* preset : {"convex", "linear", "phased", "radial"}) {
        const probe::Transducer t = probe::find_transducer(preset, "test");
        const auto table = imaging::PsfTable::build(t);
        const imaging::RowLattice lattice;
        const int near = std::min(lattice.near_depths(t, table->dz()), table->depths());
        double worst_h = 0.0, worst_receive = 0.0, worst_power = 0.0;
        int rows = 0;
        for (int i = 0; i < table->depths(); i += i < near ? 1 : lattice.depth_step) {
            const double z = table->row_depth_mm(i);
            for (int l = 0; l < t.lines; l += i < near ? 1 : t.lines - 1) {
                // The line that made the row (lines whose apertures cover the same
                // elements share it; at the array's ends their windows differ by up to
                // 1e-3 of H's peak).
                const probe::LineFields fields(
                    t, probe::line_array(t, table->line_of_row(l, i),
                                         (i < near ? lattice.snap_fraction : 1.0) * t.pitch_mm));
                const auto receive = fields.receive_aperture(z);
                const auto& row = table->row(l, i);
                double peak = 0.0, receive_peak = 0.0, h = 0.0, r = 0.0, power = 0.0;
                for (int j = -row.half; j <= row.half; ++j) {
                    const auto s = fields.speckle({j * row.dx, z}, receive);
                    const auto k = std::size_t(j + row.half);
                    peak = std::max(peak, std::abs(s.weight));
                    receive_peak = std::max(receive_peak, s.receive_power);
                    h = std::max(h, std::abs(std::complex<double>(row.h[k]) - s.weight));
                    r = std::max(r, std::abs(double(row.receive_power[k]) - s.receive_power));
                    power += s.power * row.dx;
                }
                worst_h = std::max(worst_h, h / peak);
                worst_receive = std::max(worst_receive, r / receive_peak);
                worst_power = std::max(worst_power, std::abs(row.power / power - 1.0));
                ++rows;
            }
        }
        std::printf("%s: %d rows; H %.2e, receive %.2e, power %.2e of the peak\n", preset, rows,
                    worst_h, worst_receive, worst_power);
        EXPECT_LT(worst_h, 5e-4) << preset;
        EXPECT_LT(worst_receive, 2e-4) << preset;
        EXPECT_LT(worst_power, 1e-4) << preset;
    }
}

// The table's lattice (RowLattice: beyond the near zone, rows interpolated between
// computed ones; lines at sub-element offsets 1/8 pitch apart sharing rows) against a
// table of every row computed from the fields with every line at its own position, for
// every preset's lines and depths: the error of H at each sample relative to its row's
// peak, of the row's lateral power (what sets the speckle level; the validation case
// speckle_depth holds the image's level to 1.5 dB) and of the receive sensitivity
// relative to its row's peak. Within 5 wavelengths of the face the lines' sub-element
// offsets alone move H by up to 0.6 of its peak and the power by 1.7 dB (the beam is one
// or two elements there); beyond, the bounds below, each about 1.5 times the largest
// error measured over the four presets.
TEST(Psf, InterpolatedRowsFollowComputedOnes) {
    for (const char* preset : {"convex", "linear", "phased", "radial"}) {
        const probe::Transducer t = probe::find_transducer(preset, "test");
        const auto table = imaging::PsfTable::build(t);
        const auto exact = imaging::PsfTable::build(t, imaging::RowLattice::every_row());
        ASSERT_EQ(table->depths(), exact->depths());
        EXPECT_LT(table->computed_rows(), exact->computed_rows() / 6) << preset;
        std::vector<double> h_error, power_error, receive_error;
        for (int l = 0; l < t.lines; ++l)
            for (int i = 0; i < exact->depths(); ++i) {
                if (exact->row_depth_mm(i) < 5.0 * t.wavelength_mm()) continue;
                const auto &a = table->row(l, i), &b = exact->row(l, i);
                double peak = 0.0, receive_peak = 0.0, worst = 0.0, receive_worst = 0.0;
                for (std::size_t j = 0; j < b.h.size(); ++j) {
                    peak = std::max(peak, double(std::abs(b.h[j])));
                    receive_peak = std::max(receive_peak, double(b.receive_power[j]));
                    worst = std::max(worst, double(std::abs(a.h[j] - b.h[j])));
                    receive_worst = std::max(
                        receive_worst, double(std::abs(a.receive_power[j] - b.receive_power[j])));
                }
                h_error.push_back(worst / peak);
                receive_error.push_back(receive_worst / receive_peak);
                power_error.push_back(std::abs(10.0 * std::log10(a.power / b.power)));
            }
        auto quantile = [](std::vector<double> v, double q) {
            std::sort(v.begin(), v.end());
            return v[std::size_t(q * double(v.size() - 1))];
        };
        std::printf(
            "%s: %d rows computed of %d; H error p50 %.4f p99 %.4f max %.4f; power "
            "max %.3f dB; receive max %.4f\n",
            preset, table->computed_rows(), exact->computed_rows(), quantile(h_error, 0.5),
            quantile(h_error, 0.99), quantile(h_error, 1.0), quantile(power_error, 1.0),
            quantile(receive_error, 1.0));
        EXPECT_LT(quantile(h_error, 0.5), 0.02) << preset;
        EXPECT_LT(quantile(h_error, 0.99), 0.15) << preset;
        EXPECT_LT(quantile(h_error, 1.0), 0.85) << preset;
        EXPECT_LT(quantile(power_error, 1.0), 0.6) << preset;
        EXPECT_LT(quantile(receive_error, 1.0), 0.06) << preset;
    }
}

// Two optimisations that claim to change nothing, against the plain forms they replace:
// the sub-line weights kept per table row (PsfTable::sub_line_weights) are at_row at
// j d(z_i) for every line and depth index, and the speckle sums four sub-lines at a time
// equal one sub-line at a time, bit for bit.
TEST(Psf, SubLineWeightsAreTheRowsAtTheSubLineOffsets) {
    for (const char* preset : {"convex", "linear", "phased"}) {
        probe::Transducer t = probe::find_transducer(preset, "test");
        t.lines = 24;
        const auto psf = imaging::PsfTable::of(t);
        const probe::ScanGeometry geometry(t);
        for (int K : {1, 3}) {
            const auto w = psf->sub_line_weights(K);
            ASSERT_EQ(w->reach, 8 * K);
            long differing = 0;
            for (int l = 0; l < t.lines; ++l)
                for (int i = 0; i <= psf->depths(); ++i) {
                    const double d = std::max(geometry.line_spacing_mm(i * psf->dz()), 1e-6) / K;
                    for (int j = -w->reach; j <= w->reach; ++j) {
                        const std::complex<float> expected = psf->at_row(l, i, j * d);
                        differing += std::memcmp(&w->at(l, i)[j], &expected, sizeof expected) != 0;
                    }
                }
            EXPECT_EQ(differing, 0) << preset << ", K " << K;
        }
    }
}

// A line's receive sensitivity with its rows looked up once and its spacings' reciprocals
// multiplied (PsfTable::LineReceive, an optimisation that changes only the rounding)
// against the plain form with divisions: linear in depth between rows i = floor(z / dz)
// and i + 1, linear across within each row, 0 beyond a row's samples. Over points
// inside, at and beyond the rows' reach, within 1e-12 of the value (a few ulps of the
// interpolation weights; the interpolation is continuous but for the reach's edge, which
// random points do not hit).
TEST(Psf, LineReceiveIsTheRowsInterpolated) {
    probe::Transducer t = probe::find_transducer("convex", "test");
    t.lines = 16;
    const auto psf = imaging::PsfTable::of(t);
    auto plain = [&](int l, double x, double z) {
        const double u = std::clamp(z / psf->dz(), 0.0, double(psf->depths() - 1));
        const int i = std::min(int(u), psf->depths() - 2);
        const double f = u - i;
        auto across = [&](const imaging::PsfTable::Row& r) {
            const double v = x / r.dx + r.half;
            if (!(v >= 0.0) || v >= double(2 * r.half)) return 0.0;
            const auto j = std::size_t(v);
            const double g = v - double(j);
            return double(r.receive_power[j]) * (1.0 - g) + double(r.receive_power[j + 1]) * g;
        };
        return (1.0 - f) * across(psf->row(l, i)) + f * across(psf->row(l, i + 1));
    };
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> depth(-1.0, t.depth_mm + 5.0), across(-12.0, 12.0);
    long differing = 0, nonzero = 0;
    for (int l : {0, 7, 15}) {
        const imaging::PsfTable::LineReceive receive(*psf, l);
        for (int n = 0; n < 20000; ++n) {
            const double x = across(rng), z = depth(rng);
            const double expected = plain(l, x, z), got = receive.power(x, z);
            differing += !(std::abs(got - expected) <= 1e-12 * std::abs(expected));
            nonzero += expected != 0.0;
        }
    }
    EXPECT_EQ(differing, 0);
    EXPECT_GT(nonzero, 10000) << "most points should lie within the rows' reach";
}

// The speckle sums stop where the sub-line weights fall 50 dB below their peak
// (SubLineWeights::significant). A line's speckle intensity is the sum of |H_j|^2 over its
// sub-lines, so what is left out changes it by the weights' power beyond that reach: at
// most 1e-4 of the row's (-40 dB), on every row of the three presets.
TEST(Speckle, SubLinesBeyondTheFloorHoldNoVisiblePower) {
    for (const char* preset : {"convex", "linear", "phased"}) {
        probe::Transducer t = probe::find_transducer(preset, "test");
        t.lines = 16;
        const auto psf = imaging::PsfTable::of(t);
        const auto w = psf->sub_line_weights(3);
        double worst = 0.0;
        long trimmed = 0;
        for (int l = 0; l < t.lines; ++l)
            for (int i = 0; i <= psf->depths(); ++i) {
                const int reach = w->significant_reach(l, i);
                double kept = 0.0, dropped = 0.0;
                for (int j = -w->reach; j <= w->reach; ++j)
                    (std::abs(j) <= reach ? kept : dropped) += std::norm(w->at(l, i)[j]);
                worst = std::max(worst, dropped / std::max(kept + dropped, 1e-300));
                trimmed += reach < w->reach;
            }
        std::printf("%s: worst dropped power %.2e of a row's\n", preset, worst);
        EXPECT_LT(worst, 1e-4) << preset;
        EXPECT_GT(trimmed, 0) << preset << ": the floor should trim some rows";
    }
}

}  // namespace
}  // namespace sonotrace
