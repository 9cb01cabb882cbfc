#pragma once
// The speckle of many apertures on one array at once (what the PSF table's computed rows
// take, imaging/psf.h). Lines whose arrays look the same from them (linear and convex
// lines at one sub-element offset) differ only in the weights their apertures give the
// elements: the clipping by the array's ends and the receive's growth with depth. The
// term of element e at a point q and frequency f_m,
//
//   D_e,m(q) exp(-i k_m (|q - p_e| - |p_e| - q_y)) / sqrt(|q - p_e|),
//
// is the same for all of them and for the transmit and the receive, which differ only in
// the focusing delays exp(-i k_m (|p_e| - |f - p_e| + f_y)) to their focus f: together
// LineFields::sum's phase |q - p_e| - |f - p_e| + f_y - q_y. The terms are computed once
// per point (the sums' directivity, spreading and phasors: most of their cost) and each
// aperture's sums are a weighted sum of them. Test: Psf.RowsFromSharedTermsEqualEachLinesOwnSums
// (every computed row of the PSF table against LineFields::speckle of its line).
#include <complex>
#include <vector>

#include <glm/glm.hpp>

#include "probe/aperture.h"

namespace sonotrace::probe {

class ApertureTerms {
  public:
    // The elements [first, last) of `fields`' array, the transmit focused where `fields`
    // focuses it and the receive at depth `receive_focus_mm` on the axis.
    ApertureTerms(const LineFields& fields, int first, int last, double receive_focus_mm);
    // An aperture to sum at every point: its weights (one per element of the array, 0
    // outside [first, last)) and norm. Returns its number (equal apertures are one).
    int add_transmit(const std::vector<double>& weights, double norm);
    int add_receive(const std::vector<double>& weights, double norm);
    // The terms at q (line frame, mm), and every aperture's sums there.
    void at(const glm::dvec2& q);
    // The speckle (LineFields::speckle) of a transmit and a receive aperture at the last
    // point.
    LineFields::Speckle speckle(int transmit, int receive) const;

  private:
    const LineFields& fields_;
    int first_ = 0, count_ = 0, stride_ = 0, frequencies_ = 0;
    // Per frequency m and element: the focusing delays' phasors (transmit, receive) and
    // the terms at the last point times each ([m * stride + e]).
    std::vector<float> tx_re_, tx_im_, rx_re_, rx_im_;
    std::vector<float> terms_[4];  // transmit re, im; receive re, im
    std::vector<float> x_, y_, nx_, ny_, ones_;
    // An aperture's weights on elements [first, first + w.size()) of the span, padded
    // with zero weights to whole lanes.
    struct Aperture {
        std::vector<float> w;
        int first = 0;
        double norm = 1.0;
    };
    int add(std::vector<Aperture>& apertures, const std::vector<double>& weights, double norm);
    std::vector<Aperture> transmits_, receives_;
    std::vector<std::complex<double>> sums_[2];  // transmit, receive: [aperture * M + m]
};

}  // namespace sonotrace::probe
