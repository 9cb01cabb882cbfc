#include "probe/transmit.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "probe/array_geometry.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/error.h"
#include "tissue/base/hash.h"
#include "tissue/base/number_list.h"

namespace sonotrace::probe {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;
// A scheme longer than this is a typing slip, not an acquisition (PICMUS uses 75).
constexpr int kMostTransmits = 10000;

std::vector<std::string> split(const std::string& text, char separator) {
    std::vector<std::string> parts;
    std::size_t start = 0;
    for (;;) {
        const std::size_t end = text.find(separator, start);
        parts.push_back(text.substr(start, end == std::string::npos ? end : end - start));
        if (end == std::string::npos) return parts;
        start = end + 1;
    }
}

// Angles in degrees: "A", "A,B,..." or "FROM:TO:N" (the parts after the kind).
std::vector<double> parse_angles(const std::vector<std::string>& parts, const std::string& source,
                                 const std::string& field) {
    std::vector<double> angles;
    if (parts.size() == 1) {
        if (auto error = base::parse_number_list(parts[0], &angles))
            throw base::InputError(source, field, "angles (degrees): " + *error);
    } else if (parts.size() == 3) {
        const auto from = base::finite_number(parts[0]), to = base::finite_number(parts[1]);
        if (!from || !to)
            throw base::InputError(source, field,
                                   "FROM:TO:N needs numbers for FROM and TO (degrees), got '" +
                                       parts[0] + "' and '" + parts[1] + "'");
        if (base::not_a_whole_number(parts[2]))
            throw base::InputError(
                source, field,
                "FROM:TO:N needs a whole number N of transmits, got '" + parts[2] + "'");
        const auto n = base::finite_number(parts[2]);
        if (!(*n >= 1.0))
            throw base::InputError(source, field, "zero transmits: N must be at least 1");
        if (*n > kMostTransmits)
            throw base::InputError(
                source, field,
                "N = " + parts[2] + " transmits; at most " + std::to_string(kMostTransmits));
        const int count = int(*n);
        for (int k = 0; k < count; ++k)
            angles.push_back(count == 1 ? *from : *from + (*to - *from) * k / (count - 1));
    } else {
        throw base::InputError(
            source, field, "angles are A, A,B,... or FROM:TO:N (degrees), got '" + [&] {
                std::string joined;
                for (std::size_t i = 0; i < parts.size(); ++i) {
                    if (i) joined += ':';
                    joined += parts[i];
                }
                return joined;
            }() + "'");
    }
    if (angles.empty()) throw base::InputError(source, field, "zero transmits: no angle given");
    if (angles.size() > std::size_t(kMostTransmits))
        throw base::InputError(source, field,
                               std::to_string(angles.size()) + " transmits; at most " +
                                   std::to_string(kMostTransmits));
    for (double a : angles) {
        if (!(std::abs(a) < 90.0))
            throw base::InputError(source, field,
                                   "angle " + base::number_text(a) +
                                       " degrees: a transmit must point into the tissue "
                                       "(|angle| < 90)");
    }
    return angles;
}

double sinc(double x) {
    return std::abs(x) < 1e-8 ? 1.0 : std::sin(x) / x;
}

// The element's directivity at f0 towards sin theta (probe/aperture.h's D).
double element_directivity(const Transducer& t, double sin_theta) {
    const double cos_theta = std::sqrt(std::max(0.0, 1.0 - sin_theta * sin_theta));
    return sinc(std::numbers::pi * t.element_width_mm * sin_theta / t.wavelength_mm()) * cos_theta;
}

}  // namespace

glm::dvec2 TransmitWave::virtual_source() const {
    return {-source_distance_mm * std::sin(angle_rad), -source_distance_mm * std::cos(angle_rad)};
}

std::string TransmitWave::label() const {
    char text[64];
    if (kind == Kind::plane)
        std::snprintf(text, sizeof text, "plane %.2f deg", angle_rad / kDegree);
    else
        std::snprintf(text, sizeof text, "diverging %.3g mm, %.2f deg", source_distance_mm,
                      angle_rad / kDegree);
    return text;
}

TransmitScheme parse_transmit_scheme(const std::string& text, const std::string& source,
                                     const std::string& field) {
    const std::vector<std::string> parts = split(text, ':');
    const std::string& kind = parts[0];
    TransmitScheme scheme;
    scheme.text = text;
    if (kind == "plane") {
        if (parts.size() < 2)
            throw base::InputError(source, field,
                                   "plane needs its angles: plane:A, plane:A,B,... or "
                                   "plane:FROM:TO:N (degrees)");
        for (double a : parse_angles({parts.begin() + 1, parts.end()}, source, field))
            scheme.waves.push_back({TransmitWave::Kind::plane, a * kDegree, 0.0});
    } else if (kind == "diverging") {
        if (parts.size() < 2)
            throw base::InputError(source, field,
                                   "diverging needs the virtual source's distance behind the "
                                   "face: diverging:D or diverging:D:ANGLES (mm, degrees)");
        const auto distance = base::finite_number(parts[1]);
        if (!distance)
            throw base::InputError(
                source, field,
                "the virtual source's distance must be a number (mm), got '" + parts[1] + "'");
        if (!(*distance > 0.0))
            throw base::InputError(source, field,
                                   "the virtual source must lie behind the face (distance > 0 "
                                   "mm), got " +
                                       base::number_text(*distance) +
                                       " mm: a source in front of the array is a focused "
                                       "transmit");
        const std::vector<double> angles =
            parts.size() == 2 ? std::vector<double>{0.0}
                              : parse_angles({parts.begin() + 2, parts.end()}, source, field);
        for (double a : angles)
            scheme.waves.push_back({TransmitWave::Kind::diverging, a * kDegree, *distance});
    } else {
        throw base::InputError(
            source, field,
            "unknown transmit '" + kind + "' (plane:ANGLES or diverging:DISTANCE[:ANGLES])");
    }
    return scheme;
}

std::vector<std::string> validate_transmit_scheme(const TransmitScheme& scheme, const Transducer& t,
                                                  const std::string& source,
                                                  const std::string& field) {
    if (scheme.empty()) throw base::InputError(source, field, "zero transmits");
    if (!array_type(t.type).unfocused_transmits)
        throw base::InputError(source, field,
                               "plane and diverging waves need an open array (linear, phased or "
                               "convex); the probe is " +
                                   to_string(t.type));
    // Every element's ray, from its normal: forwards, and within the grating-lobe limit.
    const std::vector<double> elements = element_arc_mm(t);
    double worst = 0.0;
    for (std::size_t k = 0; k < scheme.waves.size(); ++k) {
        const TransmitField wave(t, scheme.waves[k]);
        for (double s : elements) {
            const TransmitField::Ray ray = wave.ray_from(s);
            if (!(ray.cos_angle > 1e-6))
                throw base::InputError(
                    source, field,
                    "transmit " + std::to_string(k + 1) + " (" + scheme.waves[k].label() +
                        ") would leave the element " + base::number_text(s) +
                        " mm along the face at " +
                        base::number_text(std::atan2(ray.sin_angle, ray.cos_angle) / kDegree) +
                        " degrees from its normal: every element's ray must head into the "
                        "tissue (a virtual source behind each element, a plane wave within 90 "
                        "degrees of each normal)");
            worst = std::max(worst, std::abs(std::asin(std::clamp(ray.sin_angle, -1.0, 1.0))));
        }
    }
    // The first grating lobe at f0 lies at sin theta - lambda / pitch; past the limit it
    // comes within the element's -6 dB directivity.
    const double ratio = t.wavelength_mm() / t.pitch_mm;
    std::vector<std::string> warnings;
    const double lobe = std::sin(worst) - ratio;
    if (lobe > -1.0 && element_directivity(t, lobe) > 0.5) {
        warnings.push_back(field + ": rays at " + base::number_text(worst / kDegree) +
                           " degrees send a grating lobe towards " +
                           base::number_text(std::asin(lobe) / kDegree) +
                           " degrees within the elements' -6 dB directivity (pitch " +
                           base::number_text(t.pitch_mm) + " mm, wavelength " +
                           base::number_text(t.wavelength_mm()) + " mm)");
    }
    return warnings;
}

std::vector<double> element_arc_mm(const Transducer& t) {
    std::vector<double> s(std::size_t(t.elements));
    for (int i = 0; i < t.elements; ++i)
        s[std::size_t(i)] = (i - 0.5 * (t.elements - 1)) * t.pitch_mm;
    return s;
}

std::vector<ArrayPoint> element_points(const Transducer& t) {
    const std::unique_ptr<const ArrayGeometry> geometry = array_geometry(t);
    std::vector<ArrayPoint> points;
    for (double s : element_arc_mm(t)) points.push_back(geometry->face(s));
    return points;
}

double launch_arc_mm(const Transducer& t, int count, int i) {
    const double half = 0.5 * t.array_length_mm();
    return -half + 2.0 * half * (i + 0.5) / std::max(1, count);
}

TransmitField::TransmitField(const Transducer& t, const TransmitWave& wave)
    : wave_(wave),
      geometry_(array_geometry(t)),
      plane_heading_(std::sin(wave.angle_rad), std::cos(wave.angle_rad)),
      apodization_(t.tx_apodization),
      half_span_(0.5 * t.array_length_mm()),
      pitch_(t.pitch_mm),
      lambda0_(t.wavelength_mm()) {
    const std::vector<double> s = element_arc_mm(t);
    delays_.resize(s.size());
    weights_.resize(s.size());
    for (std::size_t i = 0; i < s.size(); ++i) {
        delays_[i] = at(geometry_->face(s[i]).position).time_s;
        weights_[i] = apodization_weight(apodization_, (double(i) + 0.5) / double(s.size()));
    }
}

double TransmitField::aperture_weight(double s) const {
    return apodization_weight(apodization_, (s + half_span_) / (2.0 * half_span_));
}

TransmitField::Ray TransmitField::ray_from(double s) const {
    const ArrayPoint f = geometry_->face(s);
    Ray ray;
    ray.origin = f.position;
    ray.direction = wave_.kind == TransmitWave::Kind::plane
                        ? plane_heading_
                        : glm::normalize(f.position - wave_.virtual_source());
    ray.sin_angle = ray.direction.x * f.normal.y - ray.direction.y * f.normal.x;
    ray.cos_angle = glm::dot(ray.direction, f.normal);
    return ray;
}

TransmitField::Arrival TransmitField::at(const glm::dvec2& r) const {
    constexpr double c0_mm_per_s = tissue::kReferenceSpeed * 1e3;
    Arrival a;
    glm::dvec2 heading;
    glm::dvec2 v(0.0);
    if (wave_.kind == TransmitWave::Kind::plane) {
        heading = plane_heading_;
        a.time_s = glm::dot(r, heading) / c0_mm_per_s;
    } else {
        v = wave_.virtual_source();
        const double to_r = glm::length(r - v);
        a.time_s = (to_r - glm::length(v)) / c0_mm_per_s;
        if (!(to_r > 0.0)) return a;
        heading = (r - v) / to_r;
    }
    // The ray through r, back to the face (header: s*, theta*).
    const std::optional<double> crossing = geometry_->face_crossing(r, heading);
    if (!crossing) return a;
    const double s = *crossing;
    const Ray ray = ray_from(s);
    const double in_front = glm::dot(r - ray.origin, heading);
    if (!(in_front > 0.0) || !(ray.cos_angle > 0.0)) return a;
    a.sin_angle = ray.sin_angle;
    double effective_range = in_front;
    if (wave_.kind == TransmitWave::Kind::diverging) {
        const double behind = glm::dot(ray.origin - v, heading);
        if (!(behind > 0.0)) return a;
        a.spreading = behind / (behind + in_front);
        effective_range = behind * in_front / (behind + in_front);
    }
    // The apodization at the nearer end continues past it, where the edge step fades.
    const double u = std::clamp((s + half_span_) / (2.0 * half_span_), 0.0, 1.0);
    const double weight = apodization_weight(apodization_, u);
    if (!(weight > 0.0)) return a;
    // The aperture's ends: a step over a Fresnel zone, in the Fresnel parameter of the
    // distance inside the nearer end (header).
    const double fresnel = ray.cos_angle * std::sqrt(2.0 / (lambda0_ * effective_range));
    const double inside = std::min(s + half_span_, half_span_ - s) * fresnel;
    const double edge = 0.5 * std::erfc(-std::sqrt(std::numbers::pi) * inside);
    a.amplitude = weight * edge * std::sqrt(lambda0_ * a.spreading) / pitch_;
    return a;
}

Sources<2> transmit_sources(const Transducer& t, const TransmitScheme& scheme, int count,
                            const glm::dvec2& to_map) {
    Sources<2> sources;
    const int n = std::max(1, count);
    sources.reserve(scheme.waves.size() * std::size_t(n));
    for (std::size_t w = 0; w < scheme.waves.size(); ++w) {
        const TransmitField field(t, scheme.waves[w]);
        for (int i = 0; i < n; ++i) {
            const TransmitField::Ray ray = field.ray_from(launch_arc_mm(t, n, i));
            SourceParticle<2> p;
            p.position = glm::vec2(ray.origin + to_map);
            p.direction = glm::vec2(ray.direction);
            p.energy = 1.0f / float(n);
            p.line = uint32_t(w);
            p.time_s = float(field.at(ray.origin).time_s);
            sources.push_back(p);
        }
    }
    return sources;
}

}  // namespace sonotrace::probe
