// sonotrace-gui headless under Xvfb with Mesa: screenshots are not blank, the B-mode
// panel changes when the probe moves, a file that fails to load leaves the scene and
// shows the error, and bad options fail with a message.
#include <gtest/gtest.h>

#include <chrono>

#include <unistd.h>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include <nlohmann/json.hpp>

#include "tissue/image_io.h"

namespace {

namespace fs = std::filesystem;

const fs::path kDir = fs::temp_directory_path() / "sonotrace_test_gui";

// Runs the GUI under a private X server; returns the exit status.
int run_gui(const std::string& arguments, const std::string& log) {
    fs::create_directories(kDir);
    // Leak checking off for the child: Mesa and X keep allocations until exit.
    // The display search starts at a number of our own: another test run may be looking.
    const std::string display = std::to_string(100 + getpid() % 800);
    const std::string command = "ASAN_OPTIONS=detect_leaks=0 xvfb-run -a -n " + display +
                                " -s '-screen 0 1280x800x24' " SONOTRACE_GUI_BINARY
                                " --size 1280x800 " +
                                arguments + " > " + (kDir / log).string() + " 2>&1";
    const int status = std::system(command.c_str());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string read_text(const fs::path& path) {
    std::ifstream in(path);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

struct Screenshot {
    cv::Mat grey;  // CV_32F, 0..255
    nlohmann::json layout;
    cv::Mat region(const char* view) const {
        const auto& r = layout.at(view);
        const cv::Rect rect(int(r[0].get<double>()) + 1, int(r[1].get<double>()) + 1,
                            int(r[2].get<double>()) - 2, int(r[3].get<double>()) - 2);
        EXPECT_GT(rect.width, 50) << view;
        EXPECT_GT(rect.height, 50) << view;
        return grey(rect & cv::Rect(0, 0, grey.cols, grey.rows));
    }
};

Screenshot load(const std::string& name) {
    Screenshot s;
    const fs::path png = kDir / (name + ".png");
    // Luminance 0..255 (tissue::read_image reduces colour to Rec. 709 luminance).
    const sonotrace::tissue::Volume v =
        sonotrace::tissue::read_image(png.string(), glm::dvec3(1.0));
    const glm::ivec3 n = v.geometry().dims;
    s.grey = cv::Mat(n.y, n.x, CV_32F);
    for (int y = 0; y < n.y; ++y)
        for (int x = 0; x < n.x; ++x) s.grey.at<float>(y, x) = v.at(x, y, 0);
    s.layout = nlohmann::json::parse(read_text(kDir / (name + ".json")));
    return s;
}

double stddev(const cv::Mat& m) {
    cv::Scalar mean, sd;
    cv::meanStdDev(m, mean, sd);
    return sd[0];
}

TEST(Gui, ScreenshotsShowEveryViewAndTheBmodeFollowsTheProbe) {
    const std::string scene = "--scene phantom:cyst_and_stone --frames 1 ";
    ASSERT_EQ(run_gui(scene + "--screenshot " + (kDir / "pose_a.png").string(), "a.log"), 0)
        << read_text(kDir / "a.log");
    ASSERT_EQ(run_gui(scene + "--slide 8 --screenshot " + (kDir / "pose_b.png").string(), "b.log"),
              0)
        << read_text(kDir / "b.log");
    const Screenshot a = load("pose_a"), b = load("pose_b");
    EXPECT_EQ(a.grey.cols, 1280);
    EXPECT_EQ(a.layout.at("frames_shown").get<int>(), 1);
    // Not blank: every view has structure (speckle, tissue colours, particles).
    for (const char* view : {"slice", "bmode", "context", "energy"})
        EXPECT_GT(stddev(a.region(view)), 10.0) << view;
    // The B-mode panel changed between the two poses (the cyst moved 8 mm).
    const cv::Mat pa = a.region("bmode"), pb = b.region("bmode");
    ASSERT_EQ(pa.size(), pb.size());
    EXPECT_GT(cv::mean(cv::abs(pa - pb))[0], 10.0);
}

// The transmit panel's plane waves and a convex probe's diverging waves: the frame shows
// (speckle and the cyst), the panel's scheme is --transmit's text (the convex array's
// virtual source at its centre of curvature), and the radial ring falls back to focused
// with a message.
TEST(Gui, UnfocusedWavesShowAFrameAndTheRingStaysFocused) {
    const std::string scene = "--scene phantom:cyst_and_stone --no-context --frames 1 ";
    // The GUI with `options`, its screenshot NAME.png; fails the test if it exits nonzero.
    auto shot = [&](const std::string& name, const std::string& options) {
        const int status = run_gui(
            scene + options + " --screenshot " + (kDir / (name + ".png")).string(), name + ".log");
        EXPECT_EQ(status, 0) << read_text(kDir / (name + ".log"));
        return load(name);
    };
    const Screenshot plane =
        shot("plane", "--probe linear --transmit plane --transmits 3 --span 6");
    EXPECT_EQ(plane.layout.at("transmit"), "plane:-6:6:3");
    EXPECT_EQ(plane.layout.at("error"), "");
    EXPECT_GT(stddev(plane.region("bmode")), 10.0);
    const Screenshot convex = shot("convex", "--probe convex --transmit diverging");
    EXPECT_EQ(convex.layout.at("transmit"), "diverging:49.57:-8:8:5");
    EXPECT_EQ(convex.layout.at("error"), "");
    EXPECT_GT(stddev(convex.region("bmode")), 10.0);
    const Screenshot radial = shot("radial", "--probe radial --transmit diverging");
    EXPECT_EQ(radial.layout.at("transmit"), "focused");
    EXPECT_NE(radial.layout.at("message").get<std::string>().find("focused"), std::string::npos);
}

// The 3D context drawn in OpenGL (--context-renderer gpu) shows what the CPU renderer
// shows: the same particles (test_gl_pbvr compares the two renderers exactly); here the
// whole program's view, whose repetitions at the moment of the screenshot may differ by
// one (2 against 1 halves the noise), so a loose bound on the mean difference. Under
// Xvfb, auto picks the CPU renderer (Mesa rasterizes in software, slower than the cores).
TEST(Gui, TheContextViewOnTheGpuShowsWhatTheCpuShows) {
    const std::string scene = "--scene phantom:cyst_and_stone --frames 1 ";
    ASSERT_EQ(run_gui(scene + "--context-renderer gpu --screenshot " +
                          (kDir / "context_gpu.png").string(),
                      "gpu.log"),
              0)
        << read_text(kDir / "gpu.log");
    ASSERT_EQ(run_gui(scene + "--screenshot " + (kDir / "context_auto.png").string(), "auto.log"),
              0)
        << read_text(kDir / "auto.log");
    const Screenshot gpu = load("context_gpu"), cpu = load("context_auto");
    EXPECT_EQ(gpu.layout.at("context_renderer"), "gpu");
    EXPECT_EQ(cpu.layout.at("context_renderer"), "cpu");
    EXPECT_GT(gpu.layout.at("context_repetitions").get<int>(), 0);
    const cv::Mat a = gpu.region("context"), b = cpu.region("context");
    EXPECT_GT(stddev(a), 10.0);
    ASSERT_EQ(a.size(), b.size());
    const double difference = cv::mean(cv::abs(a - b))[0];
    std::printf("context view, GPU against CPU: mean |difference| %.2f grey levels\n", difference);
    EXPECT_LT(difference, 6.0);
}

TEST(Gui, SavesFramesWithSidecarsAndRecordsClips) {
    const fs::path out = kDir / "saved";
    fs::remove_all(out);
    ASSERT_EQ(run_gui("--scene phantom:cyst_and_stone --frames 3 --no-context --save --record "
                      "--out " +
                          out.string() + " --screenshot " + (kDir / "saved.png").string(),
                      "saved.log"),
              0)
        << read_text(kDir / "saved.log");
    // The frame and its sidecar: probe, pose, pixel spacing, seed, version.
    const sonotrace::tissue::Volume frame =
        sonotrace::tissue::read_image((out / "frame_0.png").string(), glm::dvec3(1.0));
    const auto sidecar = nlohmann::json::parse(read_text(out / "frame_0.json"));
    EXPECT_EQ(sidecar.at("image").at("width").get<int>(), frame.geometry().dims.x);
    EXPECT_EQ(sidecar.at("image").at("height").get<int>(), frame.geometry().dims.y);
    EXPECT_GT(sidecar.at("image").at("pixel_spacing_mm")[0].get<double>(), 0.0);
    EXPECT_EQ(sidecar.at("probe").at("name").get<std::string>(), "linear");
    EXPECT_EQ(sidecar.at("quality").get<std::string>(), "high");  // refined while still
    for (const char* key : {"pose", "seed", "version", "physics", "timings_s"})
        EXPECT_TRUE(sidecar.contains(key)) << key;
    // The clip holds the frames shown after the first (standard and high), decoded back:
    // H.264 (what browsers play) at the frame's size, rounded down to even (4:2:0).
    cv::VideoCapture clip((out / "clip_0.mp4").string(), cv::CAP_FFMPEG);
    ASSERT_TRUE(clip.isOpened());
    const int fourcc = int(clip.get(cv::CAP_PROP_FOURCC));
    const std::string codec{char(fourcc & 255), char((fourcc >> 8) & 255),
                            char((fourcc >> 16) & 255), char((fourcc >> 24) & 255)};
    EXPECT_TRUE(codec == "avc1" || codec == "h264" || codec == "H264") << codec;
    int frames = 0;
    cv::Mat image;
    for (cv::Mat next; clip.read(next);) ++frames, image = next;
    EXPECT_EQ(frames, 2);
    EXPECT_EQ(image.cols, frame.geometry().dims.x & ~1);
    EXPECT_EQ(image.rows, frame.geometry().dims.y & ~1);
}

// An opened MRI (Colin27's file by its path: not the embedded scene) is scanned from the
// vertex looking down, as its sform's RAS axes say, with the transfer function asked for
// (the generic one otherwise); the saved frame's sidecar records both.
TEST(Gui, AnOpenedVolumeTakesItsTransferFunctionAndLooksDownFromTheTop) {
    const std::string volume = "/usr/share/mricron/templates/ch2.nii.gz";
    for (const std::string tf : {"mri-t1-head", ""}) {
        const fs::path out = kDir / ("volume_" + (tf.empty() ? std::string("default") : tf));
        fs::remove_all(out);
        ASSERT_EQ(run_gui("--scene " + volume + (tf.empty() ? "" : " --tf " + tf) +
                              " --frames 1 --no-context --save --out " + out.string() +
                              " --screenshot " + (out.string() + ".png"),
                          "volume.log"),
                  0)
            << read_text(kDir / "volume.log");
        const auto sidecar = nlohmann::json::parse(read_text(out / "frame_0.json"));
        EXPECT_EQ(sidecar.at("transfer_function").at("name").get<std::string>(),
                  tf.empty() ? "generic-soft-tissue" : tf);
        const auto& beam = sidecar.at("pose").at("axial");
        EXPECT_NEAR(beam[2].get<double>(), -1.0, 1e-9) << sidecar.at("pose");
        const auto& lateral = sidecar.at("pose").at("lateral");
        EXPECT_NEAR(lateral[0].get<double>(), 1.0, 1e-9) << sidecar.at("pose");
    }
}

TEST(Gui, AFileThatFailsToLoadKeepsTheSceneAndShowsTheError) {
    const fs::path corrupt = kDir / "corrupt.nii";
    fs::create_directories(kDir);
    std::ofstream(corrupt) << "not a volume";
    ASSERT_EQ(run_gui("--scene phantom:cyst_and_stone --frames 1 --no-context --open " +
                          corrupt.string() + " --screenshot " + (kDir / "error.png").string(),
                      "error.log"),
              0)
        << read_text(kDir / "error.log");
    const Screenshot s = load("error");
    const std::string error = s.layout.at("error").get<std::string>();
    EXPECT_NE(error.find(corrupt.string()), std::string::npos) << error;
    EXPECT_GT(stddev(s.region("bmode")), 10.0);  // the phantom's frame is still shown
}

TEST(Gui, BadOptionsFailWithAMessage) {
    EXPECT_NE(
        run_gui("--scene /nonexistent/volume.nii --screenshot " + (kDir / "never.png").string(),
                "missing.log"),
        0);
    EXPECT_NE(read_text(kDir / "missing.log").find("/nonexistent/volume.nii"), std::string::npos);
    EXPECT_FALSE(fs::exists(kDir / "never.png"));
    EXPECT_NE(run_gui("--quality ultra", "quality.log"), 0);
    EXPECT_EQ(run_gui("--context-renderer fast", "renderer.log"), 1);
    EXPECT_NE(read_text(kDir / "renderer.log").find("--context-renderer"), std::string::npos);
    EXPECT_EQ(run_gui("--max-fps 0", "fps.log"), 1);
    EXPECT_EQ(run_gui("--transmit sideways", "transmit.log"), 1);
    EXPECT_NE(read_text(kDir / "transmit.log").find("--transmit"), std::string::npos);
    EXPECT_EQ(run_gui("--transmit plane --transmits 0", "transmits.log"), 1);
    EXPECT_NE(read_text(kDir / "transmits.log").find("--transmits"), std::string::npos);
    EXPECT_EQ(run_gui("--transmit plane --span 45", "span.log"), 1);
    EXPECT_NE(read_text(kDir / "span.log").find("--span"), std::string::npos);
    EXPECT_NE(read_text(kDir / "quality.log").find("--quality"), std::string::npos);
    EXPECT_NE(run_gui("--scene phantom:cyst_and_stone --explain bogus", "explain.log"), 0);
    EXPECT_NE(read_text(kDir / "explain.log").find("acoustic shadowing"), std::string::npos)
        << "the message lists the scene's artifacts";
    EXPECT_NE(run_gui("--frames 0 --screenshot " + (kDir / "never.png").string(), "frames.log"), 0);
    EXPECT_NE(read_text(kDir / "frames.log").find("--frames"), std::string::npos);
    // More frames than a still probe makes (interactive, standard, high) fail at once with
    // the reason, not after the time limit.
    const auto start = std::chrono::steady_clock::now();
    EXPECT_EQ(run_gui("--scene phantom:cyst_and_stone --no-context --frames 10 --time-limit 200 "
                      "--screenshot " +
                          (kDir / "never.png").string(),
                      "still.log"),
              1);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_LT(seconds, 60.0) << "waited for frames that never come";
    const std::string still = read_text(kDir / "still.log");
    EXPECT_NE(still.find("--frames"), std::string::npos) << still;
    EXPECT_NE(still.find("3 frames"), std::string::npos) << still;
    EXPECT_NE(still.find("--animate"), std::string::npos) << still;
    EXPECT_FALSE(fs::exists(kDir / "never.png"));
}

}  // namespace
