#pragma once
// One B-mode frame from a volume and a probe: the grid under the probe, the acoustic
// map, beams, tracing and image formation (imaging/bmode.h). The default head's views
// and membranes are in imaging/colin27.h.
#include <chrono>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "imaging/bmode.h"
#include "imaging/channel_data.h"
#include "imaging/channel_scatterers.h"
#include "imaging/scan_conversion.h"
#include "probe/beam.h"
#include "probe/pose.h"
#include "probe/transducer.h"
#include "probe/transmit.h"
#include "simulator/trace_settings.h"
#include "simulator/tracer.h"
#include "tissue/acoustic_map.h"
#include "tissue/point_target.h"
#include "tissue/property_maps.h"
#include "tissue/transfer_function.h"

namespace sonotrace::imaging {

// How echoes reach the image (README, "sonotrace simulate": receive model).
enum class ReceiveModel {
    monostatic,  // every reflection/scattering event echoes at twice its time (default)
    capture,     // reflections count only when the particle itself reaches the face, which
                 // reflects part of it back (reverberation between face and tissue)
};
std::string to_string(ReceiveModel model);

// Speed/quality trade-off: map resolution and particles per line.
enum class Quality { interactive, standard, high };
struct QualityName {
    std::string_view name;  // --quality, the dataset spec's "quality", the sidecar
    Quality quality;
};
// Every quality by its one name, fastest first.
const std::vector<QualityName>& quality_names();
std::string to_string(Quality quality);
// The quality of that name; throws base::InputError(source, field) listing the names.
Quality parse_quality(const std::string& name, const std::string& source, const std::string& field);
struct QualityLevel {
    double map_pixel_mm;     // resolution of the acoustic map
    int particles_per_line;  // particles each scan line emits
    double step_texels;      // the tracer's step length, in map texels
    double sub_line_sigmas;  // speckle sub-line spacing (ImagingSettings::sub_line_sigmas)
    // Channel frames' scatterers per resolution cell (ScattererSettings): their cost is
    // scatterers x elements per transmit.
    double scatterers_per_cell;
};
QualityLevel quality_level(Quality quality);

// The physics a user switches off to take an artifact apart: the GUI's toggles and
// `simulate --disable`. Every switch on is the simulator's physics.
using PhysicsSwitches = simulator::PhysicsSet;
using simulator::Physics;
// "name: description; ..." for every switch (simulator/physics_switches.h), for --help.
std::string physics_switch_help();
// The switch of that name (a programming error if there is none).
const simulator::PhysicsSwitch& physics_switch(std::string_view name);
// "refraction,specular,..." (the switches' names; empty = none) switched off; throws
// base::InputError naming `source` and `field` for an unknown name.
PhysicsSwitches disabled_physics(const std::string& list, const std::string& source,
                                 const std::string& field);
// The names of the switches `physics` has off, in the table's order ("refraction,...").
std::string disabled_names(const PhysicsSwitches& physics);

// Switches off in a trace's settings what `physics` has off and leaves the rest (a trace
// configuration's own choices stand).
void switch_off(const PhysicsSwitches& physics, simulator::TraceSettings& trace);

struct SimulationSettings;
// Sets the tracer's and the image's settings from the switches (the transducer's face
// reflectivity too).
void apply(const PhysicsSwitches& physics, SimulationSettings& settings);

struct SimulationSettings {
    probe::Transducer transducer;
    Quality quality = Quality::standard;
    ReceiveModel receive = ReceiveModel::monostatic;
    ImagingSettings imaging;
    // Frequency, seed, echo profile are set from the rest. Reflections under R^2 = 1%
    // (brain/CSF 0.08%, fat/brain 0.6%; bone/brain 37%) are scored, not followed.
    // Scattering returns 1e-4 of the energy per event: with 0.2 events/mm that is
    // ~5e-7 per 0.25 mm cell at backscatter 0.35, the order of soft tissue's backscatter
    // coefficient (1e-4..1e-3 /(cm sr)) over a resolution cell and an F/2 aperture, and
    // 30 dB below a brain/CSF wall (R^2 = 7.6e-4), as in intraoperative images.
    simulator::TraceSettings trace = [] {
        simulator::TraceSettings s;
        s.follow_reflections_above = 0.01;
        s.scatter_echo_fraction = 1e-4;
        return s;
    }();
    uint64_t seed = 1;
    double step_texels = 0.0;  // the tracer's step (texels); 0 = the quality's
    // Gaussian sigma (mm) of the soft-tissue refractive index the rays bend in
    // (tissue::soft_tissue_smoothed_index); unset: fresnel_smoothing_mm of the
    // transducer; 0: the map's own index, texel by texel.
    std::optional<double> refraction_smoothing_mm;
    // Sub-resolution targets (world mm), imaged through the beam's field (point_echoes).
    // Their cores are painted into the maps by whoever builds them (phantoms/); the
    // tracer's echoes within a core's radius + `target_margin_mm` are its own and dropped.
    std::vector<tissue::PointTarget> targets;
    double target_margin_mm = 0.5;
    // 2: the particles are traced in the scan plane; 3: in the slab the elevation beam
    // spans (slab_grid), launched over the elevation aperture through the lens, their
    // echoes weighted by the lens's receive, so the frame integrates over the slice.
    int trace_dimensions = 2;
    // Keep the reflection echoes the image is made from in Frame::echoes (analysis:
    // which events light a region).
    bool keep_echoes = false;
    // Unfocused transmits (plane or diverging waves) with each element's channel data,
    // beamformed by delay-and-sum (imaging/channel_frame.h); unset: focused line by line.
    // The channels are sampled at imaging.sampling_mhz; their scatterers' density is the
    // quality's (QualityLevel::scatterers_per_cell).
    std::optional<probe::TransmitScheme> transmit;

    // Throws base::InputError naming the first bad parameter.
    void validate(const std::string& source) const;
};

// The ranges SimulationSettings::validate holds these to (a frame request's --help quotes
// them: phantoms/scene/request.h).
struct ValueRange {
    double low, high;
};
inline constexpr ValueRange kStepTexelsRange{0.0, 100.0};
inline constexpr ValueRange kRefractionSmoothingRange{0.0, 20.0};  // mm
inline constexpr ValueRange kGainRange{-200.0, 200.0};             // dB
inline constexpr ValueRange kDynamicRangeRange{1.0, 200.0};        // dB
inline constexpr ValueRange kPixelRange{0.01, 10.0};               // mm
inline constexpr ValueRange kNoiseSnrRange{-40.0, 120.0};          // dB

// The Fresnel scale of a probe's image: sigma = sqrt(lambda D) / 2, the Gaussian whose 1/e
// radius (sqrt(2) sigma) is the first Fresnel zone's radius sqrt(lambda D / 2) at half the
// image depth D. Convex preset: 3.0 mm; linear 1.4 mm; phased 4.1 mm.
double fresnel_smoothing_mm(const probe::Transducer& t);
// The refraction smoothing a frame uses: the settings' or the transducer's Fresnel scale.
double refraction_smoothing_mm(const SimulationSettings& s);
// The acoustic map a frame is traced in: the property maps packed with the settings'
// refraction smoothing.
tissue::AcousticMap<2> frame_map(const tissue::PropertyMaps& maps, const SimulationSettings& s);

// The probe-aligned grid that holds a transducer's scanned region plus margins, and the
// offset from probe-plane coordinates to the map frame (map = plane + to_map).
struct PlaneGrid {
    tissue::VolumeGeometry geometry;  // one slice, or the slab of a 3D frame
    glm::dvec2 to_map{0.0};
    double top_margin_mm = 0.0;  // how far the grid starts above the face
    // A slab: its slice on the scan plane, and that plane's elevation in the map frame.
    int plane_slice = 0;
    double plane_elevation_in_map = 0.0;
};
PlaneGrid plane_grid(const probe::Transducer& t, const probe::Pose& pose, double pixel_mm);
// The slab a 3D frame traces: the plane grid with slices `elevation_pixel_mm` apart over
// the lens's slab (probe::ElevationTable::slab_half_mm), an odd number so that the middle
// one lies on the scan plane.
PlaneGrid slab_grid(const probe::Transducer& t, const probe::Pose& pose, double pixel_mm,
                    double elevation_pixel_mm);
// The backscatter the image lights the plane's speckle with when the trace ran in a slab:
// sqrt(w_0 b^2 + sum over the slab's other slices of w_k b_k^2), b the plane's own (at its
// resolution) and b_k the slab's slices at the same point, with w the lens's two-way
// intensity |U|^4 at each slice's elevation and the depth, normalised over the slab
// (probe/elevation.h): a cyst thinner than the slice lets the tissue beside it light
// its speckle.
void light_from_slab(tissue::PropertyMaps& plane, const PlaneGrid& plane_grid,
                     const tissue::PropertyMaps& slab, const PlaneGrid& slab_grid,
                     const probe::Transducer& t);

// The particles a frame launches: lines x particles per line, or transmits x particles per
// transmit (imaging/channel_frame.h).
std::size_t frame_particles(const SimulationSettings& settings);

// The tracer's settings of a frame, before what its mode adds: the settings' own with the
// step of the quality, the probe's frequency, the roulette following the automatic TGC's
// loss, and the seed.
simulator::TraceSettings frame_trace_settings(const SimulationSettings& settings);

// Maps the tracer's map frame back to world coordinates.
MapToWorld map_to_world(const probe::Pose& pose, const PlaneGrid& grid);

struct Frame {
    LineData rf, envelope;
    ScanConverted image;  // the display: TGC + log compression, 0..1, scan-converted
    simulator::EnergyLedger ledger;
    simulator::TraceStats stats;
    // Energy deposition map on the grid of the plane, up to the close of the echo window
    // (empty if SimulationSettings::trace.deposition_maps is off).
    tissue::Volume absorbed;
    std::vector<simulator::Path<2>> paths;        // SimulationSettings::trace.record_paths per line
    std::vector<simulator::EchoEvent<2>> echoes;  // SimulationSettings::keep_echoes
    std::optional<ChannelData> channels;          // SimulationSettings::transmit
    // With `channels`: the beamformed envelope on the image's pixels (CV_32F, linear, before
    // TGC and compression; 1 = a perpendicular reflector of R = 1 at each element).
    cv::Mat beamformed;
    nlohmann::json timings = nlohmann::json::object();  // seconds per stage
};

using FrameProgress = std::function<void(std::size_t done, std::size_t total)>;

// Runs `work` and adds its seconds to frame.timings[name] (a stage run more than once, as
// per transmit, sums).
template <class Work>
void timed_stage(Frame& frame, const char* name, Work&& work) {
    const auto start = std::chrono::steady_clock::now();
    work();
    frame.timings[name] =
        frame.timings.value(name, 0.0) +
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Whether a point of the map frame lies in a target's core (within its core radius), by
// cells as wide as the largest radius: a tilted wire is thousands of pieces, and every
// reflection echo of a frame asks.
class TargetCores {
  public:
    explicit TargetCores(const std::vector<PointEcho>& points);
    bool contains(const glm::dvec2& at) const;

  private:
    glm::ivec2 cell_of(const glm::dvec2& at) const;
    static uint64_t key(const glm::ivec2& c);
    const std::vector<PointEcho>& points_;
    double cell_ = 1e-3;
    std::unordered_map<uint64_t, std::vector<uint32_t>> cells_;
};

// The echoes of the targets that cross this plane (points weighted by the elevation
// profile of the slice, tissue/point_target.h), at their map-frame positions, with the
// two-way losses of the straight path from the face to each: attenuation, and 1 - R^2
// of every impedance step on the way (a smoothed step counts once, as one monotone run);
// and the path's travel time against c0's, as the extra range its echo seems to come
// from (PointEcho::delay_mm). `margin_mm` keeps a target's own painted core out of its
// path.
std::vector<PointEcho> point_echoes(const std::vector<tissue::PointTarget>& targets,
                                    const tissue::AcousticMap<2>& map, const PlaneGrid& grid,
                                    const probe::Pose& pose, const probe::Transducer& t,
                                    double margin_mm);

// Traces and forms one frame on an acoustic map built on plane_grid(...).
Frame simulate_frame(const tissue::AcousticMap<2>& map, const PlaneGrid& grid,
                     const probe::Pose& pose, const SimulationSettings& settings,
                     const FrameProgress& progress = {});
// The same traced in 3D: `map` over the slab `slab` (slab_grid), the image made on
// `plane` over `grid` (plane_grid; its backscatter from light_from_slab). The echoes are
// projected on the plane after the trace; a reflector tilted in elevation echoes by the
// lens's plane response sinc^2(2 H sin(beta) / lambda).
Frame simulate_frame(const tissue::AcousticMap<3>& map, const PlaneGrid& slab,
                     const tissue::AcousticMap<2>& plane, const PlaneGrid& grid,
                     const probe::Pose& pose, const SimulationSettings& settings,
                     const FrameProgress& progress = {});

// What lies on a plane grid: property maps and, on request, tissue labels.
using PlaneMapper =
    std::function<tissue::PropertyMaps(const tissue::VolumeGeometry& grid, tissue::Volume* labels)>;

struct ScenePlacement;
struct SimulatedFrame {
    Frame frame;
    PlaneGrid grid;  // the plane's (scan_plane): what a caller's own truth maps sample
    // The ground truth on request (truth_at_echo, scan_convert_labels).
    std::optional<cv::Mat> labels;        // tissue labels where they lie
    std::optional<cv::Mat> echo_labels;   // the same where the echoes show them
    std::optional<cv::Mat> true_depth;    // the true depth of what each pixel shows
    std::optional<cv::Mat> echogenicity;  // and its backscatter
};

// A frame with what lies in its plane: the plane's grid, property maps (their backscatter
// from light_from_slab after a 3D trace) and, on request, tissue labels; the slab traced.
struct PlaneScan {
    PlaneGrid grid;
    std::optional<PlaneGrid> slab;
    tissue::PropertyMaps maps;
    std::optional<tissue::Volume> labels;
    Frame frame;
};
// The grid under the probe (plane_grid), its properties from `mapper`, prepared for the
// scene (prepare_plane), its acoustic map, then the frame. A 3D trace (trace_dimensions
// 3) runs in a slab (slab_grid) of twice the map pixel in the plane and four times across
// it: an eighth of the texels of the plane's resolution, for a frame a few times the 2D
// one's cost; the image and the labels keep the plane's resolution.
PlaneScan scan_plane(const PlaneMapper& mapper, const ScenePlacement& scene,
                     const SimulationSettings& settings, bool with_labels,
                     const FrameProgress& progress = {});
// scan_plane's frame and (optionally) its labels scan-converted.
SimulatedFrame simulate_plane(const PlaneMapper& mapper, const ScenePlacement& scene,
                              const SimulationSettings& settings, bool with_labels,
                              const FrameProgress& progress = {});

// Where a scene puts the probe and what it does to the tissue under it (the default
// head's views: imaging/colin27.h).
struct ScenePlacement {
    probe::Pose pose;
    double craniotomy_radius_mm = 0.0;  // 0 = no craniotomy
    double craniotomy_depth_mm = 0.0;   // below the face
    std::string description;
};

// Saline filling the craniotomy, and coupling gel (water properties).
tissue::AcousticProperties saline();

// Readies the property maps of a plane grid for the probe: air between the face and
// `gel_mm` below it becomes coupling gel (as on a real scan), and the scene's craniotomy
// is opened. Returns the number of samples changed.
// `labels` (tissue labels of the same grid, optional) become water where saline went.
std::size_t prepare_plane(tissue::PropertyMaps& maps, const PlaneGrid& grid,
                          const ScenePlacement& scene, double gel_mm = 5.0,
                          tissue::Volume* labels = nullptr);

// The ground truth in the frame's geometry: the label of the grid texel under each
// pixel centre (nearest: labels are not interpolated), 0 outside the scanned region.
// True positions: the frame shows echoes where their delays put them, so speed-of-sound
// displacement and refraction show up as differences between the two
// (scan_convert_labels_at_echo undoes the first).
cv::Mat scan_convert_labels(const tissue::Volume& labels, const PlaneGrid& grid,
                            const ScanConverted& frame);

// The labels where the image shows them: each pixel's displayed depth (c0 t / 2, c0 =
// tissue::kReferenceSpeed) taken back to the true depth along its line through the speed
// of sound on the way (straight ray, no refraction): behind a skull's millimetres at 3,500
// m/s the anatomy shows a few millimetres closer than it lies. 0 where what a pixel shows
// lies past the grid (the frame's bottom millimetres behind a skull).
cv::Mat scan_convert_labels_at_echo(const tissue::Volume& labels, const tissue::PropertyMaps& maps,
                                    const PlaneGrid& grid, const probe::Transducer& t,
                                    const ScanConverted& frame);

// Shape instances (a phantom's shape index, 1-based) under each pixel centre, as
// scan_convert_labels, in 16 bits (CV_16U).
cv::Mat scan_convert_instances(const tissue::Volume& instances, const PlaneGrid& grid,
                               const ScanConverted& frame);

// The ground truth of what each pixel shows, found as scan_convert_labels_at_echo finds
// it (display depth taken back along the line through the speed of sound; no refraction):
struct TruthAtEcho {
    cv::Mat labels;  // CV_8U: the tissue label there
    // CV_32F, mm: its true depth, along the pixel's line from the face (the depth the
    // display would show it at in a medium of c0 everywhere); 0 outside the scan.
    cv::Mat depth_mm;
    // CV_32F: its echogenicity with nothing in the way, the map's backscatter (0..1, the
    // speckle's mean power goes as its square) with no attenuation, shadowing or TGC;
    // 0 outside the scan or past the grid.
    cv::Mat echogenicity;
};
TruthAtEcho truth_at_echo(const tissue::Volume& labels, const tissue::PropertyMaps& maps,
                          const PlaneGrid& grid, const probe::Transducer& t,
                          const ScanConverted& frame);

// Colour picture of a label image (one fixed colour per tissue of tissue_table()).
cv::Mat label_picture(const cv::Mat& labels);
// The colour (BGR) label_picture gives a tissue label; black for an unknown one.
cv::Vec3b label_colour(int label);

}  // namespace sonotrace::imaging
