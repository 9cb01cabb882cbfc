// The frame request (phantoms/scene/request.h): its table, how text sets it, and the
// settings it makes. The expected settings are written here from the parameters' meaning
// (the preset's values, the scene's gain), not read from an earlier run.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <set>

#include "phantoms/scene/request.h"
#include "probe/transducer.h"
#include "tests/test_util.h"
#include "tissue/base/error.h"
#include "tissue/base/number_list.h"

namespace sonotrace::scene {
namespace {

const std::string kCyst = SONOTRACE_SOURCE_DIR "/phantoms/cyst_and_stone.json";

TEST(FrameRequest, EveryKeyIsOneParameterAndNoneIsATransducersToo) {
    std::set<std::string> keys;
    for (const RequestParameter& p : request_parameters()) {
        EXPECT_TRUE(keys.insert(p.key).second) << p.key << " twice";
        EXPECT_FALSE(p.description.empty()) << p.key;
        EXPECT_EQ(&request_parameter(p.key), &p);
    }
    for (const auto& doc : probe::transducer_parameter_docs())
        EXPECT_FALSE(keys.count(doc.key)) << doc.key << " is the transducer's and the frame's";
    // Two rows may not write one member: setting each row's key changes only its own
    // member, seen through the row's own pointer, and no other row reads a change.
    for (const RequestParameter& p : request_parameters()) {
        FrameRequest r;
        std::visit(
            [&](auto member) {
                using V = std::decay_t<decltype(r.*member)>;
                const std::string text = std::is_same_v<V, bool>          ? "true"
                                         : std::is_same_v<V, std::string> ? "x-" + p.key
                                                                          : "7";
                set_request_parameter(r, p.key, text, "test");
            },
            p.member);
        const FrameRequest defaults;
        for (const RequestParameter& q : request_parameters()) {
            const bool changed = std::visit(
                [&](auto member) {
                    if constexpr (std::is_same_v<decltype(member), double FrameRequest::*>)
                        if (std::isnan(r.*member) && std::isnan(defaults.*member))
                            return false;  // --outside's "unset"
                    return !(r.*member == defaults.*member);
                },
                q.member);
            EXPECT_EQ(changed, &q == &p) << "setting " << p.key << " and reading " << q.key;
        }
    }
}

TEST(FrameRequest, TextIsCheckedAsTheCommandLineChecksIt) {
    FrameRequest r;
    set_request_parameter(r, "dynamic_range", "45.5", "py");  // '_' for '-'
    EXPECT_EQ(r.dynamic_range_db, 45.5);
    set_request_parameter(r, "gain", "12", "py");
    EXPECT_EQ(r.gain_db, 12.0);
    set_request_parameter(r, "seed", "18446744073709551615", "py");
    EXPECT_EQ(r.seed, 18446744073709551615u);
    set_request_parameter(r, "depth", "30", "py");
    EXPECT_EQ(r.transducer.at("depth"), "30");
    set_request_parameter(r, "labels", "true", "py");
    EXPECT_TRUE(r.labels);
    EXPECT_NE(test::input_error_message([&] {
                  set_request_parameter(r, "colour", "3", "py");
              }).find("field 'colour': unknown parameter; known: view, volume"),
              std::string::npos);
    EXPECT_NE(test::input_error_message([&] {
                  set_request_parameter(r, "gain", "nan", "py");
              }).find("field 'gain': value nan is not a finite number"),
              std::string::npos);
    EXPECT_NE(test::input_error_message([&] {
                  set_request_parameter(r, "depth", "inf", "py");
              }).find("depth"),
              std::string::npos);
    for (const char* seed : {"-1", "18446744073709551616", "1e23", ""})
        EXPECT_NE(test::input_error_message([&] {
                      set_request_parameter(r, "seed", seed, "py");
                  }).find("not a whole number"),
                  std::string::npos)
            << seed;
    EXPECT_NE(test::input_error_message([&] {
                  set_request_parameter(r, "lines", "2.5", "py");
              }).find("not a whole number"),
              std::string::npos);
    EXPECT_NE(test::input_error_message([&] {
                  set_request_parameter(r, "labels", "yes", "py");
              }).find("field 'labels': is a flag"),
              std::string::npos);
    EXPECT_EQ(request_parameter_kind("labels"), ParameterKind::flag);
    EXPECT_EQ(request_parameter_kind("dynamic_range"), ParameterKind::value);
    EXPECT_EQ(request_parameter_kind("focus"), ParameterKind::value);
    EXPECT_EQ(request_parameter_kind("colour"), ParameterKind::unknown);
}

TEST(FrameRequest, MakesThePresetsSettingsWithTheScenesGainUnlessItIsGiven) {
    FrameRequest r;
    r.phantom = kCyst;
    r.quality = "interactive";
    const FrameSetup setup = prepare_frames(r);
    const probe::Transducer& preset = probe::find_transducer(setup.scene->probe_preset, "test");
    EXPECT_EQ(setup.settings.transducer.depth_mm, preset.depth_mm);
    EXPECT_EQ(setup.settings.imaging.gain_db, setup.scene->gain_db);
    EXPECT_EQ(setup.settings.quality, imaging::Quality::interactive);
    ASSERT_EQ(setup.placements.size(), 1u);

    r.gain_db = 20.0;
    r.transducer["depth"] = "30";
    r.disable = "refraction,speckle";
    r.tgc = "none";
    const imaging::SimulationSettings s = make_settings(r, *setup.scene);
    EXPECT_EQ(s.imaging.gain_db, 20.0);
    EXPECT_EQ(s.transducer.depth_mm, 30.0);
    EXPECT_FALSE(s.trace.physics.on(simulator::Physics::refraction));
    EXPECT_FALSE(s.imaging.speckle);
    EXPECT_TRUE(s.imaging.tgc.empty());

    // Ranges come from the settings' own (one place), and name the request's source.
    r.dynamic_range_db = 0.5;
    EXPECT_NE(test::input_error_message([&] {
                  make_settings(r, *setup.scene, "spec.json (frame 3)");
              }).find("spec.json (frame 3): field 'dynamic-range': must be in [1, 200]"),
              std::string::npos);
    r.dynamic_range_db = 60.0;
    r.quality = "ultra";
    EXPECT_NE(test::input_error_message([&] { make_settings(r, *setup.scene); }).find("quality"),
              std::string::npos);
}

// Each switch is one row: its name switches off that row alone, names and record keys are
// each one switch's, and the names of what is off read back to the same set.
TEST(PhysicsSwitches, EachNameSwitchesOffItsOwnRowAndReadsBack) {
    std::set<std::string_view> names, keys;
    for (const simulator::PhysicsSwitch& sw : simulator::kPhysicsSwitches) {
        EXPECT_TRUE(names.insert(sw.name).second) << sw.name;
        EXPECT_TRUE(keys.insert(sw.record_key).second) << sw.record_key;
        EXPECT_FALSE(sw.description.empty() || sw.label.empty()) << sw.name;
        const imaging::PhysicsSwitches off =
            imaging::disabled_physics(std::string(sw.name), "test", "");
        for (const simulator::PhysicsSwitch& other : simulator::kPhysicsSwitches)
            EXPECT_EQ(off.on(other.id), &other != &sw) << sw.name << " / " << other.name;
        EXPECT_EQ(imaging::disabled_names(off), sw.name);
    }
    const imaging::PhysicsSwitches two = imaging::disabled_physics("speckle,refraction", "t", "");
    EXPECT_EQ(imaging::disabled_names(two), "refraction,speckle");  // the table's order
    EXPECT_EQ(imaging::disabled_physics(imaging::disabled_names(two), "t", ""), two);
    // Applied to a frame's settings: the tracer's set is the request's, the image's speckle
    // follows its row.
    imaging::SimulationSettings settings;
    imaging::apply(two, settings);
    EXPECT_EQ(settings.trace.physics, two);
    EXPECT_FALSE(settings.imaging.speckle);
}

// The GUI and the dataset hand computed numbers on as text: the text must read back to
// the same double, bit for bit, or their frames would differ from the settings they meant.
TEST(FrameRequest, ExactNumberTextReadsBackToTheSameBits) {
    std::mt19937_64 bits(20261128);
    for (int i = 0; i < 200000; ++i) {
        uint64_t pattern = bits();
        double v;
        std::memcpy(&v, &pattern, sizeof v);
        if (!std::isfinite(v)) continue;
        const std::string text = base::exact_number_text(v);
        const double back = std::strtod(text.c_str(), nullptr);
        ASSERT_EQ(std::memcmp(&back, &v, sizeof v), 0) << text;
    }
    // And every preset's parameters, written as text into another preset and read back
    // through the table, give the preset.
    const auto& presets = probe::transducer_presets();
    for (std::size_t n = 0; n < presets.size(); ++n) {
        const probe::Transducer& preset = presets[n];
        probe::Transducer other = presets[(n + 1) % presets.size()];
        for (const auto& doc : probe::transducer_parameter_docs())
            doc.set(other, probe::parameter_text(doc.get(preset)), "test");
        for (const auto& doc : probe::transducer_parameter_docs())
            EXPECT_EQ(doc.get(other), doc.get(preset)) << preset.name << " " << doc.key;
    }
}

}  // namespace
}  // namespace sonotrace::scene
