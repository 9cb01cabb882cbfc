#include "tissue/tissue_table.h"

#include <array>

#include "tissue/base/error.h"

namespace sonotrace::tissue {

namespace {

constexpr AcousticProperties props(float c, float rho, float alpha, float backscatter,
                                   float scatterers, float roughness) {
    return AcousticProperties{{c, rho, alpha, backscatter, scatterers, roughness}};
}

// Speed, density and attenuation: F. A. Duck, "Physical Properties of Tissue" (1990),
// and the IT'IS Foundation tissue database v4.1 (2022), body temperature. Attenuation
// slopes are for intensity. Water and CSF attenuate as f^2 in reality; the slope given
// is the value at ~1 MHz. Backscatter, scatterer density and roughness follow the
// usual echogenicity ranking of clinical images (fluids anechoic, fat and muscle
// hypoechoic, parenchyma mid-grey, bone bright); they are modelling choices, not
// measurements.
constexpr std::array<TissueEntry, 14> kTable = {{
    //                                     c     rho    alpha  bsc   n/mm3  rough
    {"water", "water (37 C)", props(1524, 993, 0.0022f, 0.0f, 0.0f, 0.0f), "Duck 1990"},
    {"blood", "blood", props(1584, 1060, 0.15f, 0.02f, 5.0f, 0.0f), "Duck 1990; IT'IS 4.1"},
    {"fat", "fat", props(1450, 950, 0.6f, 0.25f, 10.0f, 0.3f), "Duck 1990; IT'IS 4.1"},
    {"muscle", "skeletal muscle", props(1580, 1070, 1.1f, 0.3f, 15.0f, 0.3f), "Duck 1990"},
    {"liver", "liver", props(1578, 1060, 0.5f, 0.5f, 20.0f, 0.2f), "Duck 1990; IT'IS 4.1"},
    {"kidney", "kidney", props(1560, 1050, 1.0f, 0.4f, 20.0f, 0.2f), "Duck 1990; IT'IS 4.1"},
    {"brain", "brain (grey/white average)", props(1560, 1040, 0.6f, 0.35f, 15.0f, 0.2f),
     "Duck 1990; IT'IS 4.1"},
    {"csf", "cerebrospinal fluid", props(1515, 1007, 0.0022f, 0.0f, 0.0f, 0.0f),
     "IT'IS 4.1 (water-like)"},
    {"cortical_bone", "cortical bone (skull)", props(3500, 1900, 20.0f, 1.0f, 5.0f, 0.5f),
     "Duck 1990 (cortical 3500-4000 m/s, ~20 dB/cm/MHz)"},
    {"air", "air (20 C)", props(343, 1.2f, 1.6f, 0.0f, 0.0f, 0.0f),
     "Kaye & Laby (attenuation ~1.6 dB/cm at 1 MHz)"},
    {"soft_tissue", "generic soft tissue", props(1540, 1060, 0.54f, 0.4f, 15.0f, 0.2f),
     "IEC 61391 / AIUM phantom convention (1540 m/s, 0.5-0.7 dB/cm/MHz)"},
    // Membranes a T1 MRI shows as CSF or brain; placed by anatomy (imaging/simulation.h).
    {"dura", "dura mater (falx cerebri)", props(1600, 1100, 1.0f, 0.9f, 20.0f, 0.4f),
     "fibrous collagen: between brain and tendon (Duck 1990); hyperechoic in cranial US"},
    {"choroid_plexus", "choroid plexus", props(1560, 1050, 0.8f, 0.9f, 20.0f, 0.3f),
     "blood-rich villous epithelium: soft-tissue values; hyperechoic in cranial US"},
    {"pia_arachnoid", "pia-arachnoid and its vessels (sulci)",
     props(1560, 1050, 0.8f, 1.0f, 20.0f, 0.3f),
     "thin collagenous membranes with vessels: soft-tissue values; the sulci are bright "
     "lines in intraoperative and transcranial US"},
}};

}  // namespace

AcousticProperties lerp(const AcousticProperties& a, const AcousticProperties& b, float t) {
    AcousticProperties r;
    for (std::size_t n = 0; n < kPropertyCount; ++n) {
        r.values[n] = a.values[n] + (b.values[n] - a.values[n]) * t;
    }
    return r;
}

std::span<const TissueEntry> tissue_table() {
    return kTable;
}

const TissueEntry& find_tissue(std::string_view key, const std::string& source,
                               const std::string& field) {
    for (const TissueEntry& entry : kTable) {
        if (entry.key == key) return entry;
    }
    std::string known;
    for (const TissueEntry& entry : kTable)
        known += (known.empty() ? "" : ", ") + std::string(entry.key);
    throw base::InputError(source, field,
                           "unknown tissue '" + std::string(key) + "' (known: " + known + ")");
}

}  // namespace sonotrace::tissue
