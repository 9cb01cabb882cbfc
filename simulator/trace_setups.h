#pragma once
// Built-in trace configurations: figure 5 of Reis & Bertram (a Colin27 slice in paper
// mode; figures 2, 4 and 6 are catalogue phantoms, phantoms/paper_fig*.json) and simple
// analytic media for tests.
#include <string>
#include <vector>

#include "simulator/sources.h"
#include "simulator/trace_settings.h"
#include "tissue/acoustic_map.h"
#include "tissue/property_maps.h"

namespace sonotrace::simulator {

struct TraceSetup {
    std::string name, description;
    tissue::Volume medium;  // what the pictures show underneath the paths (density or speed)
    std::string medium_label, medium_unit;
    tissue::AcousticMap<2> map;
    Sources<2> sources;
    TraceSettings settings;
};

// "fig5" (loads Colin27); throws base::InputError("--config", ...) for other names.
TraceSetup make_paper_setup(const std::string& name, int particles);

// Two media separated by a plane through `point` with unit `normal` (pointing into
// medium b), the transition smoothed linearly over `smoothing_texels`. Grid: nx x ny
// texels of h mm, texel (i, j) at (i h, j h).
tissue::PropertyMaps planar_interface(int nx, int ny, double h, glm::dvec2 point, glm::dvec2 normal,
                                      const tissue::AcousticProperties& a,
                                      const tissue::AcousticProperties& b, double smoothing_texels);
// Speed (m/s) and density (kg/m^3) only: no attenuation, scatterers or roughness.
tissue::AcousticProperties lossless_medium(double speed, double density);
// Refraction and interface decisions only (no absorption, scattering, diffuse lobes or
// roulette): the quantities tests and validation cases compare with closed forms.
TraceSettings interfaces_only_settings();

// Homogeneous medium of nx x ny texels.
tissue::PropertyMaps homogeneous(int nx, int ny, double h, const tissue::AcousticProperties& p);

// The bent fibre of figure 4: centreline, core radius, and the distance/arc length of a
// point from it (for measuring track width).
// Ray optics of a bend: L = n(rho) (R + rho) cos(theta) is conserved, and a ray stays
// in the core only if L > n_clad (R + a) at the outer core edge. The parallel bundle
// (offsets up to 0.8 a) has L >= n(0.8 a) (R - 0.8 a) = 1.18 * 66 = 77.9 > 1.0 * 75, so
// every injected particle is guided; a weaker core (1.2) or tighter bend (60 mm) leaks.
struct FibreGeometry {
    glm::dvec2 start{15.0, 118.0};  // mm; the fibre runs up (-y) from here
    double straight_mm = 20.0;      // before the bend
    glm::dvec2 bend_centre{85.0, 98.0};
    double bend_radius_mm = 70.0;  // quarter circle turning towards +x
    double exit_mm = 35.0;         // straight after the bend
    double core_radius_mm = 5.0;
    double core_density = 1.5, cladding_density = 1.0;
    // Signed distance from the centreline (negative towards the bend centre) and arc length.
    glm::dvec2 offset_and_arc(glm::dvec2 p) const;
    double length_mm() const;
};

}  // namespace sonotrace::simulator
