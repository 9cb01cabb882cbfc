// Cases measured on simulated frames of catalogue phantoms (phantoms/*.json), one family
// per file (cases_placement, cases_levels, cases_resolution, cases_speckle); listed here in
// the report's order. Expectations are computed from the phantom's parameters (shapes,
// tissue properties) and the transducer's.
#include "phantoms/validation/cases_imaging.h"

namespace sonotrace::validation {

void add_imaging_cases(std::vector<Case>& out) {
    out.push_back({"wire_depth", "depth accuracy of the calibration wires",
                   "QA phantom, linear probe: the calibration wires at 10..50 mm in a 1540 m/s "
                   "background must appear at their depth (front face) within 0.5 mm.",
                   wire_depth});
    out.push_back({"speed_displacement", "speed-of-sound displacement behind a fat layer",
                   "Wires under a 15 mm fat layer (1450 m/s) appear deeper than their neighbours "
                   "by L (c0/c_fat - c0/c_background); within 10 %.",
                   speed_displacement});
    out.push_back({"refraction_shift", "lateral displacement by refraction (Snell)",
                   "A wire under a 10 mm slow slab tilted 40 degrees: the beam leaves the slab "
                   "shifted sideways by T sin(i - t)/cos(t) (Snell), so the wire appears that far "
                   "to the other side; within 0.15 mm.",
                   refraction_shift});
    out.push_back({"mirror_image", "mirror image behind an inclined reflector",
                   "A wire 7.5 mm and a point target 6.7 mm in front of an air interface tilted "
                   "20 degrees: their images must appear at them mirrored through the interface "
                   "plane, within 1 mm.",
                   mirror_image});
    out.push_back({"shadow_enhancement", "shadow behind a plaque, enhancement behind a cyst",
                   "Intensity 4..10 mm below each object against plain liver at the same "
                   "depths: the shadow equals the two-way transmission loss of the plaque "
                   "(faces and extra attenuation) within 1.5 dB; the enhancement equals the "
                   "two-way attenuation saved over the cyst's chord within 20 %.",
                   shadow_and_enhancement});
    out.push_back({"resolution", "axial and lateral resolution against theory",
                   "The axial FWHM of a flat interface's echo against the pulse-echo "
                   "waveform's envelope (within 10 %); the lateral FWHM and first side lobe of "
                   "a 0.1 mm wire target at the focus, uniform apertures at F/2, against "
                   "sinc^2: 0.886 lambda F# (within 10 %) and -26.5 dB (within 3 dB).",
                   resolution});
    out.push_back({"flat_reflector", "a flat reflector's echo against depth",
                   "The echo of a perpendicular flat reflector moved from 6 to 40 mm follows the "
                   "aperture's on-axis two-way response (image sources of the elements) within "
                   "1 dB, with no swing above 0.5 dB about a quadratic trend.",
                   flat_reflector});
    out.push_back({"two_layers", "echo ratio of two interfaces",
                   "Water over two layers (R12 = 0.3, R23 = 0.2): the second echo's intensity "
                   "over the first's, the on-axis plane response divided out, against "
                   "R23^2 (1 - R12^2)^2 / R12^2 within 20 %.",
                   two_layers});
    out.push_back({"speckle_cysts", "speckle statistics and cyst contrast",
                   "QA phantom: envelope SNR of the homogeneous region against the Rayleigh "
                   "value 1.913 (+-0.15); the anechoic cyst's CNR tends to the same value; the "
                   "hyperechoic cyst's contrast against 20 log10 of the backscatter ratio.",
                   speckle_and_cysts});
    out.push_back({"per_line_means", "no radial streaks at the standard quality",
                   "Homogeneous brain under the default frame's convex probe at the standard "
                   "quality: in 10 mm bands at 20, 40 and 60 mm, the spread of the per-line mean "
                   "intensities over the central half of the lines at most 1.2 times what "
                   "speckle allows (sigma_I / sqrt(N_eff), N_eff from the intensity's axial "
                   "correlation length).",
                   per_line_means});
    out.push_back({"speckle_depth", "speckle statistics and level against depth",
                   "A scattering medium without attenuation under the convex probe, the whole "
                   "pipeline: the envelope's SNR 1.913 +- 0.15 at 20, 40 and 60 mm; its mean "
                   "level against depth, relative to the transmit focus, within 1.5 dB of the "
                   "two-way field's lateral power integral (from the aperture).",
                   speckle_depth});
    out.push_back({"picmus", "PICMUS measures under 75 compounded plane waves",
                   "The PICMUS-like phantom with the PICMUS probe, 75 plane waves over +-16 "
                   "degrees, on the beamformed envelope: speckle SNR 1.913 (+-0.15); the "
                   "anechoic cyst's contrast below -20 dB, CNR 1.913 (+-0.25), gCNR at least "
                   "0.9; a wire's axial FWHM the pulse's (within 15 %), its lateral FWHM at most "
                   "the receive aperture's alone (1.44 lambda F for Hann).",
                   picmus});
}

}  // namespace sonotrace::validation
