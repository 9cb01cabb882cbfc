#pragma once
// Unfocused transmits of an open array (linear, phased, convex): steered plane waves and
// diverging waves from a virtual source behind the array, the modes of ultrafast imaging.
// Each is a type with its equations beside it, in the probe plane (x along the array,
// y = z into the tissue, origin at the face's centre or the arc's apex; the elements at
// p_i on the face, facing n_i: probe/array_geometry.h).
//
// Element i fires at d_i, the time the transmit's ideal wave passes it, and radiates (the
// aperture model's element, probe/aperture.h) a_i D(theta, f) exp(-i 2 pi f (d_i + R_i /
// c0)) / sqrt(R_i) to a point r at R_i = |r - p_i|, D = sinc(pi w f sin theta / c0) cos
// theta, theta from n_i. By stationary phase the element sum is one wave (the arrivals of
// the elements at r spread no further than the pulse):
//
//   sum_i ... = (a(s*) / pitch) sinc(pi w f sin theta* / c0) sqrt(lambda_f G)
//               exp(-i pi / 4) exp(-i 2 pi f tau(r)),
//
// s* the arc length of the face point whose ray passes through r, theta* that ray's
// angle from the normal there, G a geometric factor (plane: 1; diverging: R2 / (R1 +
// R2), R2 = |p(s*) - v| behind the face, R1 = |r - p(s*)| in front), tau(r) the arrival
// time of the ideal wave:
//
//   plane, direction k = (sin theta, cos theta):  tau = r . k / c0
//   diverging, source v:                         tau = (|r - v| - |v|) / c0
//
// The path's second derivative along the face at s* is cos^2 theta* (1 / R1 + 1 / R2)
// whatever the face's curvature (the curvature's terms of the two legs cancel where they
// are collinear), so a convex array's sum is the flat one's with its own s* and theta*.
// Time zero is the instant the wave passes the face's centre (a plane wave) or would pass
// it (a diverging wave). The sqrt(lambda_f) exp(-i pi / 4), a half-integration of the
// pulse, is the same for every point and goes into the waveform the channel data are
// made with (imaging/channel_data.h). The aperture's ends are a smooth step over a
// Fresnel zone (0.5 at the geometric boundary, 0.99 a zone inside it); the edge waves
// they also send, pulses of their own later arrival, are not modelled
// (test: ChannelData.PointEchoesMatchTheElementByElementSum measures what that leaves).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "probe/array_geometry.h"
#include "probe/source_particle.h"
#include "probe/transducer.h"

namespace sonotrace::probe {

struct TransmitWave {
    enum class Kind { plane, diverging };
    Kind kind = Kind::plane;
    // Plane: the steering angle from the normal (rad, positive towards +x). Diverging: the
    // direction of the virtual source's axis, the source at `source_distance_mm` behind the
    // face's centre along it.
    double angle_rad = 0.0;
    double source_distance_mm = 0.0;
    glm::dvec2 virtual_source() const;  // diverging: (-b sin a, -b cos a)
    std::string label() const;          // "plane 10.0 deg", "diverging 20 mm, 0.0 deg"
};

// A list of transmits, in firing order.
struct TransmitScheme {
    std::vector<TransmitWave> waves;
    bool empty() const { return waves.empty(); }
    // The text `parse_transmit_scheme` reads back to this scheme ("plane:-16:16:75").
    std::string text;
};

// The syntax of --transmit (the CLI's help shows this):
//   plane:A            one plane wave at A degrees
//   plane:A,B,...      a list of angles (degrees)
//   plane:FROM:TO:N    N angles evenly from FROM to TO (degrees; N >= 1; N = 1: FROM)
//   diverging:D        one diverging wave, virtual source D mm behind the face's centre
//   diverging:D:ANGLES the same, its axis steered by each angle (list or FROM:TO:N)
// Throws base::InputError(source, field): unknown kind, a malformed or empty list, zero
// transmits, an angle beyond 90 degrees, a virtual source not behind the face (D <= 0).
TransmitScheme parse_transmit_scheme(const std::string& text, const std::string& source,
                                     const std::string& field);

// The checks that need the array: only open arrays (ArrayType::unfocused_transmits) take
// these transmits, and every element's ray must leave it forwards (a virtual source
// behind each element, a plane wave within 90 degrees of each normal); throws
// base::InputError(source, field). Returns warnings (rays past the grating-lobe limit of
// the array at f0 from their element's normal: sin theta > lambda / pitch - 1).
std::vector<std::string> validate_transmit_scheme(const TransmitScheme& scheme, const Transducer& t,
                                                  const std::string& source,
                                                  const std::string& field);

// The elements' arc lengths along the face from its centre (mm; a flat array's x), in
// order, and their places and normals.
std::vector<double> element_arc_mm(const Transducer& t);
std::vector<ArrayPoint> element_points(const Transducer& t);

// Where the i-th of `count` particles of a transmit leaves the face (arc length, mm): the
// middles of equal cells along it.
double launch_arc_mm(const Transducer& t, int count, int i);

// One transmit on one array: the elements' delays and where its wave reaches.
class TransmitField {
  public:
    TransmitField(const Transducer& t, const TransmitWave& wave);
    // d_i (s): element i fires when the ideal wave passes it.
    const std::vector<double>& delays_s() const { return delays_; }
    const std::vector<double>& apodization() const { return weights_; }
    // The wave at r (probe plane, mm): its arrival time tau (s), the frequency-independent
    // part of its amplitude (a(s*) sqrt(lambda0 G) / pitch times the aperture's edge step;
    // 0 where no element's ray reaches r), sin theta* (the transmit directivity's
    // argument is pi w f sin theta* / c0) and the spreading G.
    struct Arrival {
        double time_s = 0.0;
        double amplitude = 0.0;
        double sin_angle = 0.0;
        double spreading = 1.0;
    };
    Arrival at(const glm::dvec2& r) const;
    // at(r).spreading alone (1 for a plane wave, without tracing its ray back).
    double spreading(const glm::dvec2& r) const {
        return wave_.kind == TransmitWave::Kind::plane ? 1.0 : at(r).spreading;
    }
    // The ray that leaves the face at arc length s: its origin, direction, and the sine
    // of its angle from the face's normal there (positive turning from the normal
    // towards +x, as a plane wave's steering angle).
    struct Ray {
        glm::dvec2 origin{0.0}, direction{0.0, 1.0};
        double sin_angle = 0.0, cos_angle = 1.0;
    };
    Ray ray_from(double s) const;
    // The apodization a(s) at s mm along the face (0 beyond the array).
    double aperture_weight(double s) const;
    const TransmitWave& wave() const { return wave_; }
    const ArrayGeometry& geometry() const { return *geometry_; }

  private:
    TransmitWave wave_;
    std::shared_ptr<const ArrayGeometry> geometry_;
    glm::dvec2 plane_heading_{0.0, 1.0};  // a plane wave's direction (sin, cos of its angle)
    std::vector<double> delays_, weights_;
    Apodization apodization_;
    double half_span_ = 0.0, pitch_ = 0.0, lambda0_ = 0.0;
};

// The particles of every transmit for the tracer (line id = transmit index): `count` each,
// at launch_arc_mm (not jittered: their reflections' coherent sum is a quadrature over
// the wavefront, which cancels away from the specular direction only on a regular grid;
// jittered, a reflector tilted 20 degrees imaged 60 dB too bright:
// ChannelFrames.AnObliqueReflectorImagesAsItsImageSources),
// each heading along its ray (TransmitField::ray_from) with its clock starting at its
// place's firing time, energy 1 / count;
// shifted by `to_map` into the tracer's map frame. Each stands for array length / count
// mm of the wavefront as it leaves (what a reflection's secondary source is weighted by:
// imaging/channel_frame.h).
Sources<2> transmit_sources(const Transducer& t, const TransmitScheme& scheme, int count,
                            const glm::dvec2& to_map);

}  // namespace sonotrace::probe
