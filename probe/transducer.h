#pragma once
// Transducer models: their parameters (each documented once, with its unit), presets
// modelled on real probes, and the scan geometry in the probe's own plane. Each array
// type (linear, convex, phased, ...) is a class of its own in probe/arrays/, registered
// in probe/array_geometry.cpp.
//
// Probe-local plane: x = lateral (along the array), y = axial (into the tissue), origin
// at the centre of the transducer face (for a curved array: the apex of its arc).
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include <glm/glm.hpp>

namespace sonotrace::probe {

// The registered array types (probe/array_geometry.h: names, geometry, checks).
enum class TransducerType { linear, convex, phased, radial };

std::string to_string(TransducerType type);

// Weighting of the elements across an active aperture.
enum class Apodization {
    rectangular,  // all elements alike
    hann,         // raised cosine: lowest side lobes, widest main lobe
    tukey,        // flat middle, cosine tapers over the outer quarters (alpha 0.5)
};
std::string to_string(Apodization a);
// By name; throws base::InputError(source, field) listing the names otherwise.
Apodization parse_apodization(const std::string& name, const std::string& source,
                              const std::string& field);
// Weight of an element at fraction u in [0, 1] across the active aperture (0 outside).
double apodization_weight(Apodization a, double u);

struct Transducer {
    std::string name = "custom";
    std::string description;
    TransducerType type = TransducerType::convex;
    int elements = 128;
    double pitch_mm = 0.508;
    double element_width_mm = 0.46;  // pitch minus kerf: sets each element's directivity
    double radius_mm = 49.6;         // curved arrays: radius of the arc
    double fov_deg = 60.0;           // fans (convex, phased): angle spanned by the scan lines
    double frequency_mhz = 3.5;
    double bandwidth = 0.8;  // fractional, -6 dB of the pulse-echo spectrum
    // The band's shape: its -20 dB width over its -6 dB width (probe/pulse.h). 1.82 is a
    // Gaussian band; measured probe spectra are flatter-topped.
    double band_shape = 1.5;
    double focus_mm = 50.0;  // transmit focus depth
    double f_number = 2.0;   // transmit: focus depth / active aperture
    Apodization tx_apodization = Apodization::tukey;
    // Receive: dynamic focus at every depth with an aperture expanding as depth / F-number
    // (at most the array).
    double rx_f_number = 1.5;
    Apodization rx_apodization = Apodization::hann;
    double cycles = 1.0;  // excitation: cycles of a sine at the centre frequency
    double elevation_focus_mm = 60.0;
    double slice_thickness_mm = 3.0;  // elevation beam width (-6 dB) at the elevation focus
    double depth_mm = 80.0;           // imaging depth from the face along each line
    int lines = 128;
    double face_reflectivity = 0.3;  // intensity fraction the face reflects back (capture model)

    // The range of band_shape: from a steep, almost rectangular band (1.1: exponent 12.6) to
    // one with long skirts (2.5: exponent 1.3).
    static constexpr double kBandShapeRange[2] = {1.1, 2.5};

    // Throws base::InputError(source, field) naming the first impossible parameter.
    void validate(const std::string& source) const;

    double wavelength_mm() const;       // at the centre frequency and 1540 m/s
    double array_length_mm() const;     // elements * pitch (along the face)
    double active_aperture_mm() const;  // transmit: focus / F-number, at most the array
    double receive_aperture_mm(double range_mm) const;  // depth / rx F-number, at most the array
    // The elements' height (mm): the lens aperture whose focal beam width is the slice
    // thickness, by the same rule as the lateral focus (FWHM = wavelength x F-number), so
    // elevation_focus x wavelength / slice_thickness.
    double elevation_aperture_mm() const;
};

// The transducer's parameters, one row each: the CLI's flag and --help, the GUI's
// tooltips, the sidecar's key and value, and how a text sets it (make_transducer-style
// overrides of a preset) all read the row.
struct TransducerParameterDoc {
    using Value = std::variant<double, int, std::string>;
    const char* key;   // CLI flag stem
    const char* unit;  // "" if none
    const char* description;
    const char* record_key;  // the sidecar's key
    Value (*get)(const Transducer& t);
    // From text (a number, or a name); throws base::InputError(source, "") if it is not
    // one. Ranges are Transducer::validate's.
    void (*set)(Transducer& t, const std::string& text, const std::string& source);
    // Whether the lateral PSF's rows depend on it (imaging/psf_build.cpp keys the rows it
    // shares between tables by these; the depth only says how many rows a table takes).
    bool shapes_psf_rows = true;
};
const std::vector<TransducerParameterDoc>& transducer_parameter_docs();
// A value as the text `set` reads back to exactly that value (numbers to the bit).
std::string parameter_text(const TransducerParameterDoc::Value& value);

// Presets modelled on real probes (values from the public datasheets; see the .cpp).
const std::vector<Transducer>& transducer_presets();
// By name; throws base::InputError(source, "probe") listing the presets otherwise.
const Transducer& find_transducer(const std::string& name, const std::string& source);

// One scan line in the probe plane.
struct ScanLine {
    glm::dvec2 origin;     // mm, on the face
    glm::dvec2 direction;  // unit
};

class ArrayGeometry;

// Geometry of the scan lines of a transducer and its inverse for scan conversion (its
// array type's, probe/array_geometry.h).
class ScanGeometry {
  public:
    explicit ScanGeometry(const Transducer& t);

    int lines() const { return lines_; }
    double depth_mm() const { return depth_; }
    ScanLine line(int l) const;
    // The point at `depth` mm along line `l` (fractional lines interpolate the geometry).
    glm::dvec2 point(double l, double depth) const;
    // Inverse: fractional line index and depth of a point in the probe plane. Points off
    // the scanned region come back with a line outside [0, lines-1] or depth outside
    // [0, depth]; the caller decides.
    glm::dvec2 line_and_depth(const glm::dvec2& p) const;
    // Bounding box of the scanned region (min, max corners), for the image extent.
    std::pair<glm::dvec2, glm::dvec2> bounds() const;
    // Distance between neighbouring lines at a depth (mm).
    double line_spacing_mm(double depth) const;
    // True if the last line neighbours the first (an array closed on itself).
    bool closed() const;
    const ArrayGeometry& array() const { return *array_; }

  private:
    std::shared_ptr<const ArrayGeometry> array_;
    int lines_;
    double depth_;
};

}  // namespace sonotrace::probe
