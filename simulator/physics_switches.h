#pragma once
// The physics a user switches off to take an artifact apart, one row each: simulate's
// and trace's --disable, the dataset spec's "disable", Python's disable=, the GUI's
// toggles and tooltips, the sidecars and the phantoms' "trace" entries all read this
// table. A new switch is a row here and the code that reads it (the tracer, or the image
// for `image_only` ones).
#include <array>
#include <bitset>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace sonotrace::simulator {

enum class Physics : uint8_t {
    refraction,
    specular,
    diffuse,
    scattering,
    attenuation,
    shear,
    bounces,
    face,
    speckle,
};
inline constexpr std::size_t kPhysicsCount = 9;

struct PhysicsSwitch {
    Physics id;
    std::string_view name;         // --disable's, the sidecar's "disabled_physics"
    std::string_view label;        // the GUI's toggle
    std::string_view record_key;   // a JSON key: the phantoms' "trace" flags, records
    std::string_view description;  // what it is, and what switching it off leaves
    bool image_only = false;       // the B-mode image's, not the tracer's
};

// In the order of the enum (checked at compile time below).
inline constexpr std::array<PhysicsSwitch, kPhysicsCount> kPhysicsSwitches = {{
    {Physics::refraction, "refraction", "refraction", "refraction",
     "bending where the speed of sound changes (Snell's law); off: beams go straight"},
    {Physics::specular, "specular", "specular reflection", "specular_reflection",
     "mirror reflection at interfaces with the impedance reflection coefficient (off: total "
     "reflection stays)"},
    {Physics::diffuse, "diffuse", "diffuse reflection", "diffuse_reflection",
     "rough interfaces reflect into a cos^c lobe (c from the tissue's roughness); off: "
     "mirrors"},
    {Physics::scattering, "scattering", "scattering", "scattering",
     "sub-resolution scattering events (the tissue's speckle and its backscatter); off: "
     "tissue turns black"},
    {Physics::attenuation, "attenuation", "attenuation", "attenuation",
     "absorption alpha f along the paths (dB/(cm MHz) of each tissue)"},
    {Physics::shear, "shear", "shear waves in bone", "shear_conversion",
     "the shear wave a solid (bone) takes at its interfaces, absorbed within millimetres "
     "(off: total reflection past the critical angle)"},
    {Physics::bounces, "bounces", "multiple bounces", "multiple_bounces",
     "paths after the first reflection (reverberation, mirror images); off: a particle ends "
     "at its first reflection, whose echo still counts"},
    {Physics::face, "face", "face reflection", "face_reflection",
     "the probe face reflects part of the returning energy back into the tissue (capture "
     "receive model): reverberation between the face and reflectors"},
    {Physics::speckle, "speckle", "speckle", "speckle",
     "the scattered echoes' speckle in the image", true},
}};

constexpr bool rows_follow_the_enum() {
    for (std::size_t i = 0; i < kPhysicsCount; ++i)
        if (std::size_t(kPhysicsSwitches[i].id) != i) return false;
    return true;
}
static_assert(rows_follow_the_enum(), "kPhysicsSwitches lists the switches in enum order");

inline constexpr const PhysicsSwitch& physics_switch(Physics p) {
    return kPhysicsSwitches[std::size_t(p)];
}

// Which physics is on; every switch on by default (the simulator's physics).
class PhysicsSet {
  public:
    bool on(Physics p) const { return !off_.test(std::size_t(p)); }
    void set(Physics p, bool on) { off_.set(std::size_t(p), !on); }
    // On only where both are.
    PhysicsSet& operator&=(const PhysicsSet& other) {
        off_ |= other.off_;
        return *this;
    }
    bool all_on() const { return off_.none(); }
    bool operator==(const PhysicsSet&) const = default;

  private:
    std::bitset<kPhysicsCount> off_;
};

}  // namespace sonotrace::simulator
