// `sonotrace render` end to end on a small synthetic volume: outputs, the JSON record,
// determinism across thread counts, and bad input (clear message, non-zero exit, no
// partial files).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <OpenImageIO/imageio.h>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>

#include "probe/transducer.h"
#include "tests/test_util.h"
#include "tissue/raw_io.h"

namespace sonotrace {
namespace {

using test::files_in;
using test::run;
using test::ScratchDir;
using test::slurp;

// A 40^3 sphere of rising intensity in a raw volume.
std::string write_sphere(const ScratchDir& dir) {
    tissue::VolumeGeometry g;
    g.dims = {40, 40, 40};
    g.spacing = glm::dvec3(1.0);
    tissue::Volume v(g);
    for (int k = 0; k < 40; ++k)
        for (int j = 0; j < 40; ++j)
            for (int i = 0; i < 40; ++i)
                v.at(i, j, k) =
                    float(std::max(0.0, 18.0 - glm::length(glm::dvec3(i, j, k) - 19.5)));
    tissue::write_raw(v, dir / "sphere.raw");
    return dir / "sphere.json";
}

// An environment variable set for a scope (the commands run() starts inherit it), then
// restored: a test's setting does not leak into the tests after it.
class ScopedEnv {
  public:
    ScopedEnv(const char* name, const std::string& value) : name_(name) {
        if (const char* old = std::getenv(name)) old_ = old;
        setenv(name, value.c_str(), 1);
    }
    ~ScopedEnv() {
        if (old_)
            setenv(name_, old_->c_str(), 1);
        else
            unsetenv(name_);
    }
    ScopedEnv(const ScopedEnv&) = delete;
    ScopedEnv& operator=(const ScopedEnv&) = delete;

  private:
    const char* name_;
    std::optional<std::string> old_;
};

// The sanitizer options of a GPU run: Mesa's driver keeps allocations past exit, which
// LeakSanitizer would report (the other options stay).
std::string asan_options_for_mesa() {
    const char* asan = std::getenv("ASAN_OPTIONS");
    return std::string(asan ? asan : "") + ":detect_leaks=0";
}

TEST(CliRender, WritesTheImageTheReferenceAndTheRecord) {
    ScratchDir dir;
    const std::string volume = write_sphere(dir);
    const auto r = run(dir, "render -q --volume " + volume +
                                " --tf ramp --width 64 --height 48 "
                                "--repetitions 4 --out " +
                                (dir / "out/v.png") + " --reference " + (dir / "out/ref.png") +
                                " --json " + (dir / "out/v.json"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto record = nlohmann::json::parse(slurp(dir / "out/v.json"));
    EXPECT_EQ(record["repetitions"], 4);
    EXPECT_EQ(record["camera"]["width"], 64);
    EXPECT_GT(record["reference"]["psnr_db"].get<double>(), 15.0);
    EXPECT_GT(record["particles_per_repetition"].get<double>(), 0.0);
    EXPECT_FALSE(record.contains("cut_away_mm"));  // auto: only with the head preset
    EXPECT_EQ(files_in(dir / "out").size(), 3u);
}

TEST(CliRender, SameImageOnOneAndTwoThreads) {
    ScratchDir dir;
    const std::string volume = write_sphere(dir);
    // The GPU draws the particles in the order splats() lists them, whatever the threads.
#ifdef SONOTRACE_HAVE_GL_PBVR
    const std::vector<std::string> renderers{"cpu", "gpu"};
#else
    const std::vector<std::string> renderers{"cpu"};
#endif
    for (const std::string& renderer : renderers) {
        std::optional<ScopedEnv> asan;
        if (renderer == "gpu") asan.emplace("ASAN_OPTIONS", asan_options_for_mesa());
        for (const std::string threads : {"1", "2"}) {
            const auto r = run(dir, "render -q --volume " + volume +
                                        " --tf ramp --width 64 --height 64 "
                                        "--repetitions 3 --sampling metropolis --renderer " +
                                        renderer + " --threads " + threads + " --out " +
                                        (dir / renderer + threads) + ".png");
            ASSERT_EQ(r.exit_code, 0) << r.err;
        }
        EXPECT_EQ(slurp(dir / renderer + "1.png"), slurp(dir / renderer + "2.png")) << renderer;
    }
}

// The 8-bit PNG at `path` as bytes (RGB), through OpenImageIO.
std::vector<uint8_t> png_pixels(const std::string& path) {
    auto in = OIIO::ImageInput::open(path);
    if (!in) return {};
    const OIIO::ImageSpec& spec = in->spec();
    std::vector<uint8_t> pixels(std::size_t(spec.width) * std::size_t(spec.height) *
                                std::size_t(spec.nchannels));
    in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, pixels.data());
    return pixels;
}

double psnr_8bit(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
    double sum = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) sum += (double(a[i]) - b[i]) * (double(a[i]) - b[i]);
    return 10.0 * std::log10(255.0 * 255.0 / std::max(sum / double(a.size()), 1e-12));
}

// --renderer gpu draws the CPU renderer's particles (and the meshes' fragments) in
// OpenGL, in a context without a display (EGL; Mesa's software rasteriser on a machine
// without GPU). The expectation is the CPU image of the same seed, which the PBVR tests
// validate against the ray caster; the two differ only where particles tie in depth or
// sit on a disc's edge within float rounding (tests/gui/test_gl_pbvr.cpp: 77 dB on its
// float images), and after rounding to 8 bits a pixel may move by a level where the
// floats straddle a rounding boundary: the PNGs must agree to 55 dB PSNR. A GPU run one
// repetition short (about 48 dB) must be at least 3 dB further off: the comparison can
// fail. For a volume, and for two tetrahedral meshes fused (I-PBVR).
// The GPU tests need a build with OpenGL and EGL (scripts/setup.sh installs them).
#ifdef SONOTRACE_HAVE_GL_PBVR
#define SKIP_WITHOUT_GL()
#else
#define SKIP_WITHOUT_GL() GTEST_SKIP() << "built without OpenGL/EGL: --renderer gpu is absent"
#endif

void expect_gpu_draws_the_cpu_image(const ScratchDir& dir, const std::string& inputs,
                                    int repetitions) {
    auto render = [&](const std::string& renderer, int count) {
        const std::string name = renderer + std::to_string(count);
        std::optional<ScopedEnv> asan;
        if (renderer == "gpu") asan.emplace("ASAN_OPTIONS", asan_options_for_mesa());
        const auto r =
            run(dir, "render -q " + inputs + " --seed 5 --background 0.1,0.2,0.3" + " --renderer " +
                         renderer + " --repetitions " + std::to_string(count) + " --out " +
                         (dir / name) + ".png --json " + (dir / name) + ".json");
        EXPECT_EQ(r.exit_code, 0) << r.err;
        return png_pixels(dir / name + ".png");
    };
    const auto cpu = render("cpu", repetitions), gpu = render("gpu", repetitions),
               short_of_one = render("gpu", repetitions - 1);
    ASSERT_FALSE(cpu.empty());
    ASSERT_EQ(gpu.size(), cpu.size());
    ASSERT_EQ(short_of_one.size(), cpu.size());
    const double db = psnr_8bit(gpu, cpu);
    std::printf("GPU against CPU: %.1f dB; one repetition short: %.1f dB\n", db,
                psnr_8bit(short_of_one, cpu));
    EXPECT_GE(db, 55.0);
    EXPECT_LT(psnr_8bit(short_of_one, cpu), db - 3.0);
    const std::string n = std::to_string(repetitions);
    const auto record = nlohmann::json::parse(slurp(dir / "gpu" + n + ".json"));
    EXPECT_EQ(record["renderer"], "gpu");
    EXPECT_FALSE(record["gl_renderer"].get<std::string>().empty());
    EXPECT_EQ(record["particles_per_repetition"],
              nlohmann::json::parse(slurp(dir / "cpu" + n + ".json"))["particles_per_repetition"]);
}

TEST(CliRender, TheGpuRendererDrawsTheCpuImage) {
    SKIP_WITHOUT_GL();
    ScratchDir dir;
    expect_gpu_draws_the_cpu_image(
        dir, "--volume " + write_sphere(dir) + " --tf ramp --width 96 --height 80", 6);
}

// Without an OpenGL driver (glvnd pointed at no EGL vendor), --renderer gpu is an error
// naming the option, before any volume is loaded, and writes nothing.
TEST(CliRender, WithoutOpenGlTheGpuRendererIsAClearError) {
    SKIP_WITHOUT_GL();
    ScratchDir dir;
    const std::string volume = write_sphere(dir);
    std::optional<ScopedEnv> no_vendor(std::in_place, "__EGL_VENDOR_LIBRARY_FILENAMES",
                                       dir / "no_vendor.json");
    const auto r = run(dir, "render --renderer gpu --volume " + volume +
                                " --tf ramp --width 16 --height 16 --repetitions 1 --out " +
                                (dir / "out/g.png"));
    no_vendor.reset();
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("--renderer: gpu: no headless OpenGL context"), std::string::npos)
        << r.err;
    EXPECT_EQ(r.err.find("loading"), std::string::npos) << "loaded before failing: " << r.err;
    EXPECT_TRUE(files_in(dir / "out").empty());
}

// An image whose sub-pixels exceed the OpenGL's largest texture is an error naming the
// sizes (16384 x 16 sub-pixels across: more than any OpenGL's limit).
TEST(CliRender, TheGpuRendererNamesAnImageTooLargeForIt) {
    SKIP_WITHOUT_GL();
    const ScopedEnv asan("ASAN_OPTIONS", asan_options_for_mesa());
    ScratchDir dir;
    const auto r = run(dir, "render -q --renderer gpu --volume " + write_sphere(dir) +
                                " --tf ramp --width 16384 --height 1 --subpixel 16 "
                                "--repetitions 1 --out " +
                                (dir / "out/g.png"));
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("exceeds this OpenGL's largest texture"), std::string::npos) << r.err;
    EXPECT_TRUE(files_in(dir / "out").empty());
}

TEST(CliRender, TheGpuRendererDrawsTheCpuImageOfFusedMeshes) {
    SKIP_WITHOUT_GL();
    ScratchDir dir;
    const std::string phantoms = std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/pbvr/";
    expect_gpu_draws_the_cpu_image(
        dir,
        "--volume " + phantoms + "red_tetrahedron.vtk --tf " + phantoms + "red.json --volume " +
            phantoms + "blue_tetrahedron.vtk --tf " + phantoms + "blue.json --width 48 --height 48",
        6);
}

TEST(CliRender, FusesTetrahedralMeshesWithEachDepthMode) {
    ScratchDir dir;
    const std::string phantoms = std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/pbvr/";
    const std::string inputs = "--volume " + phantoms + "red_tetrahedron.vtk --tf " + phantoms +
                               "red.json --volume " + phantoms + "blue_tetrahedron.vtk --tf " +
                               phantoms + "blue.json --width 32 --height 32 --repetitions 20";
    const auto r = run(dir, "render -q " + inputs + " --out " + (dir / "f.png") + " --reference " +
                                (dir / "ref.png") + " --json " + (dir / "f.json"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto record = nlohmann::json::parse(slurp(dir / "f.json"));
    EXPECT_EQ(record["inputs"].size(), 2u);
    EXPECT_EQ(record["inputs"][0]["rendered_as"], "tetrahedra (I-PBVR)");
    EXPECT_GT(record["reference"]["psnr_db"].get<double>(), 20.0);
    for (const char* mode : {"entry", "middle", "exit", "random"}) {
        const auto m = run(dir, "render -q " + inputs + " --depth-sampling " + mode + " --out " +
                                    (dir / mode) + ".png");
        EXPECT_EQ(m.exit_code, 0) << mode << ": " << m.err;
    }
}

TEST(CliRender, HelpExplainsUnits) {
    ScratchDir dir;
    const auto r = run(dir, "render --help");
    ASSERT_EQ(r.exit_code, 0);
    for (const char* text : {"--azimuth", "[degrees]", "--distance", "[mm]", "--repetitions",
                             "--subpixel", "--cut-away", "--time-limit", "[s]"})
        EXPECT_NE(r.out.find(text), std::string::npos) << text;
}

TEST(CliRender, ATransparentTransferFunctionWarnsAndWritesTheBackground) {
    ScratchDir dir;
    const std::string volume = write_sphere(dir);
    std::ofstream(dir / "clear.json")
        << R"({"points": [{"value": 0, "colour": [1,1,1], "opacity": 0},
        {"value": 1, "colour": [1,1,1], "opacity": 0}]})";
    const auto r = run(dir, "render --volume " + volume + " --tf " + (dir / "clear.json") +
                                " --width 16 --height 16 --repetitions 1 --out " + (dir / "c.png"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find("warning: the transfer function makes every voxel transparent"),
              std::string::npos)
        << r.err;
    EXPECT_TRUE(std::filesystem::exists(dir / "c.png"));
}

// A frame of each array type overlays (a linear array has no field of view: 0 in its
// sidecar), and a sidecar with a field missing or of the wrong type is named, exit 1.
TEST(CliRender, OverlaysFramesOfEveryProbeTypeAndNamesBadSidecarFields) {
    ScratchDir dir;
    const std::string volume = write_sphere(dir);
    const std::string phantom = std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/cyst_and_stone.json";
    const std::string render = "render -q --volume " + volume +
                               " --tf ramp --repetitions 1 --width 16 --height 16 --frame ";
    for (const probe::Transducer& preset : probe::transducer_presets()) {
        const std::string probe = preset.name;
        const auto sim = run(dir, "simulate -q --quality interactive --phantom " + phantom +
                                      " --probe " + probe + " --out " + (dir / probe));
        ASSERT_EQ(sim.exit_code, 0) << probe << ": " << sim.err;
        const auto r = run(
            dir, render + (dir / (probe + "/bmode.json")) + " --out " + (dir / (probe + ".png")));
        EXPECT_EQ(r.exit_code, 0) << probe << ": " << r.err;
        EXPECT_TRUE(std::filesystem::exists(dir / (probe + ".png"))) << probe;
    }
    const auto good = nlohmann::json::parse(slurp(dir / "linear/bmode.json"));
    struct Mutation {
        std::string pointer;   // JSON pointer of the field changed
        nlohmann::json value;  // null: removed
        std::string message;
    };
    const Mutation mutations[] = {
        {"/image/origin_mm", nullptr, "field 'image.origin_mm'"},
        {"/image/origin_mm", "x", "field 'image.origin_mm'"},
        {"/image/pixel_spacing_mm", nlohmann::json::array({1, "a"}),
         "field 'image.pixel_spacing_mm'"},
        {"/image", 3, "field 'image'"},
        {"/probe/fov_deg", -1, "field 'probe.fov_deg'"},
        {"/pose/axial", nlohmann::json::array({0, 0, 0}), "field 'pose.axial'"},
    };
    for (const Mutation& m : mutations) {
        nlohmann::json j = good;
        const nlohmann::json::json_pointer at(m.pointer);
        if (m.value.is_null())
            j.at(at.parent_pointer()).erase(at.back());
        else
            j[at] = m.value;
        std::filesystem::create_directories(dir / "bad");
        std::filesystem::copy_file(dir / "linear/bmode.png", dir / "bad/bmode.png",
                                   std::filesystem::copy_options::overwrite_existing);
        std::ofstream(dir / "bad/bmode.json") << j.dump();
        const auto r = run(dir, render + (dir / "bad/bmode.json") + " --out " + (dir / "bad.png"));
        EXPECT_EQ(r.exit_code, 1) << m.pointer << ": " << r.err;
        EXPECT_NE(r.err.find("bad/bmode.json"), std::string::npos) << m.pointer << ": " << r.err;
        EXPECT_NE(r.err.find(m.message), std::string::npos) << m.pointer << ": " << r.err;
        EXPECT_FALSE(std::filesystem::exists(dir / "bad.png")) << m.pointer;
    }
}

// Ctrl-C stops a long render promptly, on either renderer, and writes the repetitions done (the
// record says so); without it, ten million repetitions would take hours. The signal is sent once
// the command says the refinement has begun (and half a second later, so that repetitions exist):
// sent at a fixed time instead, it raced the start-up on a loaded machine.
void expect_ctrl_c_stops_promptly(const std::string& renderer) {
    ScratchDir dir;
    const std::string volume = write_sphere(dir);
    const std::string err = dir / "err.txt";
    std::string script = "(";  // appended piecewise: GCC 12's -Wrestrict misfires on a chain
    script += SONOTRACE_BINARY;
    script += " render --renderer " + renderer + " --volume " + volume +
              " --tf ramp --width 64 --height 64 --repetitions 10000000 --out " + (dir / "r.png") +
              " --json " + (dir / "r.json") + " 2> " + err + " & pid=$!; i=0; ";
    script += "while ! grep -q Ctrl-C " + err + " && [ $i -lt 600 ]; do sleep 0.1; i=$((i+1)); ";
    script += "done; sleep 0.5; t0=$(date +%s%N); kill -INT $pid; wait $pid; status=$?; ";
    script +=
        "echo $(( ($(date +%s%N) - t0) / 1000000 )) > " + (dir / "stop_ms.txt") + "; exit $status)";
    const int status = std::system(("sh -c '" + script + "'").c_str());
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 0) << slurp(err);
    EXPECT_LT(std::stoi(slurp(dir / "stop_ms.txt")), 1000) << "stopped within a second";
    EXPECT_TRUE(std::filesystem::exists(dir / "r.png"));
    const auto record = nlohmann::json::parse(slurp(dir / "r.json"));
    EXPECT_EQ(record.at("stopped_by"), "interrupt") << record.dump();
    EXPECT_GT(record.at("repetitions").get<int>(), 0);
    EXPECT_LT(record.at("repetitions").get<int>(), 10000000);
}

TEST(CliRender, CtrlCStopsPromptlyAndWritesTheRepetitionsDone) {
    expect_ctrl_c_stops_promptly("cpu");
}

TEST(CliRender, CtrlCStopsTheGpuRendererPromptlyToo) {
    SKIP_WITHOUT_GL();
    const ScopedEnv asan("ASAN_OPTIONS", asan_options_for_mesa());
    expect_ctrl_c_stops_promptly("gpu");
}

// Ctrl-C before the first repetition ends is an interrupt (130), not bad input (1), and
// writes nothing. The repetition is made long (a 4096^2 image at 16 sub-pixels) and the
// signal sent as soon as the command says the refinement has begun.
TEST(CliRender, CtrlCBeforeTheFirstRepetitionIsAnInterruptAndWritesNothing) {
    ScratchDir dir;
    const std::string volume = write_sphere(dir);
    const std::string err = dir / "err.txt";
    std::string script = "(";
    script += SONOTRACE_BINARY;
    script += " render --volume " + volume +
              " --tf ramp --width 4096 --height 4096 --subpixel 4 --repetitions 2 --out " +
              (dir / "r.png") + " 2> " + err + " & pid=$!; i=0; ";
    script += "while ! grep -q Ctrl-C " + err + " && [ $i -lt 600 ]; do sleep 0.05; i=$((i+1)); ";
    script += "done; kill -INT $pid; wait $pid)";
    const int status = std::system(("sh -c '" + script + "'").c_str());
    ASSERT_TRUE(WIFEXITED(status));
    const std::string text = slurp(err);
    if (WEXITSTATUS(status) == 0)  // the image was written: a repetition had ended
        GTEST_SKIP() << "the first repetition ended before the signal arrived";
    EXPECT_EQ(WEXITSTATUS(status), 130) << text;
    EXPECT_NE(text.find("interrupted before a repetition finished: nothing written"),
              std::string::npos)
        << text;
    EXPECT_FALSE(std::filesystem::exists(dir / "r.png"));
}

TEST(CliRender, BadInputIsNamedAndLeavesNoFiles) {
    ScratchDir dir;
    const std::string volume = write_sphere(dir);
    std::ofstream(dir / "unsorted.json")
        << R"({"points": [{"value": 0.5, "colour": [1,1,1], "opacity": 0},
        {"value": 0.2, "colour": [1,1,1], "opacity": 0.1}]})";
    std::ofstream(dir / "broken.json") << R"({"points": [)";
    struct Case {
        std::string args, message;
    };
    const Case cases[] = {
        {"--tf " + (dir / "unsorted.json"), "field 'points[1].value'"},
        {"--tf " + (dir / "broken.json"), "broken.json"},
        {"--tf nosuchpreset", "presets: head, ramp"},
        {"--fov 0", "camera: field 'fov'"},
        {"--fov 200", "camera: field 'fov'"},
        {"--elevation 90", "camera: field 'elevation'"},
        {"--repetitions 0", "field 'repetitions'"},
        {"--width 0", "camera: field 'width'"},
        {"--subpixel 0", "field 'subpixel_level'"},
        // each in range, their product (terabytes of sub-pixels) not
        {"--width 16384 --height 16384 --subpixel 16", "--subpixel^2: would need"},
        {"--sampling best", "--sampling"},
        {"--background 1,2", "--background"},
        {"--cut-away 1,2,3", "--cut-away"},
        {"--volume " + (dir / "missing.nii"), "missing.nii"},
        {"--volume " + volume + " --volume " + volume + " --tf ramp",
         "one transfer function per --volume"},
        {"--depth-sampling deepest", "--depth-sampling"},
        {"--sector", "needs --frame"},
        {"--frame " + (dir / "nosuch.json"), "nosuch.json"},
        {"--renderer vulkan", "--renderer: must be 'cpu' or 'gpu'"},
    };
    for (const Case& c : cases) {
        std::string args = c.args;  // the case's options, then defaults for the others
        for (const auto& [option, value] :
             {std::pair{"--volume", volume}, std::pair{"--tf", std::string("ramp")},
              std::pair{"--repetitions", std::string("1")}, std::pair{"--width", std::string("16")},
              std::pair{"--height", std::string("16")}})
            if (args.find(option) == std::string::npos)
                args.append(" ").append(option).append(" ").append(value);
        const auto r = run(dir, "render -q --out " + (dir / "out/x.png") + " " + args);
        EXPECT_EQ(r.exit_code, 1) << c.args << ": " << r.err;
        EXPECT_NE(r.err.find(c.message), std::string::npos) << c.args << ": " << r.err;
        EXPECT_TRUE(files_in(dir / "out").empty()) << c.args;
    }
    // An unwritable output path fails cleanly too.
    const auto r = run(dir, "render -q --tf ramp --repetitions 1 --width 16 --height 16 --volume " +
                                volume + " --out /proc/forbidden/x.png");
    EXPECT_EQ(r.exit_code, 1);
}

}  // namespace
}  // namespace sonotrace
