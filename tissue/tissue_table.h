#pragma once
// Literature values for the tissues sonotrace knows by name. Units: speed of sound m/s,
// density kg/m^3, attenuation dB/(cm·MHz) (intensity, at body temperature), backscatter
// relative 0..1, scatterer density 1/mm^3, roughness 0..1 (see acoustic_properties.h).
#include <span>
#include <string>
#include <string_view>

#include "tissue/acoustic_properties.h"

namespace sonotrace::tissue {

struct TissueEntry {
    std::string_view key;   // name used in JSON files ("liver")
    std::string_view name;  // human name
    AcousticProperties properties;
    std::string_view source;  // where the speed, density and attenuation come from
};

std::span<const TissueEntry> tissue_table();
// Throws base::InputError(source, field, ...) listing the known names if `key` is unknown.
const TissueEntry& find_tissue(std::string_view key, const std::string& source,
                               const std::string& field);

}  // namespace sonotrace::tissue
