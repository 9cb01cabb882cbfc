#include "ui/gui/scanner.h"

#include <algorithm>
#include <chrono>
#include <map>
#include <opencv2/imgproc.hpp>

#include "imaging/pbvr/overlay.h"
#include "imaging/pbvr/pbvr.h"
#include "probe/array_geometry.h"
#include "tissue/base/error.h"
#include "tissue/base/number_list.h"

namespace sonotrace::gui {

namespace {

using clock_type = std::chrono::steady_clock;
double seconds_since(clock_type::time_point start) {
    return std::chrono::duration<double>(clock_type::now() - start).count();
}

// Thrown from the tracer's per-line progress callback to abandon a frame.
struct Cancelled {};

// The tissues of a plane grid as an atlas picture (RGB), shaded a little by impedance so
// that interfaces inside one tissue class still show.
cv::Mat slice_picture(const tissue::Volume& labels, const tissue::PropertyMaps& maps) {
    const glm::ivec3 n = labels.geometry().dims;
    cv::Mat label_image(n.y, n.x, CV_8U);
    for (int j = 0; j < n.y; ++j)
        for (int i = 0; i < n.x; ++i)
            label_image.at<uint8_t>(j, i) = uint8_t(std::clamp(labels.at(i, j, 0), 0.0f, 255.0f));
    cv::Mat bgr = imaging::label_picture(label_image);
    const auto& rho = maps[tissue::Property::density];
    const auto& c = maps[tissue::Property::speed_of_sound];
    for (int j = 0; j < n.y; ++j) {
        for (int i = 0; i < n.x; ++i) {
            // Impedance 0.4 (air) .. 7.8 MRayl (bone) -> 0.55 .. 1 brightness.
            const float z = rho.at(i, j, 0) * c.at(i, j, 0) * 1e-6f;
            const float shade = 0.55f + 0.45f * std::clamp((z - 1.3f) / 1.0f, 0.0f, 1.0f);
            cv::Vec3b& p = bgr.at<cv::Vec3b>(j, i);
            for (int k = 0; k < 3; ++k) p[k] = uint8_t(float(p[k]) * shade);
        }
    }
    cv::Mat rgb;
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    return rgb;
}

std::vector<std::pair<int, double>> tissues_present(const tissue::Volume& labels) {
    std::map<int, std::size_t> count;
    for (float v : labels.voxels()) ++count[int(v)];
    std::vector<std::pair<int, double>> out;
    for (const auto& [label, n] : count)
        if (label > 0) out.emplace_back(label, double(n) / double(labels.size()));
    std::stable_sort(out.begin(), out.end(),
                     [](const auto& a, const auto& b) { return a.second > b.second; });
    return out;
}

}  // namespace

std::string TransmitControls::text(const probe::Transducer& t) const {
    using base::exact_number_text;
    const std::string name = name_of(kind).name;
    if (kind == Kind::focused) return name;
    const std::string angles = count == 1
                                   ? std::string("0")
                                   : exact_number_text(-span_deg) + ":" +
                                         exact_number_text(span_deg) + ":" + std::to_string(count);
    if (kind == Kind::plane) return name + ":" + angles;
    const double curvature = probe::array_geometry(t)->face_radius_mm();
    return name + ":" + exact_number_text(curvature > 0.0 ? curvature : 0.5 * t.array_length_mm()) +
           ":" + angles;
}

scene::FrameRequest ScanParameters::request() const {
    using base::exact_number_text;
    scene::FrameRequest r;
    r.probe = transducer.name;
    for (const auto& doc : probe::transducer_parameter_docs())
        r.transducer[doc.key] = probe::parameter_text(doc.get(transducer));
    r.quality = imaging::to_string(quality);
    r.receive = imaging::to_string(receive);
    r.trace = trace_dimensions == 3 ? "3d" : "2d";
    r.transmit = transmit.text(transducer);
    r.seed = seed;
    r.gain_db = gain_db;
    r.dynamic_range_db = dynamic_range_db;
    // TGC: the automatic curve for brain plus the sliders.
    r.tgc.clear();
    for (int k = 0; k < kTgcSliders; ++k) {
        const double depth = transducer.depth_mm * (k + 0.5) / kTgcSliders;
        r.tgc += (k ? "," : "") + exact_number_text(depth) + ":" +
                 exact_number_text(imaging::automatic_tgc_db(transducer.frequency_mhz, depth) +
                                   tgc_db[std::size_t(k)]);
    }
    r.pixel_mm = std::max(0.1, transducer.depth_mm / 400.0);
    r.disable = imaging::disabled_names(physics);
    r.energy = true;  // the energy view
    return r;
}

imaging::SimulationSettings ScanParameters::settings(const Scene& scene) const {
    return scene::make_settings(request(), scene, "gui settings");
}

imaging::pbvr::OrbitCamera context_camera(const Scene& scene, const ContextView& view) {
    imaging::pbvr::OrbitCamera camera =
        imaging::pbvr::fit_camera(scene.context->geometry(), view.azimuth_deg, view.elevation_deg,
                                  30.0, view.width, view.height);
    camera.distance_mm /= std::clamp(view.zoom, 0.25, 8.0);
    return camera;
}

std::optional<ScanFrame> simulate_request(const ScanRequest& request, imaging::Quality quality,
                                          const std::function<bool()>& cancelled) {
    const auto start = clock_type::now();
    const Scene& scene = *request.scene;
    ScanFrame out;
    ScanParameters parameters = request.parameters;
    parameters.quality = quality;
    out.settings = parameters.settings(scene);
    out.settings.trace.record_paths = request.paths_per_line;
    out.settings.trace.record_paths_line_stride = request.path_line_stride;
    out.quality = quality;
    out.pose = scene.clamp(request.pose);
    imaging::ScenePlacement placement = scene.start;
    placement.pose = out.pose;

    try {
        imaging::PlaneScan scan = imaging::scan_plane(scene.mapper, placement, out.settings, true,
                                                      [&](std::size_t, std::size_t) {
                                                          if (cancelled && cancelled())
                                                              throw Cancelled{};
                                                      });
        out.grid = std::move(scan.grid);
        out.slice = slice_picture(*scan.labels, scan.maps);
        out.tissues = tissues_present(*scan.labels);
        out.frame = std::move(scan.frame);
    } catch (const Cancelled&) {
        return std::nullopt;
    }
    out.seconds = seconds_since(start);
    return out;
}

// The worker's context renderer, rebuilt when the scene changes.
struct Scanner::ContextCache {
    std::shared_ptr<const Scene> scene;  // held: a new scene never reuses a stale volume
    std::unique_ptr<imaging::pbvr::RenderVolume> volume;
};

Scanner::Scanner() : cache_(std::make_unique<ContextCache>()), thread_([this] { run(); }) {}

Scanner::~Scanner() {
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake_.notify_all();
    drained_.notify_all();
    thread_.join();
}

uint64_t Scanner::submit(ScanRequest request) {
    std::lock_guard lock(mutex_);
    pending_ = std::move(request);
    pending_id_ = ++next_id_;
    wake_.notify_all();
    return pending_id_;
}

std::optional<ScanFrame> Scanner::take_frame() {
    std::lock_guard lock(mutex_);
    return std::exchange(frame_, std::nullopt);
}

std::optional<ContextImage> Scanner::take_context() {
    std::lock_guard lock(mutex_);
    return std::exchange(context_, std::nullopt);
}

std::optional<ContextSplats> Scanner::take_context_splats() {
    std::lock_guard lock(mutex_);
    if (context_splats_.empty()) return std::nullopt;
    ContextSplats out = std::move(context_splats_.front());
    context_splats_.pop_front();
    drained_.notify_all();
    return out;
}

std::optional<std::string> Scanner::take_error() {
    std::lock_guard lock(mutex_);
    return std::exchange(error_, std::nullopt);
}

bool Scanner::busy() const {
    std::lock_guard lock(mutex_);
    return working_ || pending_.has_value();
}

void Scanner::run() {
    for (;;) {
        ScanRequest request;
        uint64_t id = 0;
        {
            std::unique_lock lock(mutex_);
            wake_.wait(lock, [&] { return stop_ || pending_.has_value(); });
            if (stop_) return;
            request = std::move(*pending_);
            pending_.reset();
            id = pending_id_;
            working_ = true;
        }
        try {
            work(request, id);
        } catch (const std::exception& e) {
            std::lock_guard lock(mutex_);
            error_ = e.what();
        }
        std::lock_guard lock(mutex_);
        working_ = false;
    }
}

void Scanner::work(const ScanRequest& request, uint64_t id) {
    auto superseded = [this] {
        std::lock_guard lock(mutex_);
        return stop_ || pending_.has_value();
    };
    // The requested quality first; then, while the probe is still, finer frames with
    // the 3D context's repetitions in between (its image shows the frame).
    const int context_repetitions[] = {2, 8, 24};  // per quality
    constexpr int kContextSubpixels = 1;
    constexpr int kContextRestMs = 150;  // a still probe's pause before the context starts
    std::unique_ptr<imaging::pbvr::PbvrRenderer> renderer;
    std::optional<imaging::pbvr::FrameOverlay> overlay;
    int generated = 0;  // GPU path: repetitions handed to the UI for this renderer
    uint64_t ensemble = 0;
    std::vector<uint64_t> layer;
    const auto context_start = clock_type::now();
    const int requested = int(request.parameters.quality);
    for (int stage = requested; stage <= int(imaging::Quality::high); ++stage) {
        if (stage > requested && !request.refine) break;
        {
            // The requested quality always completes (a dragged probe still gets frames);
            // refinements give way to the next request.
            std::optional<ScanFrame> frame =
                simulate_request(request, imaging::Quality(stage),
                                 stage == requested ? std::function<bool()>() : superseded);
            if (!frame) return;
            frame->request = id;
            // The context shows this frame; its renderer is built when its turn comes.
            if (request.context.enabled && request.scene->context) {
                overlay = imaging::pbvr::FrameOverlay{};
                frame->frame.image.image.convertTo(overlay->frame, CV_8U, 255.0);
                overlay->origin_mm = frame->frame.image.origin;
                overlay->pixel_mm = glm::dvec2(frame->frame.image.pixel_mm);
                overlay->position = frame->pose.position;
                overlay->axial = frame->pose.axial();
                overlay->lateral = frame->pose.lateral();
                overlay->elevation = frame->pose.elevation();
                overlay->transducer = frame->settings.transducer;
                renderer.reset();
            }
            std::lock_guard lock(mutex_);
            frame_ = std::move(frame);
        }
        if (!overlay) continue;
        auto done = [&] { return request.context.gpu ? generated : renderer->repetitions_done(); };
        while (!renderer || done() < context_repetitions[stage]) {
            if (superseded()) return;
            if (!renderer) {
                // Setting a renderer up takes longer than a frame and cannot be cut short:
                // while the probe moves (a request every UI frame) the frames come first,
                // and the context waits until the probe has rested for a moment.
                {
                    std::unique_lock lock(mutex_);
                    if (wake_.wait_for(lock, std::chrono::milliseconds(kContextRestMs),
                                       [&] { return stop_ || pending_.has_value(); }))
                        return;
                }
                if (cache_->scene != request.scene) {
                    cache_->volume.reset();
                    cache_->volume = std::make_unique<imaging::pbvr::RenderVolume>(
                        *request.scene->context, request.scene->context_tf);
                    cache_->scene = request.scene;
                }
                const imaging::pbvr::OrbitCamera camera =
                    context_camera(*request.scene, request.context);
                imaging::pbvr::RenderSettings settings;
                settings.subpixel_level = kContextSubpixels;
                settings.seed = request.parameters.seed;
                settings.clip_plane = imaging::pbvr::camera_side_of_plane(
                    *overlay, request.scene->context->geometry(), camera);
                renderer = std::make_unique<imaging::pbvr::PbvrRenderer>(
                    *cache_->volume, request.scene->context_tf, camera, settings);
                layer = imaging::pbvr::overlay_layer(*overlay, camera, settings.subpixel_level);
                if (request.context.gpu) {
                    generated = 0;
                    std::lock_guard lock(mutex_);
                    ensemble = ++ensembles_;
                } else {
                    renderer->set_overlay(layer);
                }
                continue;  // a new request may have come meanwhile
            }
            if (request.context.gpu) {
                ContextSplats batch;
                batch.request = id;
                batch.ensemble = ensemble;
                batch.camera = context_camera(*request.scene, request.context);
                batch.width = batch.camera.width;
                batch.height = batch.camera.height;
                batch.subpixel_level = kContextSubpixels;
                if (generated == 0) batch.overlay = layer;
                batch.splats = renderer->splats(uint32_t(generated));
                batch.seconds = seconds_since(context_start);
                std::unique_lock lock(mutex_);
                drained_.wait(lock, [&] {
                    return stop_ || pending_.has_value() || context_splats_.size() < 3;
                });
                if (stop_ || pending_.has_value()) return;
                context_splats_.push_back(std::move(batch));
                ++generated;
                continue;
            }
            renderer->add_repetition();
            ContextImage image;
            image.request = id;
            cv::cvtColor(imaging::pbvr::to_picture(renderer->image()), image.rgb,
                         cv::COLOR_BGR2RGB);
            image.repetitions = renderer->repetitions_done();
            image.camera = context_camera(*request.scene, request.context);
            image.seconds = seconds_since(context_start);
            std::lock_guard lock(mutex_);
            context_ = std::move(image);
        }
    }
}

}  // namespace sonotrace::gui
