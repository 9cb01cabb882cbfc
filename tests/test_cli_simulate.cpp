// `sonotrace simulate` end to end: the default frame and its sidecar, byte-identical
// frames on 1 and 2 threads, JSON scene files, and bad input that fails cleanly.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include <fstream>
#include <map>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include <opencv2/videoio.hpp>

#include "test_util.h"
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
    return {{v.geometry().dims.x, v.geometry().dims.y}, v.voxels()};
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
    } cases[] = {{"--elements 0", "elements"},
                 {"--focus 200", "beyond the imaging depth"},
                 {"--probe phased --fov 190", "fov"},
                 {"--fov 120", "arc"},
                 {"--probe sector", "unknown transducer preset 'sector'"},
                 {"--frequency nan", "frequency"},
                 {"--tgc 10:0,x", "--tgc"},
                 {"--formats gif", "--formats"},
                 {"--receive echo", "--receive"},
                 {"--pose 'at=1,2'", "--pose"},
                 {"--pose 'at=500,0,0 beam=0,0,-1'", "outside the volume"},
                 {"--sweep elevation:10", "AXIS:LENGTH:STEP"},
                 {"--sweep sideways:10:1", "axis"},
                 {"--sweep elevation:10:0", "step"},
                 {"--video mkv --sweep elevation:2:1", "--video"},
                 {"--scene /no/scene.json", "/no/scene.json"},
                 {"--volume /no/such.nii", "/no/such.nii"}};
    for (const auto& c : cases) {
        const auto r =
            run(dir, "simulate -q --quality interactive " + c.args + " --out " + (dir / "out"));
        EXPECT_NE(r.exit_code, 0) << c.args;
        EXPECT_NE(r.err.find(c.mention), std::string::npos) << c.args << ": " << r.err;
        EXPECT_TRUE(files_in(dir / "out").empty()) << c.args;
    }
    // Scene files: unknown keys and values of the wrong kind name the file and key.
    std::ofstream(dir / "bad_key.json") << R"({"probe": "linear", "gian": 30})";
    std::ofstream(dir / "bad_value.json") << R"({"gain": "loud"})";
    std::ofstream(dir / "not_json.json") << "{probe: linear";
    for (const auto& [file, mention] :
         {std::pair{"bad_key.json", "gian"}, std::pair{"bad_value.json", "gain"},
          std::pair{"not_json.json", "not valid JSON"}}) {
        const auto r = run(dir, "simulate -q --quality interactive --scene " + (dir / file) +
                                    " --out " + (dir / "out"));
        EXPECT_NE(r.exit_code, 0) << file;
        EXPECT_NE(r.err.find(mention), std::string::npos) << file << ": " << r.err;
        EXPECT_NE(r.err.find(file), std::string::npos) << file << ": " << r.err;
        EXPECT_TRUE(files_in(dir / "out").empty()) << file;
    }
    // An output path that cannot be written: a file where the directory should be.
    std::ofstream(dir / "blocked") << "x";
    const auto r = run(dir, "simulate -q --quality interactive --out " + (dir / "blocked/sub"));
    EXPECT_NE(r.exit_code, 0);
    EXPECT_NE(r.err.find("blocked"), std::string::npos) << r.err;
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

}  // namespace
}  // namespace sonotrace
