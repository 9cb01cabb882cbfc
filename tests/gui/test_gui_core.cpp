// The live scanner behind sonotrace-gui, without a display: scenes and their errors,
// the worker's latest-wins requests, what moving the probe and the physics switches do
// to the frame, the control extremes, and the explain panel.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>

#include "imaging/simulation.h"
#include "phantoms/phantom.h"
#include "probe/array_geometry.h"
#include "tissue/base/error.h"
#include "tissue/tissue_table.h"
#include "ui/gui/controls.h"
#include "ui/gui/scanner.h"

namespace sonotrace::gui {
namespace {

const std::string kPhantoms = SONOTRACE_SOURCE_DIR "/phantoms";

std::shared_ptr<const Scene> cyst_scene() {
    static const auto scene = load_scene("phantom:cyst_and_stone", kPhantoms);
    return scene;
}

ScanRequest request_for(std::shared_ptr<const Scene> scene) {
    ScanRequest r;
    r.scene = scene;
    r.pose = scene->start.pose;
    r.parameters.transducer = probe::find_transducer(scene->probe_preset, "test");
    r.parameters.gain_db = 36.0;
    r.context.enabled = false;
    r.refine = false;
    return r;
}

ScanFrame simulate(const ScanRequest& r) {
    auto frame = simulate_request(r, r.parameters.quality);
    EXPECT_TRUE(frame.has_value());
    return std::move(*frame);
}

// Mean of the frame's pixels inside the scanned region, over depths [d0, d1) mm.
double mean_inside(const ScanFrame& f, double d0 = 0.0, double d1 = 1e9) {
    const imaging::ScanConverted& img = f.frame.image;
    double sum = 0.0;
    int n = 0;
    for (int r = 0; r < img.image.rows; ++r) {
        const double depth = img.origin.y + r * img.pixel_mm;
        if (depth < d0 || depth >= d1) continue;
        for (int c = 0; c < img.image.cols; ++c)
            if (img.inside.at<uint8_t>(r, c)) sum += img.image.at<float>(r, c), ++n;
    }
    return n ? sum / n : 0.0;
}

// Lateral centroid (mm, probe plane) of the dark pixels (< 0.1) in a window.
double dark_centroid_x(const ScanFrame& f, double x0, double x1, double d0, double d1) {
    const imaging::ScanConverted& img = f.frame.image;
    double sum = 0.0;
    int n = 0;
    for (int r = 0; r < img.image.rows; ++r) {
        const double depth = img.origin.y + r * img.pixel_mm;
        if (depth < d0 || depth > d1) continue;
        for (int c = 0; c < img.image.cols; ++c) {
            const double x = img.origin.x + c * img.pixel_mm;
            if (x < x0 || x > x1 || !img.inside.at<uint8_t>(r, c)) continue;
            if (img.image.at<float>(r, c) < 0.1f) sum += x, ++n;
        }
    }
    EXPECT_GT(n, 100) << "no dark region in the window";
    return n ? sum / n : 0.0;
}

TEST(GuiScene, CatalogueListsHeadViewsAndEveryPhantom) {
    const auto entries = scene_catalogue(kPhantoms);
    int phantoms = 0;
    for (const auto& e : std::filesystem::directory_iterator(kPhantoms))
        phantoms += e.path().extension() == ".json";
    ASSERT_EQ(entries.size(), std::size_t(2 + phantoms));
    EXPECT_EQ(entries[0].name, "head-craniotomy");
    EXPECT_EQ(entries[1].name, "head-temporal");
    // Every phantom of the catalogue loads as a scene.
    for (std::size_t i = 2; i < entries.size(); ++i)
        EXPECT_NO_THROW(load_scene(entries[i].name, kPhantoms)) << entries[i].name;
}

// A phantom of meshes is drawn by its shapes, not its impedance: every texel of the
// context holds the shape it lies in (the phantom's own inside test, at the texel
// centre), the meshes' shapes are drawn in their tissue's legend colour, the layers
// (which fill the box) and the background not at all.
TEST(GuiScene, AMeshPhantomsContextDrawsEachOrganInItsTissuesColour) {
    const auto scene = load_scene("phantom:abdomen_meshes", kPhantoms);
    ASSERT_TRUE(scene->phantom && scene->context);
    const phantoms::Phantom& phantom = *scene->phantom;
    const tissue::Volume& context = *scene->context;
    const tissue::VolumeGeometry& g = context.geometry();
    int checked = 0;
    for (int k = 0; k < g.dims.z; k += 7)
        for (int j = 0; j < g.dims.y; j += 7)
            for (int i = 0; i < g.dims.x; i += 7) {
                int instance = 0;
                phantom.at(g.index_to_world({double(i), double(j), double(k)}), nullptr, &instance);
                ASSERT_EQ(context.at(i, j, k), float(instance));
                ++checked;
            }
    EXPECT_GT(checked, 1000);
    const auto& tf = scene->context_tf;
    EXPECT_EQ(tf.extinction(tf.normalize(0.0f)), 0.0f);  // the background
    for (std::size_t k = 0; k < phantom.shapes.size(); ++k) {
        const phantoms::Shape& shape = phantom.shapes[k];
        const float s = tf.normalize(float(k + 1));
        if (shape.type == phantoms::ShapeType::layer) {
            EXPECT_EQ(tf.extinction(s), 0.0f) << k;
            continue;
        }
        EXPECT_GT(tf.extinction(s), 0.0f) << k;
        const cv::Vec3b bgr = imaging::label_colour(shape.label);
        const glm::vec3 c = tf.colour(s);
        EXPECT_NEAR(c.x, bgr[2] / 255.0, 0.01) << k;
        EXPECT_NEAR(c.y, bgr[1] / 255.0, 0.01) << k;
        EXPECT_NEAR(c.z, bgr[0] / 255.0, 0.01) << k;
    }
}

TEST(GuiScene, BadFilesAreErrorsNamingTheFile) {
    const auto dir = std::filesystem::temp_directory_path() / "sonotrace_gui_scene";
    std::filesystem::create_directories(dir);
    const std::string corrupt = (dir / "corrupt.nii").string();
    std::ofstream(corrupt) << "this is not a NIfTI file";
    const std::string bad_json = (dir / "bad.json").string();
    std::ofstream(bad_json) << "{\"shapes\": [ {\"type\": \"sphere\" ";
    for (const std::string& spec : {std::string("/nonexistent/head.nii.gz"), corrupt, bad_json,
                                    std::string("phantom:no_such_phantom")}) {
        try {
            load_scene(spec, kPhantoms);
            ADD_FAILURE() << spec << " loaded";
        } catch (const base::InputError& e) {
            EXPECT_NE(std::string(e.what()).find(spec), std::string::npos) << e.what();
        }
    }
}

TEST(GuiScene, AProbeDraggedOverTheHeadStaysOnItsSurface) {
    // Slid 10 mm along the array, the probe is laid back on the curved surface (cortex
    // under the craniotomy, skin at the temple): settling again does not move it, and it
    // moved about 10 mm.
    for (const char* name : {"head-craniotomy", "head-temporal"}) {
        const auto scene = load_scene(name, kPhantoms);
        const probe::Pose start = scene->start.pose;
        EXPECT_LT(glm::distance(scene->settle(start).position, start.position), 0.2) << name;
        for (double slide : {-10.0, 10.0}) {
            probe::Pose moved = start;
            moved.position += slide * start.lateral();
            const probe::Pose settled = scene->settle(moved);
            EXPECT_LT(glm::distance(scene->settle(settled).position, settled.position), 0.2)
                << name << " " << slide;
            EXPECT_NEAR(glm::distance(settled.position, start.position), 10.0, 3.0)
                << name << " " << slide;
        }
    }
}

TEST(GuiScanner, SameRequestGivesIdenticalFrames) {
    const ScanRequest r = request_for(cyst_scene());
    const ScanFrame a = simulate(r), b = simulate(r);
    ASSERT_EQ(a.frame.image.image.size(), b.frame.image.image.size());
    EXPECT_EQ(cv::norm(a.frame.image.image, b.frame.image.image, cv::NORM_INF), 0.0);
}

TEST(GuiScanner, SlidingTheProbeMovesTheCystTheOtherWay) {
    // The cyst (a water sphere) lies at a fixed world x; the probe slides by +6 mm, so in
    // the image it moves by -6 mm. Expected position from the phantom's geometry.
    const auto scene = cyst_scene();
    const phantoms::Phantom phantom = phantoms::load_phantom(kPhantoms + "/cyst_and_stone.json");
    const glm::dvec3 cyst = phantom.shapes[0].a;
    ScanRequest r = request_for(scene);
    for (double slide : {0.0, 6.0}) {
        r.pose.position = scene->start.pose.position + slide * scene->start.pose.lateral();
        const ScanFrame f = simulate(r);
        const double expected = cyst.x - r.pose.position.x;
        const double x =
            dark_centroid_x(f, expected - 7.0, expected + 7.0, cyst.y - 4.0, cyst.y + 4.0);
        EXPECT_NEAR(x, expected, 0.75) << "slide " << slide;
    }
}

TEST(GuiScanner, PhysicsSwitchesChangeWhatTheyShould) {
    ScanRequest r = request_for(cyst_scene());
    const ScanFrame on = simulate(r);
    // Without scattering the liver has no speckle: only the interfaces echo.
    r.parameters.physics.set(imaging::Physics::scattering, false);
    const ScanFrame no_scatter = simulate(r);
    EXPECT_LT(mean_inside(no_scatter), 0.3 * mean_inside(on));
    // Without attenuation the deep tissue gets brighter (the TGC still compensates).
    r.parameters.physics.set(imaging::Physics::scattering, true);
    r.parameters.physics.set(imaging::Physics::attenuation, false);
    const ScanFrame lossless = simulate(r);
    EXPECT_GT(mean_inside(lossless, 30.0, 40.0), mean_inside(on, 30.0, 40.0) + 0.05);
}

// Mean of the frame inside the scanned region between two depths below a line
// depth = a + b x (mm).
double mean_below(const ScanFrame& f, double a, double b, double from_mm, double to_mm) {
    const imaging::ScanConverted& img = f.frame.image;
    double sum = 0.0;
    int n = 0;
    for (int row = 0; row < img.image.rows; ++row) {
        for (int c = 0; c < img.image.cols; ++c) {
            const double x = img.origin.x + c * img.pixel_mm;
            const double below = img.origin.y + row * img.pixel_mm - (a + b * x);
            if (below < from_mm || below > to_mm) continue;
            if (img.inside.at<uint8_t>(row, c)) sum += img.image.at<float>(row, c), ++n;
        }
    }
    EXPECT_GT(n, 1000);
    return sum / std::max(n, 1);
}

// point_grid's 0.1 mm wire under the probe at 20 mm (reflectivity 0.3) against the weakly
// scattering gel beside it (lateral 3-8 mm, 25-35 mm deep: no wires there): at least 20 dB
// brighter, a third of the display's 60 dB.
void expect_wire_above_gel(const ScanFrame& f) {
    const imaging::ScanConverted& img = f.frame.image;
    auto pixel = [&](double x, double depth) {
        return img.image.at<float>(int(std::lround((depth - img.origin.y) / img.pixel_mm)),
                                   int(std::lround((x - img.origin.x) / img.pixel_mm)));
    };
    float wire = 0.0f;
    for (double x = -0.5; x <= 0.5; x += 0.05)
        for (double d = 19.5; d <= 20.5; d += 0.05) wire = std::max(wire, pixel(x, d));
    double gel = 0.0;
    int n = 0;
    for (double x = 3.0; x <= 8.0; x += 0.2)
        for (double d = 25.0; d <= 35.0; d += 0.2) gel += pixel(x, d), ++n;
    gel /= n;
    EXPECT_GT(wire, gel + 20.0 / 60.0) << "wire " << wire << ", gel " << gel;
}

TEST(GuiScanner, FramesAreSimulatesFramesOfTheSameScene) {
    // The GUI and `sonotrace simulate` take their scene from one place (scene::Scene),
    // so the same settings and seed make the same frame, point targets included. Before
    // the scene was one type, the GUI dropped a phantom's targets.
    const auto scene = load_scene("phantom:point_grid", kPhantoms);
    const ScanFrame gui = simulate(request_for(scene));
    ASSERT_FALSE(scene->targets.empty());
    const imaging::Frame cli =
        imaging::simulate_plane(scene->mapper, scene->start, gui.settings, false).frame;
    ASSERT_EQ(gui.frame.envelope.values.size(), cli.envelope.values.size());
    EXPECT_EQ(0, std::memcmp(gui.frame.envelope.values.data(), cli.envelope.values.data(),
                             cli.envelope.values.size() * sizeof(float)));
    expect_wire_above_gel(gui);
}

TEST(GuiScanner, ThreeDimensionalFramesAreSimulatesToo) {
    // The GUI's "trace in 3D" switch makes simulate's --trace 3d frame, and the tissue view
    // still shows the plane (the slab's middle slice).
    const auto scene = load_scene("phantom:cyst_and_stone", kPhantoms);
    ScanRequest r = request_for(scene);
    r.parameters.trace_dimensions = 3;
    const ScanFrame gui = simulate(r);
    ASSERT_EQ(gui.settings.trace_dimensions, 3);
    const imaging::Frame cli =
        imaging::simulate_plane(scene->mapper, scene->start, gui.settings, false).frame;
    ASSERT_EQ(gui.frame.envelope.values.size(), cli.envelope.values.size());
    EXPECT_EQ(0, std::memcmp(gui.frame.envelope.values.data(), cli.envelope.values.data(),
                             cli.envelope.values.size() * sizeof(float)));
    EXPECT_FALSE(gui.slice.empty());
}

TEST(GuiScanner, UnfocusedTransmitsMakeSimulatesChannelFrames) {
    // The transmit panel's plane and diverging waves are `simulate --transmit`'s frames:
    // the same channel data and image bytes, the scheme's text as the CLI would take it,
    // the energy map and the paths of the whole acquisition, and the wire at 20 mm shows.
    const auto scene = load_scene("phantom:point_grid", kPhantoms);
    ScanRequest r = request_for(scene);
    r.parameters.transmit.kind = TransmitControls::Kind::plane;
    r.parameters.transmit.count = 5;
    r.parameters.transmit.span_deg = 8.0;
    r.paths_per_line = 4;
    const ScanFrame gui = simulate(r);
    ASSERT_TRUE(gui.settings.transmit.has_value());
    EXPECT_EQ(gui.settings.transmit->text, "plane:-8:8:5");
    ASSERT_TRUE(gui.frame.channels.has_value());
    EXPECT_EQ(gui.frame.channels->transmits, 5);
    imaging::SimulationSettings cli_settings = gui.settings;
    cli_settings.trace.record_paths = 0;  // drawing only: the frame's bytes do not depend on it
    const imaging::Frame cli =
        imaging::simulate_plane(scene->mapper, scene->start, cli_settings, false).frame;
    ASSERT_TRUE(cli.channels.has_value());
    ASSERT_EQ(gui.frame.channels->values.size(), cli.channels->values.size());
    EXPECT_EQ(0, std::memcmp(gui.frame.channels->values.data(), cli.channels->values.data(),
                             cli.channels->values.size() * sizeof(float)));
    ASSERT_EQ(gui.frame.image.image.size(), cli.image.image.size());
    EXPECT_EQ(cv::norm(gui.frame.image.image, cli.image.image, cv::NORM_INF), 0.0);
    // Paths on the transmits 0, 1, ... (the line stride applies to transmits), 4 each.
    EXPECT_EQ(gui.frame.paths.size(), 5u * 4u);
    ASSERT_GT(gui.frame.absorbed.size(), 0u);
    EXPECT_GT(cv::sum(cv::Mat(1, int(gui.frame.absorbed.size()), CV_32F,
                              const_cast<float*>(gui.frame.absorbed.voxels().data())))[0],
              0.0);
    expect_wire_above_gel(gui);

    // The panel's other texts, as parse_transmit_scheme reads them.
    TransmitControls tx;
    const probe::Transducer linear = probe::find_transducer("linear", "test");
    EXPECT_EQ(tx.text(linear), "focused");
    tx.kind = TransmitControls::Kind::plane;
    tx.count = 1;
    EXPECT_EQ(tx.text(linear), "plane:0");
    tx.kind = TransmitControls::Kind::diverging;
    tx.count = 3;
    tx.span_deg = 10.0;
    const probe::TransmitScheme diverging = probe::parse_transmit_scheme(tx.text(linear), "", "");
    ASSERT_EQ(diverging.waves.size(), 3u);
    EXPECT_NEAR(diverging.waves[0].angle_rad, glm::radians(-10.0), 1e-12);
    EXPECT_NEAR(diverging.waves[0].source_distance_mm, 0.5 * linear.array_length_mm(), 1e-9);
}

TEST(GuiControls, UnfocusedTransmitsOnlyWhereTheArrayIsOpen) {
    // The panel offers plane and diverging waves on every open preset (linear, convex,
    // phased, picmus) and not on the radial ring, where the settings refuse them naming
    // the field.
    const auto scene = cyst_scene();
    int open = 0;
    for (const probe::Transducer& preset : probe::transducer_presets()) {
        ScanParameters p;
        p.transducer = preset;
        p.transmit.kind = TransmitControls::Kind::diverging;
        SCOPED_TRACE(preset.name);
        if (offers_unfocused_transmits(preset)) {
            ++open;
            EXPECT_NO_THROW(p.settings(*scene));
            p.transmit.kind = TransmitControls::Kind::plane;
            EXPECT_NO_THROW(p.settings(*scene));
            continue;
        }
        try {
            p.settings(*scene);
            ADD_FAILURE() << "a ring took diverging waves";
        } catch (const base::InputError& e) {
            EXPECT_NE(std::string(e.what()).find("transmit"), std::string::npos) << e.what();
        }
    }
    EXPECT_EQ(open, 4);
}

TEST(GuiScanner, MirrorImageNeedsAReflectedBeam) {
    // Beyond the mirror phantom's air interface (y = 32 + tan(20 deg) x mm under the
    // probe; air has no scatterers) the frame shows the liver seen by the reflected
    // beams: it goes when particles end at their first reflection, and when they do
    // not reflect at all.
    const auto scene = load_scene("phantom:mirror", kPhantoms);
    ScanRequest r = request_for(scene);
    const double slope = std::tan(glm::radians(20.0));
    const double mirrored = mean_below(simulate(r), 32.0, slope, 3.0, 7.0);
    r.parameters.physics.set(imaging::Physics::bounces, false);
    const double direct_only = mean_below(simulate(r), 32.0, slope, 3.0, 7.0);
    r.parameters.physics.set(imaging::Physics::bounces, true);
    r.parameters.physics.set(imaging::Physics::specular, false);
    const double none = mean_below(simulate(r), 32.0, slope, 3.0, 7.0);
    // Visible: the display maps 60 dB onto 0..1, so 0.2 is 12 dB above black.
    EXPECT_GT(mirrored, 0.2);
    EXPECT_LT(direct_only, 0.3 * mirrored);
    EXPECT_LT(none, 0.3 * mirrored);
}

TEST(GuiScanner, ReverberationNeedsMultipleBounces) {
    // Two 1 mm plates at 10 and 15 mm depth in water (no scatterers): their echoes, then
    // reverberations between them from 19 mm on, which take two reflections or more.
    const auto scene = load_scene("phantom:parallel_plates", kPhantoms);
    ScanRequest r = request_for(scene);
    r.parameters.quality = imaging::Quality::standard;
    // The first reverberation lies at 20 mm (16 + 4: the gap once more); its contrast
    // against the echo-free water at 21.5-23 mm.
    auto contrast = [&](const ScanFrame& f) {
        return mean_below(f, 19.6, 0.0, 0.0, 0.8) - mean_below(f, 21.5, 0.0, 0.0, 1.5);
    };
    const double reverberating = contrast(simulate(r));
    r.parameters.physics.set(imaging::Physics::bounces, false);
    const double direct_only = contrast(simulate(r));
    EXPECT_GT(reverberating, 0.15);
    EXPECT_LT(direct_only, 0.3 * reverberating) << reverberating;
}

TEST(GuiScanner, LatestRequestWinsAndErrorsAreReported) {
    const auto scene = cyst_scene();
    Scanner scanner;
    ScanRequest a = request_for(scene), b = request_for(scene);
    b.pose.position += 4.0 * b.pose.lateral();
    scanner.submit(a);
    const uint64_t id_b = scanner.submit(b);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    std::optional<ScanFrame> last;
    while (std::chrono::steady_clock::now() < deadline) {
        if (auto f = scanner.take_frame()) last = std::move(f);
        if (!scanner.busy() && last && last->request == id_b) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    ASSERT_TRUE(last.has_value());
    EXPECT_EQ(last->request, id_b);
    EXPECT_NEAR(glm::distance(last->pose.position, b.pose.position), 0.0, 1e-9);

    // An impossible setting comes back as an error naming it; the scanner keeps going.
    ScanRequest bad = request_for(scene);
    bad.parameters.transducer.focus_mm = 1e9;
    scanner.submit(bad);
    std::optional<std::string> error;
    while (!error && std::chrono::steady_clock::now() < deadline) {
        error = scanner.take_error();
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    ASSERT_TRUE(error.has_value());
    EXPECT_NE(error->find("focus"), std::string::npos) << *error;
    scanner.submit(a);
    while (scanner.busy() && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    EXPECT_TRUE(scanner.take_frame().has_value());
}

TEST(GuiScanner, RefinementAndContextFollowAStillProbe) {
    Scanner scanner;
    ScanRequest r = request_for(cyst_scene());
    r.refine = true;
    r.context.enabled = true;
    r.context.width = r.context.height = 96;
    scanner.submit(r);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    std::vector<imaging::Quality> qualities;
    int repetitions = 0;
    while (std::chrono::steady_clock::now() < deadline && (scanner.busy() || qualities.empty())) {
        if (auto f = scanner.take_frame()) qualities.push_back(f->quality);
        if (auto c = scanner.take_context()) repetitions = c->repetitions;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    if (auto f = scanner.take_frame()) qualities.push_back(f->quality);
    if (auto c = scanner.take_context()) repetitions = c->repetitions;
    ASSERT_FALSE(qualities.empty());
    EXPECT_EQ(qualities.back(), imaging::Quality::high);
    EXPECT_EQ(repetitions, 24);  // the high stage's context repetitions
}

TEST(GuiControls, EverySliderExtremeGivesAFrame) {
    // For every preset, each slider at its minimum and maximum (slider_max, as the panel
    // clamps it) is a valid setting; on the phantom each gives a finite frame.
    const auto scene = cyst_scene();
    for (const probe::Transducer& preset : probe::transducer_presets()) {
        for (const SliderSpec& spec : slider_specs()) {
            // The panel shows the fov slider only where the type's fov is adjustable.
            if (spec.control == Control::fov && !probe::array_type(preset.type).fov_adjustable)
                continue;
            // ... and the transmits' sliders for unfocused transmits, which open arrays take.
            const bool unfocused =
                spec.control == Control::transmits || spec.control == Control::span;
            if (unfocused && !offers_unfocused_transmits(preset)) continue;
            for (double value : {spec.min, slider_max(spec.control, preset)}) {
                ScanRequest r = request_for(scene);
                r.parameters.transducer = preset;
                if (unfocused) r.parameters.transmit.kind = TransmitControls::Kind::plane;
                probe::Transducer& t = r.parameters.transducer;
                switch (spec.control) {
                    case Control::depth:
                        t.depth_mm = value;
                        break;
                    case Control::focus:
                        t.focus_mm = value;
                        break;
                    case Control::frequency:
                        t.frequency_mhz = value;
                        break;
                    case Control::lines:
                        t.lines = int(value);
                        break;
                    case Control::fov:
                        t.fov_deg = value;
                        break;
                    case Control::gain:
                        r.parameters.gain_db = value;
                        break;
                    case Control::dynamic_range:
                        r.parameters.dynamic_range_db = value;
                        break;
                    case Control::tgc:
                        r.parameters.tgc_db.fill(value);
                        break;
                    case Control::transmits:
                        r.parameters.transmit.count = int(value);
                        break;
                    case Control::span:
                        r.parameters.transmit.span_deg = value;
                        break;
                    default:
                        FAIL() << spec.label;
                }
                // The panel keeps every slider within its (probe-dependent) maximum.
                t.focus_mm = std::min(t.focus_mm, slider_max(Control::focus, t));
                if (probe::array_type(t.type).fov_adjustable)
                    t.fov_deg = std::min(t.fov_deg, slider_max(Control::fov, t));
                SCOPED_TRACE(preset.name + " " + spec.label + " = " + std::to_string(value));
                ASSERT_NO_THROW(r.parameters.settings(*scene));
                if (preset.name != scene->probe_preset) continue;  // frames: the scene's probe
                // 75 transmits of speckle on 128 elements take seconds: the tissue's
                // scatterers off (the traced echoes kept) and 20 mm deep.
                if (unfocused) {
                    r.parameters.physics.set(imaging::Physics::scattering, false);
                    t.depth_mm = 20.0;
                }
                const ScanFrame f = simulate(r);
                ASSERT_FALSE(f.frame.image.image.empty());
                EXPECT_TRUE(cv::checkRange(f.frame.image.image, true, nullptr, 0.0, 1.0 + 1e-6));
            }
        }
    }
}

TEST(GuiControls, EveryCombinationOfPhysicsSwitchesGivesAFrame) {
    // All 2^7 settings of the switches, in both receive models: a valid, finite frame
    // each (all off is a black one), at the coarsest map to keep it quick.
    const auto scene = cyst_scene();
    for (int mask = 0; mask < 128; ++mask) {
        ScanRequest r = request_for(scene);
        PhysicsSwitches& s = r.parameters.physics;
        const imaging::Physics switches[] = {
            imaging::Physics::refraction, imaging::Physics::specular,    imaging::Physics::diffuse,
            imaging::Physics::scattering, imaging::Physics::attenuation, imaging::Physics::bounces,
            imaging::Physics::face};
        for (int b = 0; b < 7; ++b) s.set(switches[b], (mask >> b) & 1);
        r.parameters.receive =
            mask % 3 == 0 ? imaging::ReceiveModel::capture : imaging::ReceiveModel::monostatic;
        r.parameters.transducer.lines = 32;
        SCOPED_TRACE(mask);
        const ScanFrame f = simulate(r);
        EXPECT_TRUE(cv::checkRange(f.frame.image.image, true, nullptr, 0.0, 1.0 + 1e-6));
        EXPECT_LT(std::abs(f.frame.ledger.relative_error()), 1e-6);
    }
}

TEST(GuiExplain, ArtifactsFollowTheMaterialsAndSwitches) {
    auto names = [](const std::vector<Artifact>& list) {
        std::set<std::string> out;
        for (const auto& a : list) out.insert(a.name);
        return out;
    };
    ScanParameters p;
    const auto cyst = names(explain(*cyst_scene(), p));
    EXPECT_TRUE(cyst.count("posterior enhancement"));  // the water cyst
    EXPECT_TRUE(cyst.count("acoustic shadowing"));     // the calcified plaque
    EXPECT_TRUE(cyst.count("speckle"));
    const auto mirror = names(explain(*load_scene("phantom:mirror", kPhantoms), p));
    EXPECT_TRUE(mirror.count("mirror images"));
    const auto layer = names(explain(*load_scene("phantom:speed_layer", kPhantoms), p));
    EXPECT_TRUE(layer.count("speed-of-sound displacement"));
    EXPECT_FALSE(layer.count("posterior enhancement"));  // no fluid there
    p.physics.set(imaging::Physics::scattering, false);
    EXPECT_FALSE(names(explain(*cyst_scene(), p)).count("speckle"));
    p.receive = imaging::ReceiveModel::capture;
    EXPECT_TRUE(names(explain(*cyst_scene(), p)).count("reverberation"));
    // Plane waves: the unfocused transmit explained; no face reverberation (channel frames
    // receive monostatically).
    ScanParameters plane;
    plane.transmit.kind = TransmitControls::Kind::plane;
    const auto unfocused = names(explain(*cyst_scene(), plane));
    EXPECT_TRUE(unfocused.count("unfocused transmit"));
    EXPECT_FALSE(unfocused.count("reverberation (off)"));
    EXPECT_FALSE(names(explain(*cyst_scene(), ScanParameters{})).count("unfocused transmit"));
    // Every physics switch has its control, and its help is its row's description.
    for (const simulator::PhysicsSwitch& sw : simulator::kPhysicsSwitches) {
        EXPECT_EQ(physics_of(physics_control(sw.id)), sw.id);
        EXPECT_EQ(switch_help(physics_control(sw.id)), sw.description);
    }
    EXPECT_FALSE(physics_of(Control::fov).has_value());
    // Every artifact names a control, with help text to show.
    for (const Artifact& a : explain(*cyst_scene(), p)) {
        if (a.control != Control::none && a.control != Control::tgc) {
            EXPECT_FALSE(switch_help(a.control).empty()) << a.name;
        }
    }
}

// The explain panel quotes the scene's own materials: the head's skull at the tissue
// table's cortical bone speed, the speed layer phantom's two layers at the speeds its
// JSON gives (read here from the file, not from the scene).
TEST(GuiExplain, NumbersAreTheScenesMaterials) {
    auto why = [](const std::vector<Artifact>& list, const std::string& name) {
        for (const auto& a : list)
            if (a.name == name) return a.why;
        ADD_FAILURE() << "no artifact " << name;
        return std::string();
    };
    ScanParameters p;
    const std::string head =
        why(explain(*load_scene("head-craniotomy", kPhantoms), p), "refraction displacement");
    const auto& bone = tissue::find_tissue("cortical_bone", "", "");
    const std::string bone_speed =
        std::to_string(int(bone.properties[tissue::Property::speed_of_sound])) + " m/s";
    EXPECT_NE(head.find(std::string(bone.name) + " " + bone_speed), std::string::npos) << head;
    EXPECT_EQ(head.find("2800"), std::string::npos) << head;
    // The layer phantom's slowest and fastest speeds, from its JSON and the tissue table.
    std::ifstream file(kPhantoms + "/speed_layer.json");
    const nlohmann::json layer_json = nlohmann::json::parse(file);
    auto speed = [](const nlohmann::json& item) {
        if (item.contains("tissue"))
            return int(tissue::find_tissue(item["tissue"].get<std::string>(), "", "")
                           .properties[tissue::Property::speed_of_sound]);
        return item["speed_of_sound"].get<int>();
    };
    std::set<int> speeds = {speed(layer_json["background"])};
    for (const auto& shape : layer_json["shapes"]) speeds.insert(speed(shape));
    ASSERT_EQ(speeds.size(), 2u);
    const std::string layer = why(explain(*load_scene("phantom:speed_layer", kPhantoms), p),
                                  "speed-of-sound displacement");
    for (int c : speeds)
        EXPECT_NE(layer.find(std::to_string(c) + " m/s"), std::string::npos) << layer;
}

}  // namespace
}  // namespace sonotrace::gui
