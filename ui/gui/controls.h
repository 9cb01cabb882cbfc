#pragma once
// The GUI's controls: each slider's range and unit, with the help text documented once
// elsewhere (transducer_parameter_docs, the simulate command's docs, the tracer's docs)
// and reused as its tooltip; and the explain panel's artifacts, each tied to the control
// that makes it vanish and return.
#include <optional>
#include <string>
#include <vector>

#include "ui/gui/scanner.h"

namespace sonotrace::gui {

// Which control an artifact depends on (highlighted in the control panel).
enum class Control {
    none,
    receive,
    trace,
    tgc,
    gain,
    dynamic_range,
    frequency,
    focus,
    depth,
    lines,
    fov,
    transmit,   // focused, plane or diverging waves
    transmits,  // their number
    span,       // their outermost steering angle
    // The physics switches follow, one per row of simulator::kPhysicsSwitches, in its
    // order (physics_control): a new switch needs no entry here.
    physics,
};
constexpr Control physics_control(imaging::Physics p) {
    return Control(int(Control::physics) + int(p));
}
// The switch a control toggles, if it is one.
std::optional<imaging::Physics> physics_of(Control control);

struct SliderSpec {
    Control control;
    const char* label;
    const char* unit;
    double min, max;
    std::string help;  // from the parameter's one documentation
};

// Every numeric slider of the panel, with its range. The extremes are valid settings
// for every probe preset (tests check it), within slider_max.
const std::vector<SliderSpec>& slider_specs();
const SliderSpec& slider(Control control);
// The slider's maximum for this probe: the focus at most the depth, a convex array's
// field of view at most its arc (elements x pitch / radius).
double slider_max(Control control, const probe::Transducer& t);

// Help text of a physics switch (its row's description) or of the receive, trace and
// transmit choices (the frame request's).
std::string switch_help(Control control);

// Whether the probe takes unfocused transmits (an open array); the panel offers them only
// then, and only traced in 2D with the monostatic receive (what channel frames support).
bool offers_unfocused_transmits(const probe::Transducer& t);

struct Artifact {
    std::string name;
    std::string why;  // the physics, in a sentence or two
    Control control;  // what to toggle or move to see it vanish and return
    std::string how;  // what to do with that control
};

// The artifacts the scene shown should exhibit with these parameters, from the tissues
// present and the physics switched on.
std::vector<Artifact> explain(const Scene& scene, const ScanParameters& parameters);

}  // namespace sonotrace::gui
