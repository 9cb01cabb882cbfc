// `sonotrace simulate` end to end: the default frame and its sidecar, byte-identical
// frames on 1 and 2 threads, JSON scene files, and bad input that fails cleanly.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <thread>

#include <fstream>
#include <map>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include <opencv2/videoio.hpp>

#include "phantoms/scene/scene.h"
#include "tests/test_util.h"
#include "tissue/image_io.h"

namespace sonotrace {
namespace {

using test::files_in;
using test::run;
using test::ScratchDir;
using test::slurp;

struct Gray {
    glm::ivec2 size;
    std::vector<float> pixels;
};
Gray read_gray(const std::string& path) {
    const tissue::Volume v = tissue::read_image(path, glm::dvec3(1.0));
    return {{v.geometry().dims.x, v.geometry().dims.y}, {v.voxels().begin(), v.voxels().end()}};
}

// Frames a video really holds, counted by decoding them.
int video_frame_count(const std::string& path) {
    cv::VideoCapture capture(path);
    if (!capture.isOpened()) return -1;
    int frames = 0;
    for (cv::Mat frame; capture.read(frame);) ++frames;
    return frames;
}

TEST(CliSimulate, DefaultFrameWithSidecar) {
    ScratchDir dir;
    const auto r = run(
        dir, "simulate -q --quality interactive --formats png8,png16,exr --out " + (dir / "out"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const char* f : {"bmode.png", "bmode_16.png", "bmode.exr", "bmode.json"})
        EXPECT_TRUE(std::filesystem::exists(dir / ("out/" + std::string(f)))) << f;
    const auto record = nlohmann::json::parse(slurp(dir / "out/bmode.json"));
    EXPECT_EQ(record["probe"]["name"], "convex");
    EXPECT_EQ(record["seed"], 1);
    EXPECT_TRUE(record.contains("version"));
    EXPECT_TRUE(record["timings_s"].contains("trace"));
    EXPECT_EQ(record["image"]["pixel_spacing_mm"][0], 0.2);
    EXPECT_LT(std::abs(record["stats"]["energy_balance_error"].get<double>()), 1e-6);
}

TEST(CliSimulate, FramesByteIdenticalOnOneAndTwoThreads) {
    ScratchDir dir;
    const std::string common =
        "simulate -q --quality interactive --formats png16,png8,exr --labels ";
    ASSERT_EQ(run(dir, common + "--threads 1 --out " + (dir / "a")).exit_code, 0);
    // A second apart at least: no write time may reach the files.
    std::this_thread::sleep_for(std::chrono::milliseconds(1100));
    ASSERT_EQ(run(dir, common + "--threads 2 --out " + (dir / "b")).exit_code, 0);
    for (const char* f : {"bmode_16.png", "bmode.png", "bmode.exr", "bmode_labels.png"})
        EXPECT_TRUE(slurp(dir / ("a/" + std::string(f))) == slurp(dir / ("b/" + std::string(f))))
            << f;
}

TEST(CliSimulate, BadInputFailsWithoutPartialOutput) {
    ScratchDir dir;
    const struct {
        std::string args;
        const char* mention;
    } cases[] = {
        {"--elements 0", "elements"},
        {"--focus 200", "beyond the imaging depth"},
        {"--probe phased --fov 190", "fov"},
        {"--fov 120", "arc"},
        {"--probe sector", "unknown transducer preset 'sector'"},
        {"--frequency nan", "frequency"},
        {"--tgc 10:0,x", "--tgc"},
        {"--formats gif", "--formats"},
        {"--receive echo", "--receive"},
        {"--disable gravity", "unknown physics 'gravity'"},
        {"--pose 'at=1,2'", "--pose"},
        {"--pose 'at=500,0,0 beam=0,0,-1'", "outside the volume"},
        {"--sweep elevation:10", "AXIS:LENGTH:STEP"},
        {"--sweep sideways:10:1", "axis"},
        {"--sweep elevation:10:0", "step"},
        {"--video mkv --sweep elevation:2:1", "--video"},
        // A file of poses that is a FIFO with no writer: reading it blocked for ever.
        {"--sweep " + (dir / "poses.fifo"), "poses.fifo: field '--sweep': is not a regular file"},
        {"--scene /no/scene.json", "/no/scene.json"},
        {"--volume /no/such.nii", "/no/such.nii"},
        {"--phantom /no/phantom.json", "/no/phantom.json"},
        {"--phantom " + std::string(SONOTRACE_SOURCE_DIR) +
             "/phantoms/mirror.json --volume /no/such.nii",
         "cannot be combined with --volume"},
        {"--phantom " + std::string(SONOTRACE_SOURCE_DIR) +
             "/phantoms/mirror.json --pose 'at=500,0,0 beam=0,1,0'",
         "outside the phantom"},
        {"--disable refraction,gravity", "--disable"},
        {"--rx-f-number 0", "rx-f-number"},
        {"--rx-apodization blackman", "rx-apodization"},
        {"--cycles 0", "cycles"},
        // An element as wide as the pitch leaves no kerf; the band shape's range.
        {"--probe linear --element-width 0.3",
         "field 'element-width': must be more than 0 and less than the pitch"},
        {"--element-width 0", "element-width"},
        {"--band-shape 3", "field 'band-shape': must be in [1.1, 2.5]"},
        {"--band-shape 1", "band-shape"},
        // CLI11 read these as the largest seed.
        {"--seed -1", "--seed: value -1 is not a whole number"},
        {"--seed 18446744073709551616", "not a whole number"},
        {"--seed 1e23", "not a whole number"},
        {"--phantom " + (dir / "far_target.json"), "targets[0].at"},
        // Meshes: an open one, and a device that never ends where the mesh should be.
        {"--phantom " + (dir / "open_mesh.json"), "open.obj: field 'triangle"},
        {"--phantom " + (dir / "open_mesh.json"), "the surface is not closed"},
        {"--phantom " + (dir / "endless_mesh.json"), "/dev/zero: does not exist or is not a file"},
        {"--name .", "--name"},
        // numbers in messages are short: not 301 digits
        {"--probe convex --fov 1e300", "field 'fov': must be in [0.001, 180] degrees, got 1e+300"},
        {"--name .hidden", "--name"},
        // Unfocused transmits.
        {"--probe linear --transmit plane:95", "angle 95 degrees"},
        {"--probe linear --transmit plane:-90", "|angle| < 90"},
        {"--probe linear --transmit plane:0:10:0", "zero transmits"},
        {"--probe linear --transmit plane:", "zero transmits"},
        {"--probe linear --transmit diverging:-3", "must lie behind the face"},
        {"--probe linear --transmit sideways:3", "unknown transmit 'sideways'"},
        {"--probe radial --transmit plane:0", "need an open array"},
        // The default head's convex probe: the arc's end faces 37.5 degrees off the axis.
        {"--transmit plane:60", "from its normal"},
        {"--probe linear --transmit plane:0 --trace 3d", "traced in 2D"},
        {"--probe linear --channels", "--channels"},
        {"--probe picmus --depth 300 --transmit plane:-16:16:9999", "memory"},
        {"--name " + std::string(250, 'a'), "--name"}};
    ASSERT_EQ(::mkfifo((dir / "poses.fifo").c_str(), 0600), 0);
    std::ofstream(dir / "far_target.json") << R"({"name": "x", "size": [40, 40, 10],
        "background": {"tissue": "water"}, "targets": [{"type": "wire", "at": [20, 45]}]})";
    // A tetrahedron with a face missing.
    std::ofstream(dir / "open.obj") << "v 10 10 0\nv 20 10 0\nv 10 20 0\nv 10 10 5\n"
                                       "f 1 3 2\nf 1 2 4\nf 2 3 4\n";
    for (const auto& [name, file] :
         {std::pair{"open_mesh.json", "open.obj"}, std::pair{"endless_mesh.json", "/dev/zero"}})
        std::ofstream(dir / name) << R"({"name": "m", "size": [40, 40, 10],
            "background": {"tissue": "water"},
            "shapes": [{"type": "mesh", "file": ")"
                                  << file << R"(", "tissue": "liver"}]})";
    for (const auto& c : cases) {
        const auto r =
            run(dir, "simulate -q --quality interactive " + c.args + " --out " + (dir / "out"));
        EXPECT_EQ(r.exit_code, 1) << c.args;
        EXPECT_NE(r.err.find(c.mention), std::string::npos) << c.args << ": " << r.err;
        EXPECT_TRUE(files_in(dir / "out").empty()) << c.args;
    }
    // Scene files: unknown keys and values of the wrong kind name the file and key.
    std::ofstream(dir / "bad_key.json") << R"({"probe": "linear", "gian": 30})";
    std::ofstream(dir / "bad_value.json") << R"({"gain": "loud"})";
    std::ofstream(dir / "not_json.json") << "{probe: linear";
    // Values no parser should pass on: a number beyond any double, and an array nested
    // 100,000 deep (it overflowed the stack of the code that printed it).
    std::ofstream(dir / "huge_number.json") << R"({"gain": 1e400})";
    std::ofstream(dir / "deep.json")
        << "{\"gain\": " << std::string(100000, '[') << std::string(100000, ']') << "}";
    for (const auto& [file, mention] :
         {std::pair{"bad_key.json", "gian"}, std::pair{"bad_value.json", "gain"},
          std::pair{"not_json.json", "invalid JSON"},
          std::pair{"huge_number.json", "number overflow"},
          std::pair{"deep.json", "levels deep"}}) {
        const auto r = run(dir, "simulate -q --quality interactive --scene " + (dir / file) +
                                    " --out " + (dir / "out"));
        EXPECT_EQ(r.exit_code, 1) << file;
        EXPECT_NE(r.err.find(mention), std::string::npos) << file << ": " << r.err;
        EXPECT_NE(r.err.find(file), std::string::npos) << file << ": " << r.err;
        EXPECT_TRUE(files_in(dir / "out").empty()) << file;
        EXPECT_LT(r.err.size(), 2000u) << file;  // the message, not the input echoed back
    }
    // A phantom that is a device never ends: refused before reading.
    {
        const auto r = run(dir, "simulate -q --phantom /dev/zero --out " + (dir / "out"));
        EXPECT_EQ(r.exit_code, 1);
        EXPECT_NE(r.err.find("/dev/zero: is not a regular file"), std::string::npos) << r.err;
        EXPECT_TRUE(files_in(dir / "out").empty());
    }
    // An output path that cannot be written: a file where the directory should be.
    std::ofstream(dir / "blocked") << "x";
    const auto r = run(dir, "simulate -q --quality interactive --out " + (dir / "blocked/sub"));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("blocked"), std::string::npos) << r.err;
}

// The cyst-and-stone phantom through the whole command: at the same depths, the column
// behind the fluid cyst is brighter than plain liver (no attenuation in the cyst: +7.6 dB
// two-way over its 10 mm at 7.6 MHz and 0.5 dB/(cm MHz)) and the column behind the stone
// darker (bone: 20 dB/(cm MHz)). No TGC, gain 56 dB (liver mid-grey there). Display units 0..255
// over 60 dB; mean of ~800 pixels (~150 speckle cells, log-speckle std 5.6 dB = 24 units): std of a
// mean ~2 units, margins 12 units (6 sigma).
TEST(CliSimulate, PhantomShowsEnhancementBehindTheCystAndShadowBehindTheStone) {
    ScratchDir dir;
    const auto r =
        run(dir, "simulate -q --quality interactive --tgc 0:0 --gain 56 --pixel 0.2 --phantom " +
                     std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/cyst_and_stone.json --out " +
                     (dir / "o"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const Gray g = read_gray(dir / "o/bmode.png");
    // The linear probe's 38.4 mm image centred on x = 20 mm: column of world x.
    auto mean_below = [&](double x_mm) {
        double sum = 0.0;
        int n = 0;
        const int c0 = int((x_mm - 2.0 - 0.8) / 0.2), c1 = int((x_mm + 2.0 - 0.8) / 0.2);
        for (int row = int(28.0 / 0.2); row < int(36.0 / 0.2); ++row)
            for (int c = c0; c <= c1; ++c, ++n) sum += g.pixels[std::size_t(row * g.size.x + c)];
        return sum / n;
    };
    const double cyst = mean_below(11.0), liver = mean_below(20.0), stone = mean_below(29.0);
    std::printf("behind the cyst %.1f, liver %.1f, behind the stone %.1f (0..255)\n", cyst, liver,
                stone);
    // Enhancement in dB: liver's two-way 2 x 0.5 x 7.6 dB/cm over the cyst's mean chord
    // of 9.6 mm across x = 9..13 mm is 7.3 dB, within 2 dB.
    EXPECT_NEAR((cyst - liver) * 60.0 / 255.0, 7.3, 2.0);
    EXPECT_LT(stone, liver - 12.0);
}

// The Colin27 scenes of the phantom catalogue (phantoms/scenes/) run as scene files.
// The point-target grid through the whole command with --disable: the sidecar records
// the switches, and a 0.1 mm wire target images as the brightest spot of its depth, on its
// own column (world x = 20 mm: the image's centre).
// Unfocused transmits with --channels: the frame and its channel data are the same bytes
// on one thread and on two, and the sidecar records the scheme and the channels' layout.
TEST(CliSimulate, ChannelDataAreByteIdenticalOnOneAndTwoThreads) {
    ScratchDir dir;
    const std::string common = "simulate -q --quality interactive --phantom " +
                               std::string(SONOTRACE_SOURCE_DIR) +
                               "/phantoms/picmus.json --transmit plane:-4:4:3 --channels ";
    ASSERT_EQ(run(dir, common + "--threads 1 --out " + (dir / "a")).exit_code, 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(1100));
    const auto r = run(dir, common + "--threads 2 --out " + (dir / "b"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const char* f : {"bmode.png", "bmode_channels.h5"})
        EXPECT_TRUE(slurp(dir / ("a/" + std::string(f))) == slurp(dir / ("b/" + std::string(f))))
            << f;
    const auto record = nlohmann::json::parse(slurp(dir / "a/bmode.json"));
    EXPECT_EQ(record["transmit"]["scheme"], "plane:-4:4:3");
    EXPECT_EQ(record["transmit"]["transmits"], 3);
    EXPECT_EQ(record["transmit"]["channels"]["elements"], 128);
}

TEST(CliSimulate, PointTargetsImageAndDisabledPhysicsAreRecorded) {
    ScratchDir dir;
    const auto r = run(dir,
                       "simulate -q --quality interactive --disable speckle,refraction "
                       "--depth 35 --phantom " +
                           std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/point_grid.json --out " +
                           (dir / "o"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto sidecar = nlohmann::json::parse(std::ifstream(dir / "o/bmode.json"));
    EXPECT_EQ(sidecar.at("disabled_physics"), nlohmann::json({"refraction", "speckle"}));
    const Gray g = read_gray(dir / "o/bmode.png");
    // The row at 30 mm depth (pixel 0.2 mm): its brightest pixel is the wire at x = 20 mm,
    // the image's middle column.
    const int row = int(30.0 / 0.2);
    int brightest = 0;
    for (int c = 0; c < g.size.x; ++c)
        if (g.pixels[std::size_t(row * g.size.x + c)] >
            g.pixels[std::size_t(row * g.size.x + brightest)])
            brightest = c;
    EXPECT_NEAR(brightest, g.size.x / 2, 2) << "of " << g.size.x;
    EXPECT_GT(g.pixels[std::size_t(row * g.size.x + brightest)], 200);
}

TEST(CliSimulate, CatalogueHeadScenesRun) {
    for (const char* name : {"colin27_craniotomy", "colin27_temporal"}) {
        ScratchDir dir;
        const auto r = run(dir, std::string("simulate -q --quality interactive --scene ") +
                                    SONOTRACE_SOURCE_DIR + "/phantoms/scenes/" + name +
                                    ".json --out " + (dir / "o"));
        ASSERT_EQ(r.exit_code, 0) << name << ": " << r.err;
        const auto sidecar = nlohmann::json::parse(slurp(dir / "o/bmode.json"));
        const bool craniotomy = std::string(name) == "colin27_craniotomy";
        EXPECT_EQ(sidecar.at("view"), craniotomy ? "craniotomy" : "temporal");
        // Without --gain, the view's (a sonographer turns it up through the skull).
        EXPECT_EQ(sidecar.at("image").at("gain_db"),
                  craniotomy ? scene::kDefaultGainDb : scene::kTemporalGainDb)
            << name;
    }
}

// A scene file sets options; the command line overrides it.
TEST(CliSimulate, SceneFileSetsOptionsAndCommandLineWins) {
    ScratchDir dir;
    std::ofstream(dir / "scene.json")
        << R"({"probe": "linear", "gain": 30, "formats": ["png8", "png16"], "quality": "interactive", "name": "scan"})";
    const auto r =
        run(dir, "simulate -q --scene " + (dir / "scene.json") + " --gain 25 --out " + (dir / "o"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto record = nlohmann::json::parse(slurp(dir / "o/scan.json"));
    EXPECT_EQ(record["probe"]["name"], "linear");                 // from the file
    EXPECT_EQ(record["image"]["gain_db"], 25.0);                  // the command line wins
    EXPECT_EQ(record["quality"]["name"], "interactive");          // from the file
    EXPECT_TRUE(std::filesystem::exists(dir / "o/scan_16.png"));  // list value
}

// A sweep writes one numbered frame per step and a video with as many frames; labels come
// in the frame's geometry with values from the sidecar's legend.
TEST(CliSimulate, SweepWritesNumberedFramesVideoAndLabels) {
    ScratchDir dir;
    const auto r = run(dir,
                       "simulate -q --quality interactive --sweep elevation:4:2 --video avi "
                       "--labels --out " +
                           (dir / "o"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const char* f : {"bmode_0000.png", "bmode_0001.png", "bmode_0002.png", "bmode.avi",
                          "bmode_0000_labels.png", "bmode_0002_labels_preview.png"})
        EXPECT_TRUE(std::filesystem::exists(dir / ("o/" + std::string(f)))) << f;
    EXPECT_FALSE(std::filesystem::exists(dir / "o/bmode_0003.png"));
    const auto record = nlohmann::json::parse(slurp(dir / "o/bmode.json"));
    ASSERT_EQ(record["sweep"]["frames"].size(), 3u);
    EXPECT_DOUBLE_EQ(record["sweep"]["frames"][0]["offset_mm"].get<double>(), -2.0);
    EXPECT_DOUBLE_EQ(record["sweep"]["frames"][2]["offset_mm"].get<double>(), 2.0);
    // The poses move 2 mm apart along the elevation axis.
    auto position = [&](int f) {
        const auto& p = record["sweep"]["frames"][f]["pose"]["position_mm"];
        return glm::dvec3(p[0].get<double>(), p[1].get<double>(), p[2].get<double>());
    };
    EXPECT_NEAR(glm::length(position(1) - position(0)), 2.0, 1e-9);
    EXPECT_EQ(video_frame_count(dir / "o/bmode.avi"), 3);
    // Labels: same size as the frame; every value is in the legend; brain dominates the
    // view through the craniotomy, and the outside of the fan is 0.
    const auto frame = read_gray(dir / "o/bmode_0001.png");
    const auto labels = read_gray(dir / "o/bmode_0001_labels.png");
    ASSERT_EQ(frame.size, labels.size);
    std::map<int, int> histogram;
    for (float v : labels.pixels) histogram[int(v)]++;
    for (const auto& [value, count] : histogram)
        EXPECT_TRUE(record["labels"]["legend"].contains(std::to_string(value))) << value;
    int brain = 0;
    for (const auto& [key, name] : record["labels"]["legend"].items())
        if (name == "brain") brain = std::stoi(key);
    EXPECT_GT(histogram[brain], histogram[0] / 2) << "brain label under the probe";
    EXPECT_GT(histogram[0], 0);
}

// The sweep's default video is H.264 in MP4 (what browsers play), decoded back here: its
// frame count, its size (the frame's, rounded down to even for 4:2:0) and its pictures,
// which are the png8 frames within the codec's loss (PSNR above 30 dB).
TEST(CliSimulate, SweepVideoIsH264ThatDecodesToTheFrames) {
    ScratchDir dir;
    const auto r =
        run(dir, "simulate -q --quality interactive --sweep lateral:4:2 --out " + (dir / "o"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    cv::VideoCapture capture(dir / "o/bmode.mp4", cv::CAP_FFMPEG);
    ASSERT_TRUE(capture.isOpened());
    const int fourcc = int(capture.get(cv::CAP_PROP_FOURCC));
    const std::string codec{char(fourcc & 255), char((fourcc >> 8) & 255),
                            char((fourcc >> 16) & 255), char((fourcc >> 24) & 255)};
    EXPECT_TRUE(codec == "avc1" || codec == "h264") << codec;
    const auto record = nlohmann::json::parse(slurp(dir / "o/bmode.json"));
    EXPECT_EQ(record["sweep"]["video"]["codec"], "H.264");
    int frames = 0;
    for (cv::Mat decoded; capture.read(decoded); ++frames) {
        char name[32];
        std::snprintf(name, sizeof name, "o/bmode_%04d.png", frames);
        const Gray png = read_gray(dir / name);
        ASSERT_EQ(decoded.cols, png.size.x & ~1);
        ASSERT_EQ(decoded.rows, png.size.y & ~1);
        double squared = 0.0;
        for (int y = 0; y < decoded.rows; ++y)
            for (int x = 0; x < decoded.cols; ++x) {
                const double d = decoded.at<cv::Vec3b>(y, x)[1] -
                                 png.pixels[std::size_t(y) * png.size.x + x];  // 0..255
                squared += d * d;
            }
        const double psnr =
            10.0 * std::log10(255.0 * 255.0 / (squared / (decoded.rows * decoded.cols)));
        std::printf("%s: PSNR %.1f dB\n", name, psnr);
        EXPECT_GT(psnr, 30.0) << name;
    }
    EXPECT_EQ(frames, 3);
}

// Without an H.264 encoder (as SONOTRACE_NO_H264 makes it) the MP4 is MPEG-4 Part 2: it
// still decodes to every frame, the sidecar says which codec, and the user is told why.
TEST(CliSimulate, WithoutAnH264EncoderTheSweepVideoFallsBackAndSaysSo) {
    ScratchDir dir;
    setenv("SONOTRACE_NO_H264", "1", 1);
    const auto r =
        run(dir, "simulate --quality interactive --sweep lateral:2:2 --out " + (dir / "o"));
    unsetenv("SONOTRACE_NO_H264");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find("no H.264 encoder"), std::string::npos) << r.err;
    cv::VideoCapture capture(dir / "o/bmode.mp4", cv::CAP_FFMPEG);
    ASSERT_TRUE(capture.isOpened());
    const int fourcc = int(capture.get(cv::CAP_PROP_FOURCC));
    const std::string codec{char(fourcc & 255), char((fourcc >> 8) & 255),
                            char((fourcc >> 16) & 255), char((fourcc >> 24) & 255)};
    EXPECT_EQ(codec, "mp4v");
    EXPECT_EQ(nlohmann::json::parse(slurp(dir / "o/bmode.json"))["sweep"]["video"]["codec"],
              "MPEG-4 Part 2");
    EXPECT_EQ(video_frame_count(dir / "o/bmode.mp4"), 2);
}

}  // namespace
}  // namespace sonotrace
