#include "ui/gui/controls.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "imaging/simulation.h"
#include "phantoms/scene/request.h"
#include "probe/array_geometry.h"
#include "tissue/base/error.h"

namespace sonotrace::gui {

using imaging::Physics;

namespace {

// A slider over a transducer parameter: its unit and help from the parameter's row.
SliderSpec transducer_slider(Control control, const char* label, const char* key, double min,
                             double max) {
    for (const auto& doc : probe::transducer_parameter_docs())
        if (std::string(doc.key) == key)
            return {control, label, doc.unit, min, max, doc.description};
    throw std::logic_error(std::string("no transducer parameter ") + key);
}

// A slider over a frame parameter (the request's table: its unit and description).
SliderSpec request_slider(Control control, const char* label, const char* key, double min,
                          double max) {
    const scene::RequestParameter& row = scene::request_parameter(key);
    return {control, label, row.unit.c_str(), min, max, row.description};
}

// What the materials of a scene can do to a beam, and the materials that do it (quoted
// in the explain panel with their own numbers).
struct Features {
    bool shadowing = false;  // strong attenuation or a strong reflector (bone, calcification)
    bool fluid = false;      // anechoic and nearly lossless (cysts, CSF, vessels)
    bool air = false;        // total reflection
    bool speed_contrast = false;
    bool rough_reflector = false;
    scene::Scene::Material slowest, fastest, most_attenuating;
};

Features features_of(const Scene& scene) {
    using tissue::Property;
    Features f;
    double slowest = 1e9, fastest = 0.0, attenuation = -1.0;
    for (const scene::Scene::Material& material : scene.materials()) {
        const tissue::AcousticProperties& m = material.properties;
        const double z = m.impedance_mrayl();
        if (z < 0.1) {
            f.air = true;
            continue;
        }
        f.shadowing |= m[Property::attenuation] >= 3.0 || z >= 3.5;
        f.fluid |= m[Property::backscatter] <= 0.05f && m[Property::attenuation] <= 0.2f;
        f.rough_reflector |= z >= 3.5 && m[Property::roughness] >= 0.3f;
        const double c = m[Property::speed_of_sound];
        if (c < slowest) slowest = c, f.slowest = material;
        if (c > fastest) fastest = c, f.fastest = material;
        if (m[Property::attenuation] > attenuation)
            attenuation = m[Property::attenuation], f.most_attenuating = material;
    }
    f.speed_contrast = fastest - slowest > 50.0;
    return f;
}

std::string speed_of(const scene::Scene::Material& m) {
    return m.name + " " +
           std::to_string(int(std::lround(m.properties[tissue::Property::speed_of_sound]))) +
           " m/s";
}

}  // namespace

const std::vector<SliderSpec>& slider_specs() {
    static const std::vector<SliderSpec> specs = {
        transducer_slider(Control::depth, "depth", "depth", 20.0, 160.0),
        transducer_slider(Control::focus, "focus", "focus", 5.0, 160.0),
        transducer_slider(Control::lines, "scan lines", "lines", 16.0, 256.0),
        transducer_slider(Control::fov, "field of view", "fov", 10.0, 120.0),
        transducer_slider(Control::frequency, "frequency", "frequency", 1.0, 12.0),
        request_slider(Control::gain, "gain", "gain", -20.0, 80.0),
        request_slider(Control::dynamic_range, "dynamic range", "dynamic-range", 20.0, 100.0),
        {Control::transmits, "transmits", "", 1.0, 75.0,
         "unfocused transmits, their steering angles evenly over +-span, each traced and its "
         "channel data (every element's RF) beamformed by delay-and-sum; coherent compounding "
         "of more angles focuses the transmit synthetically. Each costs about as much as a "
         "whole focused frame"},
        {Control::span, "span", "degrees", 0.0, 20.0,
         "the outermost steering angle of the unfocused transmits (plane waves: the wave's "
         "angle; diverging waves: the virtual source's axis)"},
        {Control::tgc, "TGC", "dB", -30.0, 30.0,
         "time-gain compensation at this depth, added to the automatic curve (2 x 0.6 "
         "dB/(cm MHz) x f x depth, brain attenuation)"},
    };
    return specs;
}

const SliderSpec& slider(Control control) {
    for (const SliderSpec& s : slider_specs())
        if (s.control == control) return s;
    throw std::logic_error("no slider for this control");
}

double slider_max(Control control, const probe::Transducer& t) {
    const double max = slider(control).max;
    if (control == Control::focus) return std::min(max, t.depth_mm);
    if (control == Control::fov)
        return std::min(max, std::floor(probe::array_type(t.type).max_fov_deg(t)));
    return max;
}

std::optional<imaging::Physics> physics_of(Control control) {
    const int i = int(control) - int(Control::physics);
    if (i < 0 || i >= int(simulator::kPhysicsCount)) return std::nullopt;
    return imaging::Physics(i);
}

std::string switch_help(Control control) {
    if (const auto p = physics_of(control))
        return std::string(simulator::physics_switch(*p).description);
    if (control == Control::receive) return scene::request_parameter("receive").description;
    if (control == Control::trace) return scene::request_parameter("trace").description;
    if (control == Control::transmit) return scene::request_parameter("transmit").description;
    return {};
}

bool offers_unfocused_transmits(const probe::Transducer& t) {
    return probe::array_type(t.type).unfocused_transmits;
}

std::vector<Artifact> explain(const Scene& scene, const ScanParameters& p) {
    std::vector<Artifact> out;
    const PhysicsSwitches& s = p.physics;
    const Features f = features_of(scene);
    if (s.on(Physics::scattering))
        out.push_back({"speckle",
                       "Echoes of sub-resolution scatterers fixed in the tissue interfere: a "
                       "granular texture that moves with the tissue, not with the probe.",
                       physics_control(Physics::scattering),
                       "switch scattering off: tissue turns black"});
    if (s.on(Physics::attenuation))
        out.push_back({"depth attenuation and TGC",
                       "Intensity falls by alpha f per cm each way, so deep echoes are weaker; "
                       "the TGC adds gain with depth to even the image out.",
                       Control::tgc, "lower the deep TGC sliders: the bottom darkens"});
    if (f.shadowing)
        out.push_back(
            {"acoustic shadowing",
             "Bone and calcifications reflect a large share of the energy at their "
             "surface and absorb far more than soft tissue (" +
                 f.most_attenuating.name + ": " +
                 base::number_text(f.most_attenuating.properties[tissue::Property::attenuation]) +
                 " dB/(cm MHz)): little reaches what lies behind them.",
             physics_control(Physics::attenuation), "switch attenuation off: the shadow fills in"});
    if (f.speed_contrast)
        out.push_back({"refraction displacement",
                       "Beams bend where the speed of sound changes obliquely (here " +
                           speed_of(f.fastest) + " against " + speed_of(f.slowest) +
                           "), but the image assumes straight lines: structures shift.",
                       physics_control(Physics::refraction),
                       "switch refraction off: they move back"});
    if (f.speed_contrast)
        out.push_back({"speed-of-sound displacement",
                       "Depth is time x 1540 m/s / 2: under slower tissue (" + speed_of(f.slowest) +
                           ") echoes arrive late and appear deeper, under faster tissue (" +
                           speed_of(f.fastest) + ") shallower.",
                       Control::none, "compare the frame with the tissue slice"});
    if (f.fluid) {
        out.push_back({"dark fluid, bright walls",
                       "Fluid has no scatterers (anechoic); its walls reflect specularly where "
                       "the beam meets them near normal incidence.",
                       physics_control(Physics::specular),
                       "switch specular reflection off: the walls fade"});
        out.push_back({"posterior enhancement",
                       "Fluid absorbs almost nothing, so tissue behind it receives more energy "
                       "than tissue at the same depth beside it (the TGC assumes tissue).",
                       physics_control(Physics::attenuation),
                       "switch attenuation off: the enhancement vanishes"});
    }
    if (f.air || f.shadowing) {
        out.push_back({"mirror images",
                       "A strong reflector (air R = 1, bone) sends the beam sideways; echoes "
                       "from what it meets return along the same path and are drawn behind "
                       "the reflector.",
                       physics_control(Physics::specular),
                       "switch specular reflection off: the mirrored copy disappears"});
        out.push_back({"reverberation between reflectors",
                       "Between two strong reflectors part of the echo bounces back and forth: "
                       "copies repeat at multiples of their spacing, fading.",
                       physics_control(Physics::bounces), "switch multiple bounces off: they go"});
    }
    const bool focused = p.transmit.kind == TransmitControls::Kind::focused;
    if (!focused)
        out.push_back(
            {"unfocused transmit",
             "Each " + std::string(TransmitControls::name_of(p.transmit.kind).name) +
                 " wave lights the whole field at once, so one transmit makes a frame with a "
                 "receive focus only: points are wider and cysts fill with clutter. Adding the "
                 "beamformed images of waves steered at several angles, in phase, focuses the "
                 "transmit synthetically.",
             Control::transmits, "compare 1 transmit with 15: points narrow, cysts darken"});
    // Face reverberation needs the capture receive, which channel frames do not model.
    if (focused && p.receive == imaging::ReceiveModel::capture && s.on(Physics::face))
        out.push_back({"reverberation",
                       "The probe face reflects part of each strong echo back into the tissue: "
                       "copies of the reflector repeat at multiples of its depth.",
                       physics_control(Physics::face),
                       "switch face reflection off: the copies go"});
    else if (focused)
        out.push_back({"reverberation (off)",
                       "Repeated echoes between the probe face and a strong reflector need the "
                       "capture receive model with face reflection.",
                       Control::receive, "set receive to capture"});
    if (f.rough_reflector && s.on(Physics::diffuse))
        out.push_back({"rough bone echoes from every angle",
                       "Rough interfaces reflect into a broad lobe, so bone echoes even where "
                       "the beam meets it obliquely.",
                       physics_control(Physics::diffuse), "switch diffuse reflection off"});
    out.push_back({"sedimentation",
                   "Energy deposits where the particles end: on the far side of strong "
                   "interfaces and at depth (the energy map).",
                   physics_control(Physics::attenuation),
                   "watch the energy map while toggling attenuation"});
    return out;
}

}  // namespace sonotrace::gui
