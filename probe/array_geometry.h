#pragma once
// The geometry of each array type, one class per type in probe/arrays/ with its equations
// beside it: where its scan lines run (and the inverse, for scan conversion), where its
// elements sit, where a line's active aperture is centred, and what its parameters must
// satisfy. The types are registered in one table (array_geometry.cpp), which also parses
// their names: adding a type is one file and one line there, plus its enumerator.
//
// Probe-local plane: x = lateral (along the array), y = axial (into the tissue), origin
// at the centre of the transducer face (for a curved array: the apex of its arc). An
// array on an arc of radius R has its centre of curvature at (0, -R).
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "probe/transducer.h"

namespace sonotrace::probe {

// A point of the array's face: position and unit normal into the tissue (probe plane).
struct ArrayPoint {
    glm::dvec2 position;
    glm::dvec2 normal;
};

class ArrayGeometry {
  public:
    virtual ~ArrayGeometry() = default;

    // The point at `depth` mm along fractional scan line l (0 .. lines - 1).
    virtual glm::dvec2 point(double l, double depth) const = 0;
    virtual ScanLine line(int l) const = 0;
    // Inverse of point(): fractional line and depth. Points off the scanned region come
    // back with a line outside [-1/2, lines - 1/2] or a depth outside [0, depth].
    virtual glm::dvec2 line_and_depth(const glm::dvec2& p) const = 0;
    // Distance between neighbouring lines at a depth (mm).
    virtual double line_spacing_mm(double depth) const = 0;

    // The face at arc length s (mm along the array from its centre).
    virtual ArrayPoint face(double s) const = 0;
    // Where `line`'s active aperture is centred, as arc length along the array; nullopt
    // if every line uses the whole array (steered).
    virtual std::optional<double> aperture_centre(const ScanLine& line) const = 0;
    // The element at arc length s, `along` = s minus the line's aperture centre (wrapped
    // around a closed array), in `line`'s own frame: x across the line (direction.y,
    // -direction.x), y along it from its origin (probe/aperture.h).
    virtual ArrayPoint seen_from_line(double s, double along, const ScanLine& line) const = 0;
    // True if the array closes on itself: apertures wrap around it instead of being
    // clipped at its ends, and the last scan line neighbours the first.
    virtual bool closed() const { return false; }
    // Radius of the face's arc (0: flat), for the capture model's face.
    virtual double face_radius_mm() const { return 0.0; }

    // The face's shape, for waves that leave the whole array (probe/transmit.h). These
    // defaults are the flat face y = 0 (s = x), facing +y.
    // Arc length of a point on the face.
    virtual double arc_length(const glm::dvec2& on_face) const { return on_face.x; }
    // Where the ray that reaches p heading along u (unit) crossed the face: the first
    // crossing going back from p, as arc length; nullopt if going back never meets it.
    virtual std::optional<double> face_crossing(const glm::dvec2& p, const glm::dvec2& u) const;
    // True if p lies in front of the face (on the tissue's side).
    virtual bool in_front(const glm::dvec2& p) const { return p.y > 0.0; }
};

// The geometry of `t` (its type's class, built from its parameters).
std::unique_ptr<const ArrayGeometry> array_geometry(const Transducer& t);

// One registered array type: its name, the CLI's description of it, whether its lines
// fan out over --fov, its geometry and its own parameter checks (after the common ones;
// base::InputError(source, field)).
struct ArrayType {
    TransducerType type;
    const char* name;
    const char* description;
    bool fov_adjustable;
    // Plane and diverging waves (probe/transmit.h) apply: an open face, every element on
    // one side of it (not a ring).
    bool unfocused_transmits;
    double (*max_fov_deg)(const Transducer&);  // the widest --fov its arrays allow
    // The widest active aperture (mm of the array) a line can use: apertures asked wider
    // are clipped to it (Transducer::active_aperture_mm, receive_aperture_mm).
    double (*largest_aperture_mm)(const Transducer&);
    std::unique_ptr<const ArrayGeometry> (*make)(const Transducer&);
    void (*validate)(const Transducer&, const std::string& source);
};
const std::vector<ArrayType>& array_types();
const ArrayType& array_type(TransducerType type);
// By name; throws base::InputError(source, field) listing the names otherwise.
TransducerType parse_transducer_type(const std::string& name, const std::string& source,
                                     const std::string& field);

// Lines spread evenly over an angle `span` (radians) from the centre of an arc of radius
// R (0: a point, the phased array's): line l at angle u_l = -span/2 + (l + 1/2) span / L
// from the axis, starting on the arc. Shared by the fan-shaped types.
struct FanLines {
    double radius, span;
    int lines;
    double angle(double l) const { return -0.5 * span + (l + 0.5) * span / lines; }
    glm::dvec2 point(double l, double depth) const;
    ScanLine line(int l) const;
    glm::dvec2 line_and_depth(const glm::dvec2& p) const;
    double line_spacing_mm(double depth) const { return (radius + depth) * span / lines; }
};

// An array on an arc of radius R (centre of curvature (0, -R)) whose lines leave along
// its normals (FanLines over `span`): the element at arc length s sits at angle phi =
// s / R, at (R sin phi, R (cos phi - 1)), facing (sin phi, cos phi); a line's aperture is
// centred on its foot, u_l R along the arc, and seen from the line the array is the same
// arc turned so that the foot is its apex. Convex arrays (part of a circle) and radial
// ones (the whole ring) are arcs.
class ArcArray : public ArrayGeometry {
  public:
    ArcArray(double radius_mm, double span_rad, int lines)
        : radius_(radius_mm), fan_{radius_mm, span_rad, lines} {}

    glm::dvec2 point(double l, double depth) const override { return fan_.point(l, depth); }
    ScanLine line(int l) const override { return fan_.line(l); }
    glm::dvec2 line_and_depth(const glm::dvec2& p) const override { return fan_.line_and_depth(p); }
    double line_spacing_mm(double depth) const override { return fan_.line_spacing_mm(depth); }
    ArrayPoint face(double s) const override;
    std::optional<double> aperture_centre(const ScanLine& line) const override;
    ArrayPoint seen_from_line(double, double along, const ScanLine&) const override {
        return face(along);
    }
    double face_radius_mm() const override { return radius_; }
    // The face's circle, |p - (0, -R)| = R; arc length R atan2(x, y + R).
    double arc_length(const glm::dvec2& on_face) const override;
    std::optional<double> face_crossing(const glm::dvec2& p, const glm::dvec2& u) const override;
    bool in_front(const glm::dvec2& p) const override;

  private:
    double radius_;
    FanLines fan_;
};

// The factories of the registered types (probe/arrays/<type>.cpp).
namespace arrays {
double no_fov(const Transducer& t);
double whole_array(const Transducer& t);
std::unique_ptr<const ArrayGeometry> make_linear(const Transducer& t);
void validate_linear(const Transducer& t, const std::string& source);
std::unique_ptr<const ArrayGeometry> make_convex(const Transducer& t);
void validate_convex(const Transducer& t, const std::string& source);
double max_fov_convex(const Transducer& t);
std::unique_ptr<const ArrayGeometry> make_phased(const Transducer& t);
void validate_phased(const Transducer& t, const std::string& source);
double max_fov_phased(const Transducer& t);
std::unique_ptr<const ArrayGeometry> make_radial(const Transducer& t);
void validate_radial(const Transducer& t, const std::string& source);
double max_fov_radial(const Transducer& t);
double half_ring(const Transducer& t);
}  // namespace arrays

}  // namespace sonotrace::probe
