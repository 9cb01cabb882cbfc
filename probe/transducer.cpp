#include "probe/transducer.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>
#include <system_error>
#include <type_traits>

#include "probe/array_geometry.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/error.h"
#include "tissue/base/number_list.h"

namespace sonotrace::probe {

std::string to_string(Apodization a) {
    switch (a) {
        case Apodization::rectangular:
            return "rectangular";
        case Apodization::hann:
            return "hann";
        case Apodization::tukey:
            return "tukey";
    }
    return "?";
}

Apodization parse_apodization(const std::string& name, const std::string& source,
                              const std::string& field) {
    for (Apodization a : {Apodization::rectangular, Apodization::hann, Apodization::tukey})
        if (to_string(a) == name) return a;
    throw base::InputError(source, field,
                           "unknown apodization '" + name + "' (rectangular, hann, tukey)");
}

double apodization_weight(Apodization a, double u) {
    if (!(u >= 0.0 && u <= 1.0)) return 0.0;
    switch (a) {
        case Apodization::rectangular:
            return 1.0;
        case Apodization::hann:
            return 0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * u);
        case Apodization::tukey: {  // alpha = 0.5: tapers over u < 1/4 and u > 3/4
            const double edge = std::min(u, 1.0 - u);
            return edge >= 0.25 ? 1.0 : 0.5 - 0.5 * std::cos(std::numbers::pi * edge / 0.25);
        }
    }
    return 0.0;
}

void Transducer::validate(const std::string& source) const {
    auto in_range = [&](double v, double lo, double hi, const char* field, const char* unit) {
        base::require_in_range(source, field, v, lo, hi, unit);
    };
    in_range(elements, 1, 4096, "elements", "");
    in_range(pitch_mm, 1e-3, 10.0, "pitch", "mm");
    if (!(element_width_mm > 0.0 && element_width_mm < pitch_mm))
        throw base::InputError(source, "element-width",
                               "must be more than 0 and less than the pitch (" +
                                   base::number_text(pitch_mm) +
                                   " mm): elements are separated "
                                   "by a kerf, got " +
                                   base::number_text(element_width_mm));
    in_range(frequency_mhz, 0.5, 50.0, "frequency", "MHz");
    in_range(bandwidth, 0.05, 2.0, "bandwidth", "(fraction of the centre frequency)");
    in_range(band_shape, kBandShapeRange[0], kBandShapeRange[1], "band-shape", "");
    in_range(depth_mm, 1.0, 500.0, "depth", "mm");
    in_range(focus_mm, 1e-3, 1e6, "focus", "mm");
    if (focus_mm > depth_mm) {
        throw base::InputError(source, "focus",
                               "the transmit focus (" + base::number_text(focus_mm) +
                                   " mm) lies beyond the imaging depth (" +
                                   base::number_text(depth_mm) + " mm)");
    }
    in_range(f_number, 0.5, 20.0, "f-number", "");
    if (!(rx_f_number > 0.0))
        throw base::InputError(source, "rx-f-number",
                               "the receive F-number must be > 0 (a small value such as 0.1 "
                               "receives on the whole array), got " +
                                   base::number_text(rx_f_number));
    in_range(rx_f_number, 1e-3, 20.0, "rx-f-number", "");
    if (!(cycles > 0.0))
        throw base::InputError(
            source, "cycles",
            "the excitation needs a positive number of cycles, got " + base::number_text(cycles));
    in_range(cycles, 0.01, 64.0, "cycles", "");
    in_range(elevation_focus_mm, 1.0, 1000.0, "elevation-focus", "mm");
    in_range(slice_thickness_mm, 0.01, 50.0, "slice-thickness", "mm");
    in_range(lines, 1, 4096, "lines", "");
    in_range(face_reflectivity, 0.0, 1.0, "face-reflectivity", "");
    array_type(type).validate(*this, source);
}

double Transducer::wavelength_mm() const {
    return tissue::kReferenceSpeed / (frequency_mhz * 1e6) * 1e3;
}
double Transducer::array_length_mm() const {
    return elements * pitch_mm;
}
double Transducer::active_aperture_mm() const {
    return std::min(focus_mm / f_number, array_type(type).largest_aperture_mm(*this));
}
double Transducer::elevation_aperture_mm() const {
    return elevation_focus_mm * wavelength_mm() / slice_thickness_mm;
}
double Transducer::receive_aperture_mm(double range_mm) const {
    return std::min(std::max(range_mm, 0.0) / rx_f_number,
                    array_type(type).largest_aperture_mm(*this));
}

namespace {

using Value = TransducerParameterDoc::Value;

template <typename T>
T parse_number(const std::string& text, const std::string& source) {
    T value{};
    const char* end = text.data() + text.size();
    const auto [ptr, error] = std::from_chars(text.data(), end, value);
    if (error != std::errc() || ptr != end || text.empty()) {
        throw base::InputError(
            source, "",
            std::string(std::is_integral_v<T> ? "must be a whole number" : "must be a number") +
                ", got '" + text + "'");
    }
    if constexpr (std::is_floating_point_v<T>) {
        if (!std::isfinite(value))
            throw base::InputError(source, "", "must be finite, got '" + text + "'");
    }
    return value;
}

template <auto Member>
Value member_value(const Transducer& t) {
    return t.*Member;
}

template <auto Member>
void set_member(Transducer& t, const std::string& text, const std::string& source) {
    using T = std::remove_reference_t<decltype(t.*Member)>;
    t.*Member = parse_number<T>(text, source);
}

template <auto Member>
Value apodization_value(const Transducer& t) {
    return to_string(t.*Member);
}

template <auto Member>
void set_apodization(Transducer& t, const std::string& text, const std::string& source) {
    t.*Member = parse_apodization(text, source, "");
}

}  // namespace

std::string parameter_text(const TransducerParameterDoc::Value& value) {
    return std::visit(
        [](const auto& v) {
            using V = std::decay_t<decltype(v)>;
            if constexpr (std::is_same_v<V, std::string>)
                return v;
            else if constexpr (std::is_same_v<V, int>)
                return std::to_string(v);
            else
                return base::exact_number_text(v);
        },
        value);
}

const std::vector<TransducerParameterDoc>& transducer_parameter_docs() {
    // The types' own descriptions, from their registration.
    static const std::string types = [] {
        std::string text = "transducer type: ";
        for (const ArrayType& a : array_types())
            text += std::string(&a == &array_types().front() ? "" : ", ") + a.name + " (" +
                    a.description + ")";
        return text;
    }();
    using T = Transducer;
    static const std::vector<TransducerParameterDoc> docs = {
        {"type", "", types.c_str(), "type", [](const T& t) -> Value { return to_string(t.type); },
         [](T& t, const std::string& text, const std::string& source) {
             t.type = parse_transducer_type(text, source, "");
         }},
        {"elements", "", "number of array elements", "elements", member_value<&T::elements>,
         set_member<&T::elements>},
        {"pitch", "mm", "centre-to-centre element distance", "pitch_mm", member_value<&T::pitch_mm>,
         set_member<&T::pitch_mm>},
        {"radius", "mm",
         "radius of a curved array: a convex arc, or a radial ring (elements x pitch / 2 pi)",
         "radius_mm", member_value<&T::radius_mm>, set_member<&T::radius_mm>},
        {"fov", "degrees", "angle spanned by the scan lines (convex, phased; radial: 360)",
         "fov_deg", member_value<&T::fov_deg>, set_member<&T::fov_deg>},
        {"frequency", "MHz", "centre frequency of the pulse", "frequency_mhz",
         member_value<&T::frequency_mhz>, set_member<&T::frequency_mhz>},
        {"element-width", "mm", "width of one element (the pitch minus the kerf)",
         "element_width_mm", member_value<&T::element_width_mm>, set_member<&T::element_width_mm>},
        {"bandwidth", "", "fractional -6 dB bandwidth of the pulse-echo spectrum", "bandwidth",
         member_value<&T::bandwidth>, set_member<&T::bandwidth>},
        {"band-shape", "",
         "shape of the pulse-echo spectrum: its -20 dB width over its -6 dB width, 1.1-2.5 "
         "(1.82: a Gaussian band; smaller: flatter-topped, as measured probe spectra)",
         "band_shape", member_value<&T::band_shape>, set_member<&T::band_shape>},
        {"focus", "mm", "transmit focus depth", "focus_mm", member_value<&T::focus_mm>,
         set_member<&T::focus_mm>},
        {"f-number", "", "transmit F-number: focus depth / active transmit aperture width",
         "f_number", member_value<&T::f_number>, set_member<&T::f_number>},
        {"tx-apodization", "",
         "weighting of the transmit aperture: rectangular, hann or tukey (cosine tapers over "
         "the outer quarters)",
         "tx_apodization", apodization_value<&T::tx_apodization>,
         set_apodization<&T::tx_apodization>},
        {"rx-f-number", "",
         "receive F-number: the receive aperture expands as depth / F-number (dynamic focus "
         "at every depth, at most the array); 0.1 = the whole array",
         "rx_f_number", member_value<&T::rx_f_number>, set_member<&T::rx_f_number>},
        {"rx-apodization", "", "weighting of the receive aperture: rectangular, hann or tukey",
         "rx_apodization", apodization_value<&T::rx_apodization>,
         set_apodization<&T::rx_apodization>},
        {"cycles", "", "excitation length in cycles of a sine at the centre frequency", "cycles",
         member_value<&T::cycles>, set_member<&T::cycles>},
        {"elevation-focus", "mm", "depth of the fixed elevation (lens) focus", "elevation_focus_mm",
         member_value<&T::elevation_focus_mm>, set_member<&T::elevation_focus_mm>, false},
        {"slice-thickness", "mm", "elevation beam width (-6 dB) at the elevation focus",
         "slice_thickness_mm", member_value<&T::slice_thickness_mm>,
         set_member<&T::slice_thickness_mm>, false},
        {"depth", "mm", "imaging depth from the face along each scan line", "depth_mm",
         member_value<&T::depth_mm>, set_member<&T::depth_mm>, false},
        {"lines", "", "number of scan lines", "lines", member_value<&T::lines>,
         set_member<&T::lines>},
        {"face-reflectivity", "",
         "intensity fraction the transducer face reflects back into the tissue",
         "face_reflectivity", member_value<&T::face_reflectivity>,
         set_member<&T::face_reflectivity>, false},
    };
    return docs;
}

// Values from the public datasheets of the modelled probes (Verasonics L11-5v, C5-2v and
// P4-2v specification sheets): element count, pitch, radius, centre frequency, bandwidth
// range, elevation focus and element height; the L11-5v's element width (0.27 mm). The
// other arrays' sheets give the pitch alone: their elements are the pitch less a kerf of
// about 0.05 mm, as diced arrays of that pitch are made (0.03 mm on the radial ring). No
// sheet gives a -20 dB bandwidth: every preset keeps the struct's band shape, 1.5, within
// the 1.4-1.6 of published pulse-echo spectra of composite arrays (flatter than a Gaussian's
// 1.82). Where a sheet gives an element height h,
// the slice thickness is the diffraction-limited lambda * elevation focus / h. Transmit
// focus, F-number, depth and line count are typical scanner settings, not probe data.
// Every preset keeps the struct's imaging defaults: a one-cycle excitation (the B-mode
// pulse of research scanners such as the Verasonics Vantage), a Tukey-tapered transmit
// aperture, and a dynamic receive at F/1.5 with a Hann window: the usual rule of
// delay-and-sum beamformers, an F-number of 1-2 so that the edge elements still see the
// focus within their directivity, and a taper against side lobes.
const std::vector<Transducer>& transducer_presets() {
    static const std::vector<Transducer> presets = [] {
        std::vector<Transducer> p;
        Transducer linear;
        linear.name = "linear";
        linear.description =
            "linear 7.6 MHz, 128 elements at 0.30 mm (like the L11-5v: 5-11 MHz, "
            "elevation focus 18 mm, element height 5 mm)";
        linear.type = TransducerType::linear;
        linear.elements = 128;
        linear.pitch_mm = 0.30;
        linear.element_width_mm = 0.27;
        linear.radius_mm = 0.0;
        linear.fov_deg = 0.0;
        linear.frequency_mhz = 7.6;
        linear.bandwidth = 0.79;  // (11 - 5) / 7.6
        linear.focus_mm = 20.0;
        linear.f_number = 2.0;
        linear.elevation_focus_mm = 18.0;
        linear.slice_thickness_mm = 0.73;  // 0.203 mm * 18 / 5
        linear.depth_mm = 40.0;
        linear.lines = 128;
        p.push_back(linear);

        Transducer convex;
        convex.name = "convex";
        convex.description =
            "convex 3.5 MHz, 128 elements at 0.508 mm on a 49.6 mm radius (like the C5-2v: "
            "2-5 MHz, elevation focus 60 mm, element height 13.5 mm)";
        convex.type = TransducerType::convex;
        convex.elements = 128;
        convex.pitch_mm = 0.508;
        convex.element_width_mm = 0.46;
        convex.radius_mm = 49.57;
        convex.fov_deg = 60.0;
        convex.frequency_mhz = 3.5;
        convex.bandwidth = 0.86;  // (5 - 2) / 3.5
        convex.focus_mm = 50.0;
        convex.f_number = 2.0;
        convex.elevation_focus_mm = 60.0;
        convex.slice_thickness_mm = 1.96;  // 0.44 mm * 60 / 13.5
        convex.depth_mm = 80.0;
        convex.lines = 128;
        p.push_back(convex);

        Transducer phased;
        phased.name = "phased";
        phased.description =
            "phased 2.7 MHz, 64 elements at 0.30 mm (like the P4-2v: 2-4 MHz, elevation "
            "focus 60 mm, element height 14 mm)";
        phased.type = TransducerType::phased;
        phased.elements = 64;
        phased.pitch_mm = 0.30;
        phased.element_width_mm = 0.25;
        phased.radius_mm = 0.0;
        phased.fov_deg = 90.0;
        phased.frequency_mhz = 2.7;
        phased.bandwidth = 0.74;  // (4 - 2) / 2.7
        phased.focus_mm = 60.0;
        phased.f_number = 3.2;  // the whole 19.2 mm array at 60 mm
        phased.elevation_focus_mm = 60.0;
        phased.slice_thickness_mm = 2.44;  // 0.570 mm * 60 / 14
        phased.depth_mm = 120.0;
        phased.lines = 128;
        p.push_back(phased);

        // Typical values of electronic radial echoendoscopes (360 degrees, 5-10 MHz, a
        // tip about 12 mm across), not one probe's datasheet. The ring of 256 elements
        // of 0.147 mm closes on a 6 mm radius; the transmit aperture (7.5 mm, 51
        // elements) and the receive (at most 16 mm at 40 mm) stay within the half of the
        // ring that faces a line.
        Transducer radial;
        radial.name = "radial";
        radial.description =
            "radial 7.5 MHz, 256 elements at 0.147 mm around a 12 mm tip (an electronic "
            "radial array as in echoendoscopes and EBUS: 360 degrees, 5-10 MHz)";
        radial.type = TransducerType::radial;
        radial.elements = 256;
        radial.radius_mm = 6.0;
        radial.pitch_mm = 2.0 * std::numbers::pi * radial.radius_mm / radial.elements;
        radial.element_width_mm = 0.12;
        radial.fov_deg = 360.0;
        radial.frequency_mhz = 7.5;
        radial.bandwidth = 0.67;  // (10 - 5) / 7.5
        radial.focus_mm = 15.0;
        radial.f_number = 2.0;
        radial.rx_f_number = 2.5;
        radial.elevation_focus_mm = 20.0;
        radial.slice_thickness_mm = 1.0;
        radial.depth_mm = 40.0;
        radial.lines = 256;
        p.push_back(radial);

        // The probe of the PICMUS challenge (Liebgott et al., IEEE IUS 2016: an L11-4v on a
        // Verasonics scanner), for plane-wave and diverging-wave imaging: 128 elements at
        // 0.30 mm (kerf 0.03 mm), 5.208 MHz, 67 % bandwidth, a 2.5-cycle excitation,
        // elevation focus 20 mm with 5 mm high elements, no transmit apodization.
        Transducer picmus = p.front();  // the linear preset's array
        picmus.name = "picmus";
        picmus.description =
            "linear 5.208 MHz, 128 elements at 0.30 mm, the PICMUS challenge's L11-4v "
            "(67 % bandwidth, 2.5-cycle excitation, elevation focus 20 mm, element height "
            "5 mm)";
        picmus.frequency_mhz = 5.208;
        picmus.bandwidth = 0.67;
        picmus.cycles = 2.5;
        picmus.focus_mm = 25.0;
        picmus.tx_apodization = Apodization::rectangular;
        picmus.rx_f_number = 1.75;
        picmus.elevation_focus_mm = 20.0;
        picmus.slice_thickness_mm = 1.18;  // 0.2957 mm * 20 / 5
        picmus.depth_mm = 50.0;
        p.push_back(picmus);
        return p;
    }();
    return presets;
}

const Transducer& find_transducer(const std::string& name, const std::string& source) {
    std::string names;
    for (const Transducer& t : transducer_presets()) {
        if (t.name == name) return t;
        names += (names.empty() ? "" : ", ") + t.name;
    }
    throw base::InputError(source, "probe",
                           "unknown transducer preset '" + name + "' (presets: " + names + ")");
}

ScanGeometry::ScanGeometry(const Transducer& t)
    : array_(array_geometry(t)), lines_(t.lines), depth_(t.depth_mm) {}

glm::dvec2 ScanGeometry::point(double l, double depth) const {
    return array_->point(l, depth);
}
ScanLine ScanGeometry::line(int l) const {
    return array_->line(l);
}
glm::dvec2 ScanGeometry::line_and_depth(const glm::dvec2& p) const {
    return array_->line_and_depth(p);
}
bool ScanGeometry::closed() const {
    return array_->closed();
}

std::pair<glm::dvec2, glm::dvec2> ScanGeometry::bounds() const {
    glm::dvec2 lo(1e300), hi(-1e300);
    // The region's outline: both end lines, the face and the deepest arc or segment.
    const int n = 256;
    for (int i = 0; i <= n; ++i) {
        const double l = -0.5 + double(lines_) * i / n;  // outer edges of the end lines
        const double d = depth_ * i / n;
        for (const glm::dvec2& p :
             {point(l, 0.0), point(l, depth_), point(-0.5, d), point(lines_ - 0.5, d)}) {
            lo = glm::min(lo, p);
            hi = glm::max(hi, p);
        }
    }
    return {lo, hi};
}

double ScanGeometry::line_spacing_mm(double depth) const {
    return array_->line_spacing_mm(depth);
}

}  // namespace sonotrace::probe
