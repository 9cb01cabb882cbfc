#pragma once
// The acoustic properties a transfer function assigns to tissue. Each property is
// documented once here (key, unit, valid range, meaning); the JSON parsers, the CLI
// help, the sidecars and the README table all read this list.
#include <array>
#include <cstddef>
#include <string_view>

namespace sonotrace::tissue {

enum class Property : int {
    speed_of_sound = 0,  // m/s
    density,             // kg/m^3
    attenuation,         // dB/(cm·MHz)
    backscatter,         // relative, 0..1
    scatterer_density,   // scatterers per mm^3
    roughness,           // 0 (mirror) .. 1 (fully diffuse)
};
inline constexpr std::size_t kPropertyCount = 6;

struct PropertyInfo {
    std::string_view key;    // JSON key and output file stem
    std::string_view label;  // for plots and help
    std::string_view unit;
    double min, max;  // accepted range
    std::string_view description;
};

inline constexpr std::array<PropertyInfo, kPropertyCount> kPropertyInfo = {{
    {"speed_of_sound", "speed of sound", "m/s", 100.0, 6000.0,
     "longitudinal sound speed; sets refraction (Snell) and the echo delays"},
    {"density", "density", "kg/m^3", 0.1, 25000.0,
     "mass density; with the speed of sound gives the impedance Z = rho*c"},
    {"attenuation", "attenuation", "dB/(cm*MHz)", 0.0, 100.0,
     "intensity attenuation slope, applied as alpha*f (linear in frequency)"},
    {"backscatter", "backscatter", "relative 0..1", 0.0, 1.0,
     "echogenicity of sub-resolution scatterers (0 anechoic .. 1 strongest); a relative "
     "ranking, not a measured backscatter coefficient"},
    {"scatterer_density", "scatterer density", "1/mm^3", 0.0, 1000.0,
     "sub-resolution scatterers per mm^3; above ~10 per resolution cell speckle is fully "
     "developed"},
    {"roughness", "interface roughness", "0..1", 0.0, 1.0,
     "0 reflects like a mirror, 1 reflects fully diffusely (sets the cos^c lobe width)"},
}};

inline const PropertyInfo& info(Property p) {
    return kPropertyInfo[std::size_t(p)];
}

// Derived quantity shown alongside the properties.
inline constexpr std::string_view kImpedanceUnit = "MRayl";  // 1 MRayl = 1e6 kg/(m^2 s)

// Energy loss per mm (natural log) of an attenuation of `db_per_cm_mhz` dB/(cm MHz) at
// `frequency_mhz`: intensity falls as exp(-this x path).
inline double attenuation_per_mm(double db_per_cm_mhz, double frequency_mhz) {
    return db_per_cm_mhz * frequency_mhz * 0.1 * 0.23025850929940458;  // dB -> ln: ln 10 / 10
}

struct AcousticProperties {
    std::array<float, kPropertyCount> values{};

    float& operator[](Property p) { return values[std::size_t(p)]; }
    float operator[](Property p) const { return values[std::size_t(p)]; }
    // Characteristic acoustic impedance Z = rho * c in MRayl.
    double impedance_mrayl() const {
        return double((*this)[Property::density]) * (*this)[Property::speed_of_sound] * 1e-6;
    }
};

// Linear blend a*(1-t) + b*t of every property.
AcousticProperties lerp(const AcousticProperties& a, const AcousticProperties& b, float t);

}  // namespace sonotrace::tissue
