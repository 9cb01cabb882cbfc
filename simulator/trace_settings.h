#pragma once
// Parameters of the particle tracer, each documented once (name, unit, default) here;
// the CLI help and the sidecars use these texts.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "probe/transducer.h"
#include "simulator/physics_switches.h"

namespace sonotrace::simulator {

enum class PhysicsMode {
    acoustic,  // Snell from the speed of sound, reflection from impedance, attenuation, scattering
    paper,     // one scalar density field acting as refractive index and impedance (Reis & Bertram)
};

// Interpretation of the exponent c of the diffuse lobe cos^c (eq. 11).
enum class LobeExponent {
    roughness,           // c = 1/roughness^2 - 1 from the tissue's roughness (acoustic default)
    reflecting_density,  // c = lobe_scale * d1, the density beyond the interface (paper option 1)
    density_ratio,       // c = lobe_scale * d1/d0 (paper option 2)
};

// Interpretation of the weight w = cos^c(phi_d) of eq. 11.
enum class LobeWeight {
    probability,  // phi_d drawn with density w, energy kept (lossless scattering)
    energy,       // phi_d uniform over the opening angle, energy multiplied by w (lossy)
};

// The transducer face as seen by the tracer: particles that come back through it are
// captured (kind returned_to_probe), except the fraction it reflects back into the tissue.
template <int Dim>
struct ProbeFace {
    glm::vec<Dim, float> centre{0.0f};  // mm, map frame
    glm::vec<Dim, float> normal{0.0f};  // unit, pointing into the tissue
    float half_width_mm = 0.0f;         // lateral half aperture
    float half_height_mm = 0.0f;        // elevation half aperture (3D)
    // 3D: the array's elevation axis (unit, across `normal`); lateral = normal x elevation.
    glm::vec3 elevation{0.0f, 0.0f, 1.0f};
    // Radius of curvature of a convex face (0 = flat). The face is then the arc of that
    // radius through `centre`, bulging along `normal`, with half_width_mm of arc length on
    // either side; in 3D that arc swept along the elevation axis (a cylinder's patch).
    float radius_mm = 0.0f;
    float reflectivity = 0.0f;  // intensity fraction the face reflects (0..1)
};

// The face of a transducer's array in the probe frame (x lateral, y axial, z elevation)
// shifted by `to_map`: its whole length (the arc of a convex or radial array) and, in 3D,
// its elements' height.
ProbeFace<2> probe_face(const probe::Transducer& t, const glm::dvec2& to_map);
ProbeFace<3> probe_face(const probe::Transducer& t, const glm::dvec3& to_map);

// A detector on a circle (2D) in the map frame: energy of particles leaving the circle
// is binned by polar angle over [0, 180] degrees, measured from `zero_direction`
// towards `up` (the paper's figure 6c profile over a semicircle).
struct RingDetector {
    glm::vec2 centre{0.0f};  // mm
    float radius_mm = 10.0f;
    int bins = 90;
    glm::vec2 zero_direction{1.0f, 0.0f};  // unit, angle 0
    glm::vec2 up{0.0f, -1.0f};             // unit, angle 90 degrees (map rows run downwards)

    // The bin a step from `from` to `to` leaves the circle through (polar angle 0-180
    // degrees), or -1 if it does not leave it there.
    int bin_crossed(glm::vec2 from, glm::vec2 to) const {
        if (!(glm::length(from - centre) < radius_mm && glm::length(to - centre) >= radius_mm))
            return -1;
        const glm::vec2 rel = to - centre;
        const float deg =
            glm::degrees(std::atan2(glm::dot(rel, up), glm::dot(rel, zero_direction)));
        if (!(deg >= 0.0f && deg <= 180.0f)) return -1;
        return std::min(bins - 1, int(deg / 180.0f * float(bins)));
    }
};

// The track-length estimate of the echo that sub-resolution scattering sends back, per
// scan line and echo-time bin: at every step a particle adds its expected scattered
// intensity (energy * rate * step * fraction, times its two-way loss E/E0 and receive
// weight) to the bin of twice its time of flight, with the position it came from. It
// has far less variance than the scattering events themselves, which still happen.
struct EchoProfileSettings {
    double bin_s = 5e-8;  // echo-time bin width (s)
    int bins = 0;         // bins per line (echo times beyond are dropped)
    // Also the scattered intensity and its centroid (EchoProfile::intensity, position);
    // without, those stay zero. A frame lit by its map needs only the illumination: the
    // two sums at every step would be wasted there.
    bool scattered = true;
};

// The image's receive sensitivity for each particle's echoes by the particle's one-way
// time (imaging::receive_weights makes it from the aperture): the profile's scattered
// intensity is weighted by it, once. Particle p of line l owns row first_of_line[l] + p.
struct ReceiveWeights {
    double bin_s = 0.0;          // one-way time per column (set_bin_s)
    double inverse_bin_s = 0.0;  // 1 / bin_s
    int bins = 0;
    std::vector<uint32_t> first_of_line;
    std::vector<float> weight;  // [row * bins + bin]
    void set_bin_s(double s) { bin_s = s, inverse_bin_s = 1.0 / s; }
    // A particle's weights by column, or null where it has none (every echo counts fully).
    const float* row(uint32_t line, uint32_t particle) const {
        if (std::size_t(line) + 1 >= first_of_line.size()) return nullptr;
        const std::size_t r = std::size_t(first_of_line[line]) + particle;
        if (r >= first_of_line[line + 1]) return nullptr;
        return weight.data() + r * std::size_t(bins);
    }
    float at(uint32_t line, uint32_t particle, double time_s) const {
        const float* w = row(line, particle);
        return w != nullptr ? w[column(time_s)] : 1.0f;
    }
    // floor(time_s / bin_s), clamped to the columns, by the multiply: every step of a
    // frame's trace asks, and the division, or checking the product against it near a
    // column's edge, was a large share of the frame. NaN gives column 0.
    int column(double time_s) const {
        const double u = time_s * inverse_bin_s;
        return u > 0.0 ? (u < double(bins) ? int(u) : bins - 1) : 0;
    }
};

struct TraceSettings {
    PhysicsMode mode = PhysicsMode::acoustic;
    double step_texels = 0.5;    // step length s in texels (of the smallest spacing)
    double frequency_mhz = 5.0;  // attenuation alpha*f and scattering
    uint64_t seed = 1;

    // The physics switched on (simulator/physics_switches.h; all by default). Shear: at
    // a solid's interface (faster than kSolidSpeedMin: bone, wires) part of the energy
    // converts into the solid's shear wave (fluid_solid_fractions), which its attenuation
    // absorbs within millimetres at imaging frequencies: absorbed where it converts.
    // Bounces off: max_bounces 0. Face off: the probe face reflects nothing.
    PhysicsSet physics;
    int max_bounces = 64;  // reflections before a particle is retired

    LobeExponent lobe_exponent = LobeExponent::roughness;
    LobeWeight lobe_weight = LobeWeight::probability;
    double lobe_scale = 1.0;  // factor on c for the paper's interpretations

    double interface_threshold = 0.005;  // relative change of Z per texel marking an interface
    // How far (mm) on each side of a steep step the tracer looks for the plateaus that
    // make it a sharp interface (one reflection decision) rather than a graded medium
    // (refraction only). 0 = 8 texels. Volumes blur anatomy over a few voxels: MRI
    // ventricle walls span ~2-3 mm of 1 mm voxels, so scenes from volumes use 3 voxels.
    double interface_reach_mm = 0.0;
    double scattering_rate_per_mm =
        0.2;  // sub-resolution scattering events per mm at backscatter 1
    double scatter_echo_fraction = 1e-3;  // intensity fraction a scattering event sends back
    double roulette_energy = 1e-3;  // Russian roulette below this fraction of the initial energy
    // The one-way loss (dB/mm) the roulette's threshold follows with the particle's time:
    // below roulette_energy of the energy a particle would keep in tissue of this loss.
    // 0: a fixed threshold.
    double roulette_loss_db_per_mm = 0.0;
    // Reflections weaker than this intensity fraction R^2 are scored, not followed: the
    // expected echo is recorded as always, the reflected share E R^2 leaves the particle
    // as recorded energy and the particle transmits. Without it, a particle reflected
    // with probability 1e-3 carries 1000x its expected energy into every later echo:
    // isolated bright dots. The bias is the neglected multi-path through weak
    // reflectors, of relative order R^2. 0 = every reflection stochastic (unbiased).
    double follow_reflections_above = 0.0;
    // The echo of a path goes back the way it came: through a rough (diffuse) reflection
    // taken, only the share of the reversed lobe that heads back along the incoming way,
    // within this half-angle (rad: the receive aperture's, as the beam sees it), returns
    // (simulator::lobe_share of the sampled direction's angle from the mirror). It joins
    // the return factor; 0 = not applied (traces without an image).
    double diffuse_return_half_angle_rad = 0.0;
    double max_path_mm = 2000.0;  // paths end (energy "remaining") beyond this length
    // Paths end (energy "remaining") once their time of flight passes this (s); 0 = never.
    // An image's echo window: nothing a particle does later lands in it.
    double max_time_s = 0.0;

    // Uniform blocks of the map (AcousticMap::uniform_block) are crossed in a tight loop
    // without interpolation: the same arithmetic as the general step there. Off: every
    // step interpolates (for tests and benchmarks that compare the two).
    bool uniform_runs = true;
    // The general step of eight particles at once (vector registers), with the scalar
    // step's arithmetic: the same paths bit for bit. Off: one particle at a time (for
    // tests and benchmarks that compare the two). Not with a probe face or ring detector.
    bool vector_steps = true;
    // The transition around a texel (sharp or graded; plateaus, patch normal, middle) is
    // searched from the texel's centre once per trace and kept for the texel's later
    // interface events (in the head 5-20 events share a texel; a search takes 40-80
    // samples). Off: every event searches again, with the same results bit for bit (for
    // tests and benchmarks that compare the two).
    bool interface_cache = true;

    // The fluence and absorbed-energy maps (TraceResult::fluence, absorbed). Off: they
    // stay empty and the absorbed energy goes to the ledger only, per particle; a step
    // then writes no map (~6 % of a B-mode frame's trace, whose energy map is optional).
    bool deposition_maps = true;

    int record_paths = 0;              // particles per line whose paths are kept as polylines
    int record_paths_line_stride = 1;  // ... of the lines whose id is a multiple of this
    bool record_scatter_echoes = true;

    std::optional<EchoProfileSettings> echo_profile;
    std::shared_ptr<const ReceiveWeights> receive_weights;  // null: every echo counts fully

    // Set by the caller in the map frame; optional.
    std::optional<ProbeFace<2>> probe_face_2d;
    std::optional<ProbeFace<3>> probe_face_3d;
    std::optional<RingDetector> ring;

    // Throws base::InputError(source, field) naming the first bad parameter.
    void validate(const std::string& source) const;
};

std::string to_string(PhysicsMode mode);
std::string to_string(LobeExponent lobe);
std::string to_string(LobeWeight weight);

// Help texts, one per parameter, reused by the CLI.
namespace doc {
inline constexpr const char* kMode =
    "physics: 'acoustic' (Snell from speed of sound, reflection from impedance, attenuation, "
    "scattering) or 'paper' (one density field as refractive index, as in Reis & Bertram)";
inline constexpr const char* kStep = "integration step s, in texels of the map";
inline constexpr const char* kFrequency = "centre frequency for attenuation alpha*f";
inline constexpr const char* kSeed =
    "random seed; the same seed gives identical results on any thread count";
inline constexpr const char* kLobeExponent =
    "exponent c of the diffuse lobe cos^c: 'roughness' (c = 1/roughness^2 - 1), "
    "'reflecting-density' (c = scale*d1) or 'density-ratio' (c = scale*d1/d0)";
inline constexpr const char* kLobeWeight =
    "weight w = cos^c: 'probability' (direction drawn from w, energy kept) or 'energy' "
    "(direction uniform, energy multiplied by w)";
inline constexpr const char* kLobeScale = "factor on c for the paper's lobe interpretations";
inline constexpr const char* kInterfaceThreshold =
    "relative change of impedance per texel above which a step is at an interface";
inline constexpr const char* kScatteringRate =
    "sub-resolution scattering events per mm at backscatter 1";
inline constexpr const char* kRoulette =
    "Russian roulette below this fraction of a particle's initial energy (survivors go on "
    "with twice it)";
inline constexpr const char* kFollowReflections =
    "reflections with intensity fraction R^2 below this are scored (echo recorded, particle "
    "transmits with E(1-R^2)) instead of followed; 0 = all stochastic (unbiased)";
inline constexpr const char* kMaxBounces = "reflections after which a particle is retired";
}  // namespace doc

}  // namespace sonotrace::simulator
