#pragma once
// Channel data: the RF each element of an open array receives after each unfocused
// transmit (probe/transmit.h), transmit x element x sample, float32, as a scanner's
// ultrafast mode records it before any beamforming.
//
// An echo source at r (probe plane, mm) of strength sigma (mm: the echo it sends back per
// unit pressure arriving, as an element's own radiation) lit by transmit w gives element
// e at p_e, at frequency f of the pulse-echo spectrum S(f) (probe/pulse.h),
//
//   E_e(f) = S(f) sigma T_w(r, f) D(theta_e, f) exp(-i 2 pi f R_e / c0) / sqrt(R_e)
//
// with T_w the transmit's wave at r (its element sum by stationary phase,
// probe/transmit.h), R_e = |r - p_e| (element e at p_e facing n_e), theta_e the angle of
// the way back from n_e (no echo where it is 90 degrees or more) and D = sinc(pi w f sin theta /
// c0) cos theta the element's directivity (probe/aperture.h): the aperture model's element, applied
// element by element. The channel's RF is Re sum_f E_e(f) exp(i 2 pi f t).
//
// How it is computed, and what that approximates:
//   - the two directivities' product is a quadratic in f / f0 - 1 through its values at
//     f0 and at the -6 dB band edges, so each echo is three complex amplitudes per
//     element, convolved once per channel with the waveforms S(f) sqrt(f0 / f) exp(-i pi /
//     4) (f / f0 - 1)^j, j = 0, 1, 2 (the transmit's half-integration: probe/transmit.h);
//   - each amplitude is split between the two samples around its arrival time with the
//     carrier's phase at each (so the carrier is exact and the envelope's centroid is at
//     the arrival; its shape is off by the second order of the sample fraction).
// Their error against the sum over every transmit element and frequency is measured in
// tests/imaging/channel_data_test.cpp.
#include <complex>
#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "probe/transducer.h"
#include "probe/transmit.h"
#include "tissue/acoustic_map.h"

namespace sonotrace::imaging {

// The speed of sound the channels' delays take (tissue::kReferenceSpeed), in mm/s.
inline constexpr double kC0MmPerS = tissue::kReferenceSpeed * 1e3;

// A point that echoes: where it is (probe plane, mm), its strength sigma (mm^1/2, may
// carry a phase: a 2D scatterer of backscatter width w has |sigma| = sqrt(w / (2 pi))),
// and any delay of its path beyond the straight ways at c0 (s, both ways together).
//
// An echo the transmit's particles carried to its place themselves (a reflection the
// tracer recorded: imaging/channel_frame.h) is `lit`: its transmit arrival time and the
// direction its particle left the array are given, its strength holds the transmit's
// amplitude, and it is one of the secondary sources whose sum over a reflector makes the
// reflected wave. That sum (stationary phase along the reflector) is itself a
// half-integration, so lit echoes take the pulse without the transmit's (header).
struct ChannelEcho {
    glm::dvec2 position{0.0};
    std::complex<double> strength = 1.0;
    double extra_delay_s = 0.0;
    struct Lit {
        double arrival_s = 0.0;           // after the transmit's time zero
        double transmit_sin_angle = 0.0;  // of the particle's launch, from the normal
        // A facet: the piece of a smooth surface the echo stands for
        // (imaging/coherent_surfaces.h), whose Kirchhoff integral sends element e
        // sinc(pi f w (d - u_e) . t / c0) times a point's echo: d the incident direction,
        // u_e the unit way to the element, t the tangent. Width 0: a point.
        double facet_mm = 0.0;
        glm::dvec2 tangent{1.0, 0.0};
        glm::dvec2 incident{0.0, 1.0};
    };
    std::optional<Lit> lit;
};

// Parameters of a channel-data acquisition:
//   sampling_mhz  (MHz, default 0 = 4 x the centre frequency): the channels' sampling rate
//   start_us      (us, default 0): the time of sample 0 after the transmit's time zero
//   depth_mm      (mm, default 0 = the transducer's depth): the deepest point whose echo
//                 each channel holds, from every element and every transmit
struct ChannelSettings {
    double sampling_mhz = 0.0;
    double start_us = 0.0;
    double depth_mm = 0.0;
};

struct ChannelData {
    int transmits = 0, elements = 0, samples = 0;
    double fs_hz = 0.0;
    double start_s = 0.0;       // time of sample 0 after the transmit's time zero
    double speed_m_s = 0.0;     // c0 the delays are computed with
    double frequency_hz = 0.0;  // centre frequency
    double pitch_mm = 0.0;
    std::vector<double> element_s_mm;               // arc length along the face (a flat array's x)
    std::vector<probe::ArrayPoint> element_points;  // place and normal, probe plane (mm)
    std::vector<probe::TransmitWave> waves;         // one per transmit
    std::vector<std::vector<double>> delays_s;      // [transmit][element]: firing times
    std::vector<float> values;                      // [(w * elements + e) * samples + n]
    float at(int w, int e, int n) const { return values[index(w, e, n)]; }
    const float* channel(int w, int e) const { return values.data() + index(w, e, 0); }
    float* channel(int w, int e) { return values.data() + index(w, e, 0); }
    double time_s(double n) const { return start_s + n / fs_hz; }

  private:
    std::size_t index(int w, int e, int n) const {
        return (std::size_t(w) * std::size_t(elements) + std::size_t(e)) * std::size_t(samples) +
               std::size_t(n);
    }
};

// The sampling of an acquisition: rate, start, and samples enough for the round trip to
// `depth` from every element and transmit (and the pulse's tail); values empty.
ChannelData channel_layout(const probe::Transducer& t, const probe::TransmitScheme& scheme,
                           const ChannelSettings& settings);

// Bytes the channel data of a layout take.
inline double channel_bytes(const ChannelData& layout) {
    return double(layout.transmits) * layout.elements * layout.samples * sizeof(float);
}

// The channel data of `echoes` under every transmit of `scheme` (header).
ChannelData channel_data(const probe::Transducer& t, const probe::TransmitScheme& scheme,
                         const std::vector<ChannelEcho>& echoes, const ChannelSettings& settings);
// The same with each transmit's own echoes (asked for once per transmit, in order).
using TransmitEchoes = std::function<std::vector<ChannelEcho>(int transmit)>;
ChannelData channel_data(const probe::Transducer& t, const probe::TransmitScheme& scheme,
                         const TransmitEchoes& echoes, const ChannelSettings& settings);

}  // namespace sonotrace::imaging
