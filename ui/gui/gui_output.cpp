// The application's outputs: a frame saved with its record, and a clip recorded
// (App's views are in gui_views.cpp, its panels of controls in gui_app.cpp).
#include <filesystem>

#include <nlohmann/json.hpp>

#include "imaging/picture.h"
#include "phantoms/scene/records.h"
#include "sonotrace_version.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/json_util.h"
#include "tissue/transfer_function.h"
#include "ui/gui/gui_app.h"

namespace sonotrace::gui {

void App::save_frame() {
    if (!frame_) return;
    try {
        const std::filesystem::path dir(options_.out_dir);
        int n = 0;
        while (std::filesystem::exists(dir / ("frame_" + std::to_string(n) + ".png"))) ++n;
        const std::string stem = (dir / ("frame_" + std::to_string(n))).string();
        base::OutputTransaction transaction;
        cv::Mat grey;
        frame_->frame.image.image.convertTo(grey, CV_8U, 255.0);
        imaging::write_png(grey, transaction.stage(stem + ".png"));
        const imaging::ScanConverted& image = frame_->frame.image;
        const nlohmann::json record = {
            {"command", "sonotrace-gui"},
            {"version", SONOTRACE_VERSION},
            {"seed", frame_->settings.seed},
            {"scene", scene_->name},
            {"probe", scene::transducer_json(frame_->settings.transducer)},
            {"pose", scene::pose_json(frame_->pose)},
            {"quality", imaging::to_string(frame_->quality)},
            {"trace", frame_->settings.trace_dimensions == 3 ? "3d" : "2d"},
            {"transmit", frame_->settings.transmit ? frame_->settings.transmit->text : "focused"},
            {"transfer_function",
             scene_->volume ? scene_->volume->tf->describe() : nlohmann::json(nullptr)},
            {"image",
             {{"width", image.image.cols},
              {"height", image.image.rows},
              {"pixel_spacing_mm", {image.pixel_mm, image.pixel_mm}},
              {"origin_mm", {image.origin.x, image.origin.y}},
              {"gain_db", frame_->settings.imaging.gain_db},
              {"dynamic_range_db", frame_->settings.imaging.dynamic_range_db}}},
            {"physics",
             [&] {
                 nlohmann::json on = {{"receive", imaging::to_string(frame_->settings.receive)}};
                 for (const simulator::PhysicsSwitch& sw : simulator::kPhysicsSwitches)
                     on[std::string(sw.record_key)] = parameters_.physics.on(sw.id);
                 return on;
             }()},
            {"timings_s", frame_->frame.timings}};
        base::jsonio::write_json(record, transaction.stage(stem + ".json"));
        transaction.commit();
        message_ = "saved " + stem + ".png and .json";
    } catch (const std::exception& e) {
        error_ = std::string("could not save the frame: ") + e.what();
    }
}

void App::toggle_recording() {
    if (recording_) {
        recording_->close();
        message_ = "wrote " + recording_path_ + " (" + std::to_string(recorded_frames_) +
                   " frames, " + recording_->codec() + ")";
        recording_.reset();
        return;
    }
    if (!frame_) return;
    std::error_code error;
    std::filesystem::create_directories(options_.out_dir, error);
    recording_size_ = frame_->frame.image.image.size();
    // H.264 in MP4 plays in browsers and slides; Motion JPEG in AVI where FFmpeg writes
    // no MP4 at all.
    for (const char* container : {"mp4", "avi"}) {
        int n = 0;
        auto name = [&] {
            return (std::filesystem::path(options_.out_dir) /
                    ("clip_" + std::to_string(n) + "." + container))
                .string();
        };
        while (std::filesystem::exists(name())) ++n;
        recording_path_ = name();
        try {
            recording_.emplace(recording_path_, container, 10.0, recording_size_);
            break;
        } catch (const std::exception& e) {
            error_ = e.what();
        }
    }
    if (!recording_) return;
    recorded_frames_ = 0;
    message_ = "recording " + recording_path_ + " (" + recording_->codec() + ")" +
               (recording_->note().empty() ? "" : ": " + recording_->note());
}

}  // namespace sonotrace::gui
