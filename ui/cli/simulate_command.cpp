#include "ui/cli/simulate_command.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <sstream>

#include "imaging/colin27.h"
#include "imaging/picture.h"
#include "imaging/simulation.h"
#include "imaging/video.h"
#include "phantoms/phantom.h"
#include "phantoms/scene/records.h"
#include "probe/array_geometry.h"
#include "probe/placement.h"
#include "sonotrace_version.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/file_read.h"
#include "tissue/base/json_util.h"
#include "tissue/image_io.h"
#include "tissue/property_maps.h"
#include "tissue/transfer_function.h"
#include "ui/dataset/channel_file.h"

namespace sonotrace::ui {

namespace {

using nlohmann::json;

// ---- the command line's own parameters, documented once ----
constexpr ParameterDoc kFormatsDoc = {
    "--formats", "",
    "comma list of frame formats: png8 (NAME.png), png16 (NAME_16.png), exr (NAME.exr, float "
    "0..1)"};
constexpr ParameterDoc kOutDoc = {"--out", "", "output directory"};
constexpr ParameterDoc kNameDoc = {"--name", "", "file stem of the frame and its sidecar"};
constexpr ParameterDoc kJsonDoc = {
    "--json", "", "also write the run record (description and timings); '-' = stdout"};
constexpr ParameterDoc kVideoDoc = {
    "--video", "",
    "container of the sweep's video: mp4 (H.264, plays in browsers) or avi "
    "(Motion JPEG); empty = frames only"};
constexpr ParameterDoc kFpsDoc = {"--fps", "1/s", "frame rate of the sweep's video"};
constexpr ParameterDoc kSceneDoc = {
    "--scene", "",
    "JSON file of option values, keys = option names without dashes (\"probe\": \"linear\", "
    "\"gain\": 40, \"formats\": [\"png8\", \"exr\"]); options given on the command line win; "
    "unknown keys are errors"};

// The files a request's parameter makes the command write (the table says what they hold).
const std::map<std::string, std::string> kFilesWritten = {
    {"labels",
     "Written as NAME_labels.png and NAME_labels_echo.png, with a colour preview of each; "
     "with them NAME_depth.exr (the true depth in mm of what each pixel shows), "
     "NAME_echogenicity.exr (its backscatter, 0..1, with no attenuation or shadowing on the "
     "way) and NAME_instances.png (16 bits: a phantom's shape index from 1, 0 background)"},
    {"energy", "Written as NAME_energy.png"},
    {"channels", "Written as NAME_channels.h5 (layout: docs/guide/channel-data.md)"},
    {"sweep", "Written as NAME_0000.png, ... and a video"},
};

// --frequency, --depth, ...: the transducer's parameters, each overriding the preset's.
void add_transducer_options(CLI::App& cmd, scene::FrameRequest& request) {
    for (const auto& doc : probe::transducer_parameter_docs()) {
        const std::string flag = std::string("--") + doc.key;
        std::string help = std::string(doc.description) + " (default: the preset's)";
        if (doc.unit[0] != '\0') help += std::string(" [") + doc.unit + "]";
        const char* type_name = std::visit(
            [](const auto& value) {
                using V = std::decay_t<decltype(value)>;
                return std::is_same_v<V, double> ? "FLOAT"
                       : std::is_same_v<V, int>  ? "INT"
                                                 : "TEXT";
            },
            doc.get(probe::Transducer{}));
        cmd.add_option(flag, request.transducer[doc.key], help)->type_name(type_name);
    }
}

// Frame (0..1, scan converted) as an image file of the requested format (png8: the
// grey levels of imaging::grey_levels).
void write_frame(const cv::Mat& image, const std::string& path, int bits) {
    std::vector<float> pixels(image.begin<float>(), image.end<float>());
    const float full_scale = bits == 8 ? 255.0f : bits == 16 ? 65535.0f : 1.0f;
    for (float& v : pixels) v = bits == 32 ? v : std::round(v * full_scale);  // stored as integers
    tissue::write_gray_image(path, image.cols, image.rows, pixels, bits);
}

// A sweep stops cleanly on SIGINT or SIGTERM: the frame in flight is finished, the video
// of the frames so far written, and the run exits 130. A second signal exits at once
// (the frame in flight's temporaries are left, and the next run removes them).
std::atomic<bool> g_stop_sweep{false};
extern "C" void on_sweep_signal(int) {
    if (g_stop_sweep.exchange(true)) _exit(130);
}

}  // namespace

CLI::App* add_simulate_command(CLI::App& app, SimulateOptions& o) {
    CLI::App* cmd = app.add_subcommand(
        "simulate",
        "Simulate a B-mode frame: beams from a transducer model are traced through the tissue "
        "map, their echoes become RF lines (pulse, speckle), envelope, TGC, log compression and "
        "a scan-converted image with a JSON sidecar. Without arguments: the Colin27 head, convex "
        "probe on the cortex through a craniotomy, written to out/bmode.png.");
    // The frame's parameters from the request's table, the transducer's after --probe.
    for (const scene::RequestParameter& p : scene::request_parameters()) {
        const std::string flag = "--" + p.key;
        const auto files = kFilesWritten.find(p.key);
        const std::string help =
            p.help() + (files != kFilesWritten.end() ? ". " + files->second : "");
        std::visit(
            [&](auto member) {
                auto& value = o.request.*member;
                using V = std::decay_t<decltype(value)>;
                if constexpr (std::is_same_v<V, bool>)
                    cmd->add_flag(flag, value, help);
                else if constexpr (std::is_same_v<V, std::optional<double>>)
                    cmd->add_option(flag, value, help);
                else
                    cmd->add_option(flag, value, help)->capture_default_str();
            },
            p.member);
        if (p.key == "probe") add_transducer_options(*cmd, o.request);
    }
    add_parameter(*cmd, kFormatsDoc, o.formats);
    cmd->add_flag("--rf", o.write_rf, "also write the RF lines (NAME_rf.exr: lines x samples)");
    cmd->add_flag("--envelope", o.write_envelope,
                  "also write the envelope (NAME_envelope.exr: lines x samples)");
    add_parameter(*cmd, kOutDoc, o.out_dir);
    add_parameter(*cmd, kNameDoc, o.name);
    add_parameter(*cmd, kJsonDoc, o.json_path);
    add_parameter(*cmd, kThreadsDoc, o.threads)->check(CLI::Range(0, 1024));
    cmd->add_flag("--resume", o.resume,
                  "continue a stopped sweep into the same --out: frames whose files are all "
                  "there are kept (not simulated again; the last frame always is), the video is "
                  "rebuilt from their png8 frames. The frames are those of an uninterrupted run");
    add_parameter(*cmd, kVideoDoc, o.video);
    add_parameter(*cmd, kFpsDoc, o.fps);
    add_parameter(*cmd, kSceneDoc, o.scene);
    cmd->add_flag("-q,--quiet", o.quiet, "no progress on stderr");
    o.command = cmd;
    return cmd;
}

namespace {

// The label maps --labels writes (a PNG of tissue indices and its colour preview each).
struct LabelOutput {
    const char* suffix;  // NAME<suffix>.png
    const char* record;  // its entry in the sidecar's "labels"
    std::optional<cv::Mat> imaging::SimulatedFrame::*map;
    const char* geometry;
};
constexpr LabelOutput kLabelOutputs[] = {
    {"_labels", "true_position", &imaging::SimulatedFrame::labels,
     "same pixels as the frame; the anatomy where it lies"},
    {"_labels_echo", "echo_position", &imaging::SimulatedFrame::echo_labels,
     "same pixels as the frame; the anatomy where its echoes show it (display depth c0 t / 2 "
     "at 1540 m/s taken back along each line through the speed of sound; no refraction)"},
};

// The other truth maps --labels writes, in the frame's pixels.
struct TruthOutput {
    const char* suffix;  // NAME<suffix>
    const char* record;  // its entry in the sidecar's "labels"
    int bits;            // 32: float EXR; 16: PNG
    const char* geometry;
};
constexpr TruthOutput kTruthOutputs[] = {
    {"_depth.exr", "true_depth_mm", 32,
     "float mm: the true depth, along each pixel's line from the face, of what the pixel shows "
     "(as echo_position finds it); 0 outside the scan"},
    {"_echogenicity.exr", "echogenicity", 32,
     "float 0..1: the backscatter of what each pixel shows (as echo_position finds it), with "
     "no attenuation, shadowing or TGC; the speckle's mean power goes as its square"},
    {"_instances.png", "instances", 16,
     "16-bit: the phantom shape each pixel centre lies in (its place in the phantom's shapes "
     "from 1; 0 the background, and everywhere for a volume), where it lies"},
};

// Values of a --scene file become the results of the options not given on the command
// line (the command line wins). Keys are option names without dashes; '_' = '-'.
void apply_scene_file(CLI::App& command, const std::string& path) {
    const json scene = base::jsonio::read_file(path);
    if (!scene.is_object()) throw base::InputError(path, "", "must be a JSON object");
    for (const auto& [key, value] : scene.items()) {
        if (key == "comment") continue;  // notes for people, as in phantoms
        std::string flag = key;
        std::replace(flag.begin(), flag.end(), '_', '-');
        CLI::Option* option = command.get_option_no_throw("--" + flag);
        if (!option || flag == "scene" || flag == "help") {
            std::string known;
            for (const CLI::Option* o : command.get_options()) {
                const std::string name = o->get_name(false, true);
                if (name.rfind("--", 0) == 0 && name != "--scene" && name != "--help")
                    known += (known.empty() ? "" : ", ") + name.substr(2);
            }
            throw base::InputError(path, key, "unknown key; known keys: " + known);
        }
        if (option->count() > 0) continue;  // given on the command line
        std::string text;
        if (value.is_string())
            text = value.get<std::string>();
        else if (value.is_boolean())
            text = value.get<bool>() ? "true" : "false";
        else if (value.is_number())
            text = value.dump();
        else if (value.is_array()) {
            for (const auto& item : value)
                text += (text.empty() ? "" : ",") +
                        (item.is_string() ? item.get<std::string>() : item.dump());
        } else
            throw base::InputError(path, key, "must be a string, number, boolean or list");
        try {
            option->add_result(text);
            option->run_callback();
        } catch (const CLI::Error& e) {
            throw base::InputError(path, key, e.what());
        }
    }
}

}  // namespace

int run_simulate_command(const SimulateOptions& o) {
    // The scene file writes into the options bound to the command, i.e. into `o`.
    if (!o.scene.empty() && o.command) apply_scene_file(*o.command, o.scene);
    StageTimer timer(o.quiet);
    const auto thread_limit = limit_threads(o.threads);

    // ---- validate the outputs, then everything else, before loading ----
    base::require_in_range("simulate options", "fps", o.fps, 0.1, 240.0);
    std::vector<std::pair<std::string, int>> formats;  // file suffix, bits
    {
        std::istringstream list(o.formats);
        for (std::string f; std::getline(list, f, ',');) {
            if (f == "png8")
                formats.emplace_back(".png", 8);
            else if (f == "png16")
                formats.emplace_back("_16.png", 16);
            else if (f == "exr")
                formats.emplace_back(".exr", 32);
            else
                throw base::InputError("--formats", f, "unknown format (png8, png16, exr)");
        }
        if (formats.empty()) throw base::InputError("--formats", "", "is empty");
    }
    // A visible file stem that leaves room in a file name (255 bytes) for the frame number,
    // the suffixes and the staged temporary's prefix.
    constexpr std::size_t kMaxNameBytes = 200;
    if (o.name.empty() || o.name.find('/') != std::string::npos || o.name.front() == '.' ||
        o.name.size() > kMaxNameBytes ||
        std::any_of(o.name.begin(), o.name.end(), [](char c) { return std::iscntrl(uint8_t(c)); }))
        throw base::InputError("--name", "",
                               "must be a plain file stem: no '/', not starting with '.', no "
                               "control characters, at most 200 bytes");
    const std::string video_suffix = o.video.empty() ? "" : "." + o.video;
    if (!o.video.empty() && o.video != "mp4" && o.video != "avi")
        throw base::InputError("--video", o.video, "must be mp4, avi or empty");
    if (o.resume && o.request.sweep.empty())
        throw base::InputError("--resume", "", "needs --sweep");
    if (o.resume && !o.video.empty() &&
        std::none_of(formats.begin(), formats.end(), [](const auto& f) { return f.second == 8; }))
        throw base::InputError("--resume", "",
                               "rebuilds the video from the png8 frames: add png8 to --formats "
                               "or give --video ''");

    const scene::FrameSetup setup = scene::prepare_frames(o.request, &timer);
    const imaging::SimulationSettings& settings = setup.settings;
    const std::shared_ptr<const scene::Scene>& scene = setup.scene;
    const std::vector<scene::SweepPlacement>& placements = setup.placements;
    if (settings.transmit && !o.quiet)
        for (const std::string& warning : probe::validate_transmit_scheme(
                 *settings.transmit, settings.transducer, "--transmit", ""))
            std::cerr << "sonotrace: warning: " << warning << "\n";

    // ---- trace and form the frames; outputs staged and committed together ----
    const bool sweeping = !o.request.sweep.empty();
    const imaging::QualityLevel level = imaging::quality_level(settings.quality);
    const std::size_t particles = imaging::frame_particles(settings);
    base::OutputTransaction transaction;
    const std::filesystem::path out(o.out_dir);
    std::vector<std::string> written;
    json frames_record = json::array();
    json label_record;
    std::optional<imaging::VideoClip> video;
    std::string video_path;
    ProgressBar sweep_bar("sweep of " + std::to_string(placements.size()) + " frames", o.quiet);
    imaging::Frame last;
    // Each frame of a sweep is committed as soon as it is written: a killed sweep leaves
    // complete frames under their names. A single frame and its sidecar are one commit.
    // The video's frames are the png8 frames' pixels, so that a resumed sweep, which reads
    // them back, makes the same video.
    std::string video_staged;
    int video_frames = 0;
    auto add_video_frame = [&](const cv::Mat& grey) {
        if (!video) {
            video_path = (out / (o.name + video_suffix)).string();
            video_staged = transaction.stage(video_path);
            video.emplace(video_staged, o.video, o.fps, grey.size(), video_path);
            if (!video->note().empty() && !o.quiet)
                std::cerr << "sonotrace: " << video_path << ": " << video->note() << "\n";
            written.push_back(video_path);
        }
        video->write(grey);
        ++video_frames;
    };
    g_stop_sweep = false;
    const auto previous_int = sweeping ? std::signal(SIGINT, on_sweep_signal) : SIG_DFL;
    const auto previous_term = sweeping ? std::signal(SIGTERM, on_sweep_signal) : SIG_DFL;
    std::size_t frames_done = 0;
    for (std::size_t f = 0; f < placements.size() && !g_stop_sweep; ++f) {
        const scene::SweepPlacement& placement = placements[f];
        char numbered[32];
        std::snprintf(numbered, sizeof numbered, "_%04zu", f);
        const std::string stem = o.name + (sweeping ? numbered : "");
        base::OutputTransaction frame_transaction;
        base::OutputTransaction& frame_files = sweeping ? frame_transaction : transaction;
        // -- --resume: a frame whose files are all there is kept as it is
        std::vector<std::string> frame_paths;
        for (const auto& [suffix, bits] : formats)
            frame_paths.push_back((out / (stem + suffix)).string());
        if (o.write_rf) frame_paths.push_back((out / (stem + "_rf.exr")).string());
        if (o.write_envelope) frame_paths.push_back((out / (stem + "_envelope.exr")).string());
        if (o.request.labels) {
            for (const LabelOutput& l : kLabelOutputs) {
                frame_paths.push_back((out / (stem + l.suffix + ".png")).string());
                frame_paths.push_back((out / (stem + l.suffix + "_preview.png")).string());
            }
            for (const TruthOutput& t : kTruthOutputs)
                frame_paths.push_back((out / (stem + t.suffix)).string());
        }
        if (o.request.energy) frame_paths.push_back((out / (stem + "_energy.png")).string());
        if (o.request.channels) frame_paths.push_back((out / (stem + "_channels.h5")).string());
        if (o.resume && f + 1 < placements.size() &&
            std::all_of(frame_paths.begin(), frame_paths.end(),
                        [](const std::string& p) { return std::filesystem::exists(p); })) {
            if (!video_suffix.empty()) {
                const auto png8 = std::find_if(formats.begin(), formats.end(),
                                               [](const auto& fm) { return fm.second == 8; });
                const tissue::Volume kept =
                    tissue::read_image((out / (stem + png8->first)).string(), glm::dvec3(1.0));
                cv::Mat grey(kept.dims().y, kept.dims().x, CV_8U);
                for (int y = 0; y < grey.rows; ++y)
                    for (int x = 0; x < grey.cols; ++x)
                        grey.at<uint8_t>(y, x) = uint8_t(kept.at(x, y, 0));
                add_video_frame(grey);
            }
            written.insert(written.end(), frame_paths.begin(), frame_paths.end());
            frames_record.push_back({{"index", f},
                                     {"offset_mm", placement.offset_mm},
                                     {"pose", scene::pose_json(placement.scene.pose)},
                                     {"resumed", true}});
            ++frames_done;
            if (sweeping) sweep_bar.update(f + 1, placements.size());
            continue;
        }
        ProgressBar bar("simulating " + std::to_string(particles) + " particles",
                        o.quiet || sweeping);
        imaging::SimulatedFrame simulated = imaging::simulate_plane(
            scene->mapper, placement.scene, settings, o.request.labels,
            [&bar](std::size_t done, std::size_t total) { bar.update(done, total); });
        bar.finish();
        const imaging::Frame& frame = simulated.frame;

        for (const auto& [suffix, bits] : formats) {
            const std::string path = (out / (stem + suffix)).string();
            write_frame(frame.image.image, frame_files.stage(path), bits);
            written.push_back(path);
        }
        auto write_lines = [&](const imaging::LineData& d, const std::string& suffix) {
            const std::string path = (out / (stem + suffix)).string();
            tissue::write_gray_image(frame_files.stage(path), d.samples, d.lines, d.values, 32);
            written.push_back(path);
        };
        if (o.write_rf) write_lines(frame.rf, "_rf.exr");
        if (o.write_envelope) write_lines(frame.envelope, "_envelope.exr");
        if (simulated.labels) {
            label_record = {{"legend", tissue::label_legend()}};
            for (const LabelOutput& l : kLabelOutputs) {
                const cv::Mat& label_image = *(simulated.*(l.map));
                const std::string path = (out / (stem + l.suffix + ".png")).string();
                const std::vector<float> values(label_image.begin<uint8_t>(),
                                                label_image.end<uint8_t>());
                tissue::write_gray_image(frame_files.stage(path), label_image.cols,
                                         label_image.rows, values, 8);
                const std::string preview = (out / (stem + l.suffix + "_preview.png")).string();
                imaging::write_png(imaging::label_picture(label_image), frame_files.stage(preview));
                written.push_back(path);
                written.push_back(preview);
                label_record[l.record] = {
                    {"files",
                     (out / (o.name + (sweeping ? "_NNNN" : "") + l.suffix + ".png")).string()},
                    {"geometry", l.geometry}};
            }
            const cv::Mat truth[] = {*simulated.true_depth, *simulated.echogenicity,
                                     scene::instance_map(*scene, simulated)};
            for (std::size_t k = 0; k < std::size(kTruthOutputs); ++k) {
                const TruthOutput& t = kTruthOutputs[k];
                cv::Mat values;
                truth[k].convertTo(values, CV_32F);
                const std::string path = (out / (stem + t.suffix)).string();
                tissue::write_gray_image(
                    frame_files.stage(path), values.cols, values.rows,
                    std::vector<float>(values.begin<float>(), values.end<float>()), t.bits);
                written.push_back(path);
                label_record[t.record] = {
                    {"files", (out / (o.name + (sweeping ? "_NNNN" : "") + t.suffix)).string()},
                    {"geometry", t.geometry}};
            }
        }
        if (o.request.energy) {
            imaging::FieldStyle style{"absorbed energy (sedimentation)",
                                      "energy",
                                      imaging::Colormap::inferno,
                                      std::nullopt,
                                      true,
                                      level.map_pixel_mm};
            const std::string path = (out / (stem + "_energy.png")).string();
            imaging::write_png(imaging::render_field(frame.absorbed, style),
                               frame_files.stage(path));
            written.push_back(path);
        }
        if (o.request.channels && frame.channels) {
            const std::string path = (out / (stem + "_channels.h5")).string();
            const std::string bytes = dataset::channel_file_bytes(
                *frame.channels, settings.transducer, o.request.transmit, path);
            base::write_file(frame_files.stage(path), bytes.data(), bytes.size());
            written.push_back(path);
        }
        if (sweeping && !video_suffix.empty())
            add_video_frame(imaging::grey_levels(frame.image.image));
        frames_record.push_back({{"index", f},
                                 {"offset_mm", placement.offset_mm},
                                 {"pose", scene::pose_json(placement.scene.pose)},
                                 {"timings_s", frame.timings}});
        if (sweeping) frame_transaction.commit();
        ++frames_done;
        if (sweeping) sweep_bar.update(f + 1, placements.size());
        last = std::move(simulated.frame);
    }
    if (sweeping) {
        sweep_bar.finish();
        std::signal(SIGINT, previous_int);
        std::signal(SIGTERM, previous_term);
    }
    if (video) {
        // OpenCV reports no write errors: the video is read back, and a short one (a full
        // disk) is an error naming it, not a truncated file reported as written.
        video->close();
        cv::VideoCapture check(video_staged, cv::CAP_FFMPEG);
        int decoded = 0;
        for (cv::Mat image; check.isOpened() && check.read(image);) ++decoded;
        if (decoded != video_frames)
            throw base::InputError(
                video_path, "",
                "the video could not be written completely (" + std::to_string(decoded) + " of " +
                    std::to_string(video_frames) + " frames read back): is the disk full?");
    }
    const bool interrupted = frames_done < placements.size();
    if (frames_done == 0)
        throw base::InputError("--sweep", "",
                               "interrupted before the first frame: nothing written");

    const imaging::Frame& frame = last;
    json record = scene::frame_sidecar(o.request, setup, frame);
    record["labels"] = label_record;
    record["stage_timings_s"] = timer.timings();
    record["outputs"] = written;
    if (sweeping) {
        record["sweep"] = {{"spec", o.request.sweep},
                           {"frames", frames_record},
                           {"frames_planned", placements.size()},
                           {"interrupted", interrupted}};
        if (video)
            record["sweep"]["video"] = {
                {"file", video_path}, {"fps", o.fps}, {"codec", video->codec()}};
    }
    if (!o.scene.empty()) record["scene_file"] = o.scene;
    const std::string sidecar = (out / (o.name + ".json")).string();
    write_json(record, transaction.stage(sidecar));
    if (!o.json_path.empty() && o.json_path != "-")
        write_json(record, transaction.stage(o.json_path));
    transaction.commit();
    if (o.json_path == "-") write_json(record, "-");
    if (interrupted) {
        std::cerr << "sonotrace: interrupted after " << frames_done << " of " << placements.size()
                  << " frames; wrote them, the video so far and " << sidecar << "\n";
        return 130;
    }
    if (!o.quiet) std::cerr << "sonotrace: wrote " << written.front() << " and " << sidecar << "\n";
    return 0;
}

}  // namespace sonotrace::ui
