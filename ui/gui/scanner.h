#pragma once
// The live scanner behind the demo GUI: a worker thread that turns the latest request
// (scene, probe pose, settings) into a B-mode frame, then, while the probe stays still,
// refines it (interactive -> standard -> high quality) and renders the 3D context by
// PBVR between the stages. A new request cancels the work in progress at the next scan
// line, so the image follows the probe at once; the UI thread only polls for results
// and never waits. No OpenGL here: the tests drive it directly.
#include <array>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "imaging/pbvr/camera.h"
#include "imaging/pbvr/pbvr.h"
#include "imaging/simulation.h"
#include "phantoms/scene/request.h"
#include "ui/gui/scene.h"

namespace sonotrace::gui {

// The switches a student flips to make an artifact vanish and return.
using PhysicsSwitches = imaging::PhysicsSwitches;

inline constexpr int kTgcSliders = 8;  // evenly spaced over the imaging depth

// The transmit: focused line by line, or unfocused waves whose channel data are
// beamformed by delay-and-sum and compounded (open arrays: probe/transmit.h).
struct TransmitControls {
    enum class Kind { focused, plane, diverging };
    // Each kind's --transmit name (the GUI's option, the scheme's prefix) and its label on
    // the panel, in Kind's order.
    struct KindName {
        Kind kind;
        const char* name;
        const char* label;
    };
    static constexpr std::array<KindName, 3> kKinds{{
        {Kind::focused, "focused", "focused (line by line)"},
        {Kind::plane, "plane", "plane waves"},
        {Kind::diverging, "diverging", "diverging waves"},
    }};
    static const KindName& name_of(Kind k) { return kKinds[std::size_t(k)]; }
    Kind kind = Kind::focused;
    int count = 5;          // transmits, their steering angles evenly over +-span_deg
    double span_deg = 8.0;  // the outermost steering angle (degrees)
    // --transmit's text for this probe: "focused", "plane:0", "plane:-8:8:5",
    // "diverging:D:-8:8:5" with the virtual source D behind the face: half a flat array's
    // length (a wave that opens 90 degrees), a curved array's radius (its centre of
    // curvature: the wave opens as its arc).
    std::string text(const probe::Transducer& t) const;
};

// Everything the control panel sets. One validated conversion to the simulator's
// settings (settings()); ranges for the sliders live in controls.h.
struct ScanParameters {
    probe::Transducer transducer = probe::find_transducer("convex", "gui");
    imaging::Quality quality = imaging::Quality::interactive;
    imaging::ReceiveModel receive = imaging::ReceiveModel::monostatic;
    int trace_dimensions = 2;  // 3: the slab of the elevation beam (slower)
    TransmitControls transmit;
    double gain_db = 0.0;
    double dynamic_range_db = 60.0;
    std::array<double, kTgcSliders> tgc_db{};  // added to the automatic TGC (0.6 dB/(cm MHz))
    PhysicsSwitches physics;
    uint64_t seed = 1;

    // The frame request these controls make (what `simulate` would be given).
    scene::FrameRequest request() const;
    // Its settings on `scene`; throws base::InputError naming the field when out of range.
    imaging::SimulationSettings settings(const Scene& scene) const;
};

// The 3D context view's camera: an orbit about the volume, zoom as a distance factor.
struct ContextView {
    bool enabled = true;
    // The worker only generates the particles (ContextSplats) and the UI thread projects
    // and averages them in OpenGL (gl_pbvr.h); false: the worker's CPU renderer does it all.
    bool gpu = false;
    double azimuth_deg = 235.0, elevation_deg = 18.0, zoom = 1.0;
    int width = 320, height = 320;
    bool operator==(const ContextView&) const = default;
};

struct ScanRequest {
    std::shared_ptr<const Scene> scene;
    probe::Pose pose;
    ScanParameters parameters;
    ContextView context;
    int paths_per_line = 0;    // particle paths kept for drawing ...
    int path_line_stride = 1;  // ... on the lines whose id is a multiple of this
    bool refine = true;        // finer qualities while nothing new arrives
};

struct ScanFrame {
    uint64_t request = 0;  // ScanRequest number (Scanner::submit's return)
    imaging::Quality quality = imaging::Quality::interactive;
    probe::Pose pose;
    imaging::SimulationSettings settings;
    imaging::PlaneGrid grid;
    imaging::Frame frame;  // B-mode, energy map, paths, statistics, timings
    cv::Mat slice;         // CV_8UC3 RGB on the plane grid: the tissues under the probe
    // The tissue labels in the slice, with the share of its texels each covers, largest
    // first (the tissue view's legend).
    std::vector<std::pair<int, double>> tissues;
    double seconds = 0.0;  // wall time to simulate it
};

struct ContextImage {
    uint64_t request = 0;
    cv::Mat rgb;  // CV_8UC3
    int repetitions = 0;
    imaging::pbvr::OrbitCamera camera;
    double seconds = 0.0;  // since the request began
};

// One repetition of the context's particles for the GPU path (ContextView::gpu): the
// UI thread draws them into a gl::GlPbvr, a new one whenever `ensemble` changes.
struct ContextSplats {
    uint64_t request = 0;
    uint64_t ensemble = 0;  // a new camera, frame or scene starts a new ensemble
    int width = 0, height = 0, subpixel_level = 1;
    glm::vec3 background{0.0f};
    std::vector<uint64_t> overlay;  // the frame's layer (PbvrRenderer::set_overlay)
    std::vector<imaging::pbvr::Splat> splats;
    imaging::pbvr::OrbitCamera camera;
    double seconds = 0.0;  // since the request began
};

// The camera of a context view of a scene (the orbit fitted to its volume).
imaging::pbvr::OrbitCamera context_camera(const Scene& scene, const ContextView& view);

class Scanner {
  public:
    Scanner();
    ~Scanner();
    Scanner(const Scanner&) = delete;
    Scanner& operator=(const Scanner&) = delete;

    // Replaces any pending request and cancels the work in progress. Returns its number.
    uint64_t submit(ScanRequest request);
    // The newest finished frame / context image not taken yet.
    std::optional<ScanFrame> take_frame();
    std::optional<ContextImage> take_context();
    // The oldest repetition of particles not drawn yet (GPU path). The worker waits while
    // a few are queued, so it never runs far ahead of the screen.
    std::optional<ContextSplats> take_context_splats();
    // The last error (bad parameters, a failed frame), with the request it belongs to.
    std::optional<std::string> take_error();
    // True while a request is being worked on or refined.
    bool busy() const;

  private:
    void run();
    void work(const ScanRequest& request, uint64_t id);

    mutable std::mutex mutex_;
    std::condition_variable wake_;
    std::optional<ScanRequest> pending_;
    uint64_t next_id_ = 0, pending_id_ = 0;
    std::optional<ScanFrame> frame_;
    std::optional<ContextImage> context_;
    std::deque<ContextSplats> context_splats_;
    std::condition_variable drained_;  // context_splats_ shrank
    uint64_t ensembles_ = 0;
    std::optional<std::string> error_;
    bool working_ = false, stop_ = false;
    struct ContextCache;
    std::unique_ptr<ContextCache> cache_;  // worker only
    std::thread thread_;
};

// Simulates one frame of a request at a quality, synchronously (the worker's core).
// `cancelled` is polled once per scan line; when it returns true the frame is abandoned
// (returns nullopt).
std::optional<ScanFrame> simulate_request(const ScanRequest& request, imaging::Quality quality,
                                          const std::function<bool()>& cancelled = {});

}  // namespace sonotrace::gui
