#pragma once
// The elevation beam: the row of elements is H = Transducer::elevation_aperture_mm high
// and a cylindrical lens focuses it at F = elevation_focus_mm. The same lens transmits and
// receives, so a reflector at elevation e (mm from the scan plane) and depth z returns the
// product of the two one-way fields.
//
// One-way field (narrowband at the centre frequency, Fresnel approximation; Kino,
// "Acoustic Waves", ch. 3; Szabo, "Diagnostic Ultrasound Imaging", ch. 6), up to a factor
// common to all e at a depth:
//     U(e, z) = integral over x in [-H/2, H/2] of exp(i k (x^2 / 2 (1/z - 1/F) - x e / z)) dx,
// k = 2 pi / lambda. At the focus |U| = H sinc(H e / (lambda F)): the two-way -6 dB width
// there is 0.886 lambda F / H. By Parseval the integral of |U|^2 over e is lambda z H at
// every depth, so
//     p(e, z) = |U(e, z)|^2 / (lambda z H)
// is the two-way amplitude of a reflector per mm of elevation with unit integral: a point
// of diameter d images as a piece of wire of length d weighted by p, and a wire across the
// slice sums its pieces to the wire's own echo.
#include <complex>
#include <memory>
#include <vector>

#include "probe/transducer.h"

namespace sonotrace::probe {

class ElevationBeam {
  public:
    explicit ElevationBeam(const Transducer& t);

    // U(e, z) above (mm); z below a wavelength is taken as one wavelength.
    std::complex<double> field(double e_mm, double z_mm) const;
    // p(e, z) above: the two-way amplitude per mm of elevation, unit integral over e.
    double profile(double e_mm, double z_mm) const;
    // Half-width (mm) outside which p is negligible at depth z: the geometric beam
    // H/2 |1 - z/F| plus ten diffraction widths lambda z / H.
    double reach_mm(double z_mm) const;

    double aperture_mm() const { return aperture_mm_; }
    double focus_mm() const { return focus_mm_; }
    double wavelength_mm() const { return wavelength_mm_; }

  private:
    double aperture_mm_, focus_mm_, wavelength_mm_;
};

// The one-way intensity |U(e, z)|^2 / H^2 (1 on the axis at the focus) tabulated over the
// imaging depth and the elevation a 3D frame traces, for the image's many look-ups
// (receive weights, the speckle's elevation average). Built once per lens and depth.
class ElevationTable {
  public:
    static std::shared_ptr<const ElevationTable> of(const Transducer& t);
    explicit ElevationTable(const Transducer& t);

    // Bilinear in depth and |e|; 0 beyond the slab.
    double intensity(double e_mm, double z_mm) const;
    // Half-thickness (mm) of the slab a 3D frame traces: over the imaging depth, the
    // geometric beam H/2 |1 - z/F| plus two diffraction widths lambda z / H, and 1 mm.
    double slab_half_mm() const { return slab_half_mm_; }

  private:
    double dz_ = 0.5, de_ = 0.05, slab_half_mm_ = 0.0;
    int rows_ = 0, columns_ = 0;
    std::vector<float> values_;  // [row * columns + column]
};

}  // namespace sonotrace::probe
