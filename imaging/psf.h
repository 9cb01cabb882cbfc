#pragma once
// The two-way point-spread functions of a transducer's scan lines (probe/aperture.h),
// tabulated once per probe set-up: for every line, rows at depths dz apart of
// H(x, z) = T R across the line, x = j dx(z) for |j| <= J, where dx(z) is a quarter of
// the receive beam's main lobe lambda max(F_rx(z), 1/2) (so every row holds +-6 lobes).
// Lines whose array looks the same from them (linear and convex lines at the same
// sub-element offset, with the same clipping by the array's ends) share rows.
//
// The image formation reads from it the lateral weights of the speckle, the response of
// planar reflectors and the lateral power integral |H|^2 dx that sets the mean speckle
// level at each depth (brighter at the focus, where the two-way beam is narrowest).
#include <complex>
#include <memory>
#include <vector>

#include "probe/source_particle.h"
#include "probe/transducer.h"
#include "simulator/trace_settings.h"

namespace sonotrace::imaging {

class PsfTable {
  public:
    // The table of `t` (computed on first use, kept for the next frames of the same
    // probe set-up).
    static std::shared_ptr<const PsfTable> of(const probe::Transducer& t);

    struct Row {
        double dx = 0.0;                     // lateral spacing (mm)
        int half = 0;                        // J: samples j = -J .. J
        std::vector<std::complex<float>> h;  // H at x = (j - J) dx... index j + J
        std::vector<float> receive_power;    // |R|^2 at the same x
        double power = 0.0;                  // sum |H|^2 dx (1/mm)
    };

    double dz() const { return dz_; }
    int depths() const { return depths_; }
    // The row of line l at depth index i (z = i dz), i clamped to the table.
    const Row& row(int l, int i) const;
    // H of line l at (x, z) (line frame, mm): linear in depth between rows and across
    // within them; 0 beyond a row's reach.
    std::complex<float> at(int l, double x, double z) const;
    // Lateral power integral at depth z (1/mm), linear between rows.
    double power(int l, double z) const;
    // The receive sensitivity |R|^2 of line l at (x, z) (1/mm; linear between rows and
    // samples, 0 beyond a row's reach).
    double receive_power(int l, double x, double z) const;
    // The lateral power integral on the central line at the transmit focus: speckle is
    // calibrated there (its level at other depths follows the ratio).
    double focal_power() const { return focal_power_; }

  private:
    friend struct PsfTableBuilder;
    double dz_ = 1.0, k_ = 0.0;
    int lines_ = 0, depths_ = 0;
    double focal_power_ = 1.0;
    std::vector<Row> rows_;
    std::vector<int> row_of_;  // [line * depths + i] -> rows_
};

// The receive weight of every particle of `sources` (map frame; the probe face centre at
// `face_in_map`) by its one-way time: |R|^2 at the point its path
// reaches at that time if it went on straight from launch (for a reflected or refracted
// particle, by reciprocity, where its echo seems to come from), over the energy-weighted
// mean of the same over the line's particles at that range. A reflector or tissue
// across the whole beam averages the weights to 1; a target smaller than the beam echoes
// on the lines whose receive sees it.
std::shared_ptr<const simulator::ReceiveWeights> receive_weights(const probe::Transducer& t,
                                                                 const probe::Sources<2>& sources,
                                                                 const glm::dvec2& face_in_map);

}  // namespace sonotrace::imaging
