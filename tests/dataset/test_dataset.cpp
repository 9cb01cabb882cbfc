// `sonotrace dataset` (ui/dataset): the spec and its errors, frame i as a pure
// function of (spec, i) with chi-square checks of its draws, byte-identical shards on 1
// and 2 threads, a stopped run resumed to the same bytes, and shards of another spec
// refused.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

#include "tests/test_util.h"
#include "ui/dataset/dataset.h"
#include "ui/dataset/frames.h"
#include "ui/dataset/shard.h"

namespace sonotrace::dataset {
namespace {

using test::chi_square;
using test::expect_input_error;
using test::ScratchDir;

const std::string kPhantoms = SONOTRACE_SOURCE_DIR "/phantoms";

nlohmann::json small_spec() {
    return nlohmann::json::parse(R"({
      "frames": 5, "frames_per_shard": 2, "seed": 3,
      "image": {"width": 48, "height": 40},
      "sources": [{"phantom": ")" +
                                 kPhantoms + R"(/cyst_and_stone.json", "weight": 2},
                  {"phantom": ")" +
                                 kPhantoms + R"(/point_grid.json"}],
      "transducer": {"depth": [18, 24], "focus": 15, "f-number": [1.5, 2.5]},
      "gain_db": [40, 56], "pose": {"lateral_mm": 2, "rotation_deg": 4},
      "tgc": {"slope": [0.3, 0.9], "sliders": 4, "slider_db": 3}, "noise_snr_db": [10, 40],
      "tissues": {"liver": {"speed_of_sound": [1550, 1600], "backscatter": {"spread": 0.3}}},
      "quality": "interactive",
      "write": ["bmode", "labels", "envelope"]
    })");
}

// The value a frame drew for a frame-table column.
double drawn(const Spec& spec, const FrameDraw& d, const std::string& column) {
    for (const DrawnValue& v : drawn_values(spec, d))
        if (v.name == column) return v.value;
    ADD_FAILURE() << "no column " << column;
    return 0.0;
}

std::string bytes_of(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

TEST(DatasetSpec, BadSpecsNameTheFileAndField) {
    ScratchDir dir;
    const std::string file = dir / "spec.json";
    auto check = [&](const std::function<void(nlohmann::json&)>& edit, const std::string& field,
                     const std::string& text) {
        nlohmann::json j = small_spec();
        edit(j);
        std::ofstream(file) << j.dump();
        expect_input_error([&] { read_spec(file); }, "spec.json", field, text);
    };
    check([](auto& j) { j["colour"] = 1; }, "colour", "unknown key");
    // A pattern is a volume's (an image stack), never a phantom's: a fuzz input whose phantom
    // ".%3dfrniotomy" was listed as a stack.
    check([](auto& j) { j["sources"][0]["phantom"] = ".%3dfrniotomy"; }, "sources[0].phantom",
          "no such file");
    check([](auto& j) { j.erase("frames"); }, "frames", "");
    check([](auto& j) { j["frames"] = 2.5; }, "frames", "whole number");
    check(
        [](auto& j) {
            j["transducer"]["depth"] = {30, 20};
        },
        "transducer.depth", "low must not exceed high");
    check([](auto& j) { j["depth_mm"] = 30; }, "depth_mm", "is now \"transducer\"");
    check([](auto& j) { j["transducer"]["type"] = "linear"; }, "transducer.type",
          "not a numeric transducer parameter");
    check(
        [](auto& j) {
            j["transducer"]["elements"] = {64.5, 64.7};
        },
        "transducer.elements", "no whole number");
    check([](auto& j) { j["tgc"] = {{"sliders", 4}}; }, "tgc", "go together");
    check([](auto& j) { j["tgc"] = {{"slope", {0.2, 9}}}; }, "tgc.slope.high", "");
    check([](auto& j) { j["noise_snr_db"] = 500; }, "noise_snr_db", "");
    check(
        [](auto& j) {
            j["tissues"] = {{"unobtainium", {{"density", 2}}}};
        },
        "tissues.unobtainium", "");
    check(
        [](auto& j) {
            j["tissues"] = {{"liver", {{"colour", 2}}}};
        },
        "tissues.liver.colour", "unknown property");
    check(
        [](auto& j) {
            j["tissues"] = {{"liver", {{"density", {{"spread", 2}}}}}};
        },
        "tissues.liver.density.spread", "");
    check(
        [](auto& j) {
            j["tissues"] = {{"water", {{"backscatter", 0.2}}}};
        },
        "tissues.water.backscatter", "nothing to scale");
    check([](auto& j) { j["gain_db"] = {40, "a"}; }, "gain_db", "");
    check([](auto& j) { j["probes"] = {"sonar"}; }, "probes[0]", "");
    check([](auto& j) { j["write"] = {"bmode", "video"}; }, "write[1]", "must be");
    check([](auto& j) { j["sources"] = nlohmann::json::array(); }, "sources", "at least one");
    check([](auto& j) { j["sources"][1]["phantom"] = "nothing.json"; }, "sources[1].phantom",
          "no such file");
    check([](auto& j) { j["sources"][0]["scene"] = "head-craniotomy"; }, "sources[0]",
          "exactly one");
    check([](auto& j) { j["sources"][0] = {{"scene", "head-side"}}; }, "sources[0].scene", "");
    check([](auto& j) { j["disable"] = {"gravity"}; }, "disable", "");
    check([](auto& j) { j["quality"] = "best"; }, "quality",
          "unknown quality 'best' (known: interactive, standard, high)");
    check([](auto& j) { j["trace"] = "4d"; }, "trace", "2d or 3d");
    check([](auto& j) { j["pose"]["tilt_deg"] = 90; }, "pose.tilt_deg", "");
    // 100,000 frames of 1024 x 1024 a shard: 400 GB held before it is written (RSS grew
    // to 9.6 GB in 90 s before). Refused before the first frame.
    {
        nlohmann::json j = small_spec();
        j["frames"] = 100000, j["frames_per_shard"] = 100000;
        j["image"] = {{"width", 1024}, {"height", 1024}};
        RunOptions o;
        o.out_dir = dir / "never";
        expect_input_error([&] { make_dataset(parse_spec(j, "big.json"), o); }, "big.json",
                           "frames_per_shard", "");
        EXPECT_FALSE(std::filesystem::exists(dir / "never"));
    }
    // A volume's stack pattern is checked as the spec is read (it went to printf before).
    check(
        [](auto& j) {
            j["sources"][0] = {{"volume", "a%s%s%s%s.png"}, {"spacing", "1,1"}};
        },
        "sources[0].volume", "takes one index as %d");
    check(
        [](auto& j) {
            j["sources"][0] = {{"volume", "none_%03d.png"}, {"spacing", "1,1"}};
        },
        "sources[0].volume", "no file matches");
}

TEST(DatasetSpec, AFocusBeyondADepthTheSpecAllowsIsRefusedBeforeAnyFrame) {
    nlohmann::json j = small_spec();
    j["transducer"].erase("focus");  // the linear preset's 20 mm focus, beyond the 18 mm depth
    expect_input_error([&] { FrameMaker maker(parse_spec(j, "spec.json")); }, "spec.json", "focus",
                       "depth 18");
}

TEST(DatasetSpec, AFramesDrawsDependOnlyOnTheSeedAndItsIndex) {
    Spec spec = parse_spec(small_spec(), "spec");
    Spec larger = spec;
    larger.frames = 1000;
    larger.frames_per_shard = 7;
    for (uint64_t i = 0; i < 5; ++i) {
        const FrameDraw a = draw_frame(spec, i), b = draw_frame(larger, i);
        EXPECT_EQ(a.seed, b.seed);
        EXPECT_EQ(a.source, b.source);
        EXPECT_EQ(a.transducer, b.transducer);
        EXPECT_EQ(a.gain_db, b.gain_db);
        EXPECT_EQ(a.lateral_mm, b.lateral_mm);
    }
    // Different frames, different seeds.
    EXPECT_NE(draw_frame(spec, 0).seed, draw_frame(spec, 1).seed);
}

TEST(DatasetSpec, SourcesFollowTheirWeightsAndRangesAreUniform) {
    // 6000 frames: the sources' counts against the weights 2:1 (1 dof, p = 0.001 critical
    // value 10.83) and the depths against 10 equal bins of [18, 24] (9 dof: 27.88).
    Spec spec = parse_spec(small_spec(), "spec");
    const int n = 6000, bins = 10;
    std::vector<int> sources(2, 0), depths(bins, 0);
    for (int i = 0; i < n; ++i) {
        const FrameDraw d = draw_frame(spec, uint64_t(i));
        ++sources[std::size_t(d.source)];
        const double depth = drawn(spec, d, "transducer.depth");
        ASSERT_GE(depth, 18.0);
        ASSERT_LT(depth, 24.0);
        ++depths[std::min(bins - 1, int((depth - 18.0) / 6.0 * bins))];
        ASSERT_LE(std::abs(d.lateral_mm), 2.0);
        ASSERT_LE(std::abs(d.rotation_deg), 4.0);
    }
    EXPECT_LT(chi_square(sources, {2.0 / 3.0, 1.0 / 3.0}, n), 10.83);
    EXPECT_LT(chi_square(depths, std::vector<double>(bins, 1.0 / bins), n), 27.88);
}

// Domain randomisation: every drawn value is a column (the same columns for every frame),
// each is uniform over its range (chi-square, 10 bins, 9 dof: p = 0.001 critical value
// 27.88; the whole-number one over its 8 values, 7 dof: 24.32), and two of them are
// independent (a 4 x 4 table, 15 dof: 37.70). 8,000 frames with a fixed seed; at
// p = 0.001 for each of the 9 statistics a sound sampler fails one with probability 0.9 %.
TEST(DatasetSpec, RandomisedValuesAreRecordedUniformAndIndependent) {
    nlohmann::json j = small_spec();
    j["transducer"]["elements"] = {60, 67};
    j["tissues"]["brain"] = {{"attenuation", {{"spread", 0.2}}}};
    const Spec spec = parse_spec(j, "spec");
    const std::vector<std::string> columns = {"transducer.depth",
                                              "transducer.elements",
                                              "transducer.f-number",
                                              "transducer.focus",
                                              "tgc.slope",
                                              "tgc.slider0",
                                              "tgc.slider1",
                                              "tgc.slider2",
                                              "tgc.slider3",
                                              "noise_snr_db",
                                              "tissues.brain.attenuation",
                                              "tissues.liver.backscatter",
                                              "tissues.liver.speed_of_sound"};
    // Expected range of each: the spec's, or the tissue table's value x (1 +- spread).
    const std::map<std::string, std::pair<double, double>> ranges = {
        {"transducer.depth", {18, 24}},
        {"transducer.f-number", {1.5, 2.5}},
        {"tgc.slope", {0.3, 0.9}},
        {"tgc.slider0", {-3, 3}},
        {"tgc.slider3", {-3, 3}},
        {"noise_snr_db", {10, 40}},
        {"tissues.brain.attenuation", {0.48, 0.72}},  // 0.6 dB/(cm MHz) +-20 %
        {"tissues.liver.backscatter", {0.35, 0.65}},  // 0.5 +-30 %
        {"tissues.liver.speed_of_sound", {1550, 1600}}};
    const int n = 8000, bins = 10;
    std::map<std::string, std::vector<int>> counts;
    std::vector<int> elements(8, 0), pair(16, 0);
    for (int i = 0; i < n; ++i) {
        const FrameDraw d = draw_frame(spec, uint64_t(i));
        const std::vector<DrawnValue> values = drawn_values(spec, d);
        ASSERT_EQ(values.size(), columns.size());
        std::map<std::string, double> row;
        for (std::size_t k = 0; k < values.size(); ++k) {
            ASSERT_EQ(values[k].name, columns[k]);
            row[values[k].name] = values[k].value;
        }
        EXPECT_EQ(row["transducer.focus"], 15.0);
        const double e = row["transducer.elements"];
        ASSERT_TRUE(e == std::floor(e) && e >= 60 && e <= 67) << e;
        ++elements[std::size_t(e - 60)];
        for (const auto& [name, range] : ranges) {
            const double u = (row[name] - range.first) / (range.second - range.first);
            ASSERT_TRUE(u >= 0.0 && u < 1.0 + 1e-12) << name << " " << row[name];
            auto& c = counts[name];
            c.resize(bins);
            ++c[std::size_t(std::min(bins - 1, int(u * bins)))];
        }
        auto quarter = [&](const std::string& name) {
            const auto& r = ranges.at(name);
            return std::min(3, int((row[name] - r.first) / (r.second - r.first) * 4));
        };
        ++pair[std::size_t(4 * quarter("transducer.f-number") + quarter("noise_snr_db"))];
        // The factor the maps get is the recorded value over the table's.
        for (std::size_t k = 0; k < spec.tissues.size(); ++k)
            EXPECT_NEAR(d.tissue_scales[k].factor * spec.tissues[k].table_value, d.tissue_values[k],
                        1e-9 * d.tissue_values[k]);
    }
    for (const auto& [name, c] : counts)
        EXPECT_LT(chi_square(c, std::vector<double>(bins, 1.0 / bins), n), 27.88) << name;
    EXPECT_LT(chi_square(elements, std::vector<double>(8, 1.0 / 8), n), 24.32);
    EXPECT_LT(chi_square(pair, std::vector<double>(16, 1.0 / 16), n), 37.70);
}

// The TGC text a frame gets: 2 x slope x f x depth plus each slider at its depth.
TEST(DatasetSpec, ADrawnTgcCurveIsTheSlopeAndTheSlidersAtEvenDepths) {
    FrameDraw d;
    d.tgc_slope = 0.5;
    d.tgc_sliders_db = {1.0, -2.0, 0.5};
    probe::Transducer t;
    t.frequency_mhz = 4.0, t.depth_mm = 60.0;
    // 2 x 0.5 x 4 MHz x d / 10 = 0.4 dB/mm: 0, 12 and 24 dB at 0, 30 and 60 mm.
    EXPECT_EQ(tgc_curve(d, t), "0:1,30:10,60:24.5");
    d.tgc_sliders_db.clear();
    EXPECT_EQ(tgc_curve(d, t), "0:0,60:24");
    EXPECT_EQ(tgc_curve(FrameDraw{}, t), "auto");
}

// A drawn backscatter scales the tissue's echoes: the scatterers are lit by the map's
// backscatter squared in intensity (imaging/bmode.h), so liver at 0.25 instead of the
// table's 0.5 is 20 log10(0.25 / 0.5) = -6.02 dB in the envelope's mean power over the
// liver above the cyst. The same frame seed draws the same speckle: within 0.1 dB.
TEST(Dataset, ADrawnBackscatterScalesTheTissuesEchoLevel) {
    auto liver_power_db = [](const std::optional<double>& backscatter) {
        nlohmann::json j = small_spec();
        j.erase("tissues");
        j.erase("noise_snr_db");
        j["pose"] = nlohmann::json::object();
        j["write"] = {"envelope"};
        if (backscatter) j["tissues"] = {{"liver", {{"backscatter", *backscatter}}}};
        const FrameMaker maker(parse_spec(j, "spec"));
        const DatasetFrame f = maker.make(0);
        double sum = 0.0;
        int count = 0;
        for (int l = 0; l < f.envelope.lines; ++l)
            for (int i = 0; i < f.envelope.samples; ++i)
                if (f.envelope.depth_mm(i) > 4.0 && f.envelope.depth_mm(i) < 13.0) {
                    sum += double(f.envelope.at(l, i)) * f.envelope.at(l, i);
                    ++count;
                }
        return 10.0 * std::log10(sum / count);
    };
    EXPECT_NEAR(liver_power_db(0.25) - liver_power_db(std::nullopt), 20.0 * std::log10(0.5), 0.1);
}

TEST(Dataset, ShardsAreByteIdenticalOnOneAndTwoThreadsAndResumeToTheSameBytes) {
    ScratchDir dir;
    const Spec spec = parse_spec(small_spec(), "spec");
    ASSERT_EQ(spec.shards(), 3u);  // 2 + 2 + 1 frames
    auto run = [&](const std::string& out, int threads, std::function<bool()> stop = {}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                                  std::size_t(threads));
        RunOptions o;
        o.out_dir = out;
        o.stop = std::move(stop);
        return make_dataset(spec, o);
    };
    const RunReport one = run(dir / "one", 1);
    EXPECT_EQ(one.shards_written, 3u);
    run(dir / "two", 2);
    // Stopped after the third frame (its shard, the second, abandoned), then resumed.
    int polls = 0;
    const RunReport stopped = run(dir / "resumed", 2, [&] { return ++polls > 3; });
    EXPECT_TRUE(stopped.stopped);
    EXPECT_EQ(stopped.shards_written, 1u);
    EXPECT_TRUE(std::filesystem::exists(shard_path(dir / "resumed", 0)));
    EXPECT_FALSE(std::filesystem::exists(shard_path(dir / "resumed", 1)));
    EXPECT_FALSE(std::filesystem::exists(dir / "resumed/manifest.json"));
    const RunReport resumed = run(dir / "resumed", 2);
    EXPECT_EQ(resumed.shards_kept, 1u);
    EXPECT_EQ(resumed.shards_written, 2u);
    for (const char* file :
         {"shard_00000.h5", "shard_00001.h5", "shard_00002.h5", "manifest.json"}) {
        const std::string reference = bytes_of(dir / (std::string("one/") + file));
        ASSERT_FALSE(reference.empty()) << file;
        EXPECT_TRUE(bytes_of(dir / (std::string("two/") + file)) == reference) << file;
        EXPECT_TRUE(bytes_of(dir / (std::string("resumed/") + file)) == reference) << file;
    }
    // Nothing else in the directory: no temporaries left by the stopped run.
    int entries = 0;
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir / "resumed"))
        ++entries;
    EXPECT_EQ(entries, 4);

    // Frames made alone, out of order, are the run's: shard 1 (frames 2 and 3) again.
    const FrameMaker maker(spec);
    const DatasetFrame third = maker.make(3), second = maker.make(2);
    write_shard(dir / "alone.h5", "alone.h5", spec, 1, {second, third});
    EXPECT_TRUE(bytes_of(dir / "alone.h5") == bytes_of(shard_path(dir / "one", 1)));

    // The same spec with whole numbers written as 8.0 is the same spec.
    nlohmann::json as_floats = small_spec();
    as_floats["frames"] = 5.0, as_floats["transducer"]["depth"] = {18.0, 24.0};
    EXPECT_EQ(parse_spec(as_floats, "floats").digest(), spec.digest());

    // Another spec into the same directory is refused, naming the shard.
    nlohmann::json changed = small_spec();
    changed["seed"] = 4;
    const Spec other = parse_spec(changed, "other");
    RunOptions o;
    o.out_dir = dir / "one";
    expect_input_error([&] { make_dataset(other, o); }, "shard_00000.h5", "spec_digest",
                       "not a shard of this spec");
}

// A shard is kept only if its header and checksum agree with the spec and its number.
// Before, only the spec digest was read: a shard with 8 flipped bytes was kept (h5py then
// failed with "inflate() failed"), a copy of shard 0 named shard 1 was kept as shard 1, and
// a truncated or empty shard of this very spec was reported as another spec's.
TEST(Dataset, DamagedOrMisnumberedShardsAreMadeAgainNeverKept) {
    ScratchDir dir;
    const Spec spec = parse_spec(small_spec(), "spec");
    RunOptions o;
    o.out_dir = dir / "out";
    make_dataset(spec, o);
    std::vector<std::string> sound;
    for (uint64_t k = 0; k < spec.shards(); ++k)
        sound.push_back(bytes_of(shard_path(o.out_dir, k)));
    auto overwrite = [&](uint64_t k, const std::string& bytes) {
        std::ofstream(shard_path(o.out_dir, k), std::ios::binary | std::ios::trunc) << bytes;
    };
    auto expect_made_again = [&](const std::string& why) {
        const RunReport report = make_dataset(spec, o);
        ASSERT_EQ(report.damaged.size(), 1u) << why;
        EXPECT_NE(report.damaged[0].find(why), std::string::npos) << report.damaged[0];
        EXPECT_EQ(report.shards_written, 1u) << why;
        for (uint64_t k = 0; k < spec.shards(); ++k)
            EXPECT_TRUE(bytes_of(shard_path(o.out_dir, k)) == sound[k]) << why << " shard " << k;
    };
    std::string flipped = sound[1];
    for (std::size_t b = flipped.size() / 2; b < flipped.size() / 2 + 8; ++b) flipped[b] ^= 0x5a;
    overwrite(1, flipped);
    expect_made_again("does not match its checksum");
    overwrite(1, sound[0]);  // shard 0, renamed to shard 1
    expect_made_again("holds shard 0, not shard 1");
    overwrite(2, sound[2].substr(0, sound[2].size() - 100));
    expect_made_again("does not match its checksum");
    overwrite(2, "");
    expect_made_again("shorter than its header");
    std::string header = sound[0];
    header[5] ^= 1;  // "sonotrace shard" no longer
    overwrite(0, header);
    expect_made_again("its header is damaged or missing");
    header = sound[0];
    header[300] = 'x';  // in the header's zero padding
    overwrite(0, header);
    expect_made_again("its header is damaged or missing");
}

// `sonotrace dataset --verify DIR`: the manifest lists each shard's checksum (the one in
// the shard's header, which covers its content), and the verification reads every shard
// back: a flipped byte, a missing shard, a shard swapped for another and a checksum edited
// in the manifest are each named; a malformed manifest is an InputError naming the field,
// and a manifest naming a file outside the dataset is refused before anything is read.
TEST(Dataset, VerifyNamesEveryDamagedMissingOrSwappedShard) {
    ScratchDir dir;
    const Spec spec = parse_spec(small_spec(), "spec");
    RunOptions o;
    o.out_dir = dir / "out";
    make_dataset(spec, o);
    const std::string manifest_path = dir / "out/manifest.json";
    const nlohmann::json manifest = nlohmann::json::parse(bytes_of(manifest_path));
    ASSERT_EQ(manifest["content_checksums"].size(), spec.shards());
    for (uint64_t k = 0; k < spec.shards(); ++k) {
        const std::string bytes = bytes_of(shard_path(o.out_dir, k));
        char hex[17];
        std::snprintf(hex, sizeof hex, "%016llx",
                      static_cast<unsigned long long>(content_checksum(bytes)));
        EXPECT_EQ(manifest["content_checksums"][shard_path("", k)], hex) << k;
    }
    EXPECT_TRUE(verify_dataset(o.out_dir, {}).problems.empty());

    const std::string shard0 = bytes_of(shard_path(o.out_dir, 0));
    std::string flipped = bytes_of(shard_path(o.out_dir, 1));
    flipped[flipped.size() / 2] ^= 0x01;
    std::ofstream(shard_path(o.out_dir, 1), std::ios::binary | std::ios::trunc) << flipped;
    std::filesystem::remove(shard_path(o.out_dir, 2));
    VerifyReport report = verify_dataset(o.out_dir, {});
    EXPECT_EQ(report.shards, spec.shards());
    ASSERT_EQ(report.problems.size(), 2u);
    EXPECT_NE(report.problems[0].find("shard_00001.h5: its content does not match"),
              std::string::npos)
        << report.problems[0];
    EXPECT_NE(report.problems[1].find("shard_00002.h5"), std::string::npos);
    EXPECT_NE(report.problems[1].find("file not found"), std::string::npos);

    make_dataset(spec, o);  // the run remakes them
    EXPECT_TRUE(verify_dataset(o.out_dir, {}).problems.empty());
    std::ofstream(shard_path(o.out_dir, 1), std::ios::binary | std::ios::trunc) << shard0;
    report = verify_dataset(o.out_dir, {});
    ASSERT_EQ(report.problems.size(), 1u);
    EXPECT_NE(report.problems[0].find("holds shard 0, not shard 1"), std::string::npos);
    make_dataset(spec, o);

    // A sound shard whose checksum the manifest does not list.
    nlohmann::json edited = manifest;
    edited["content_checksums"]["shard_00000.h5"] = "0123456789abcdef";
    std::ofstream(manifest_path, std::ios::trunc) << edited.dump();
    report = verify_dataset(o.out_dir, {});
    ASSERT_EQ(report.problems.size(), 1u);
    EXPECT_NE(report.problems[0].find("not the manifest's"), std::string::npos);

    auto expect_refused = [&](const std::function<void(nlohmann::json&)>& edit,
                              const std::string& field, const std::string& text) {
        nlohmann::json j = manifest;
        edit(j);
        std::ofstream(manifest_path, std::ios::trunc) << j.dump();
        expect_input_error([&] { verify_dataset(o.out_dir, {}); }, "manifest.json", field, text);
    };
    expect_refused([](auto& j) { j.erase("content_checksums"); }, "content_checksums", "missing");
    expect_refused([](auto& j) { j["spec_digest"] = "xyz"; }, "spec_digest", "hex digits");
    expect_refused([](auto& j) { j["shards"][0] = "../../etc/passwd"; }, "shards[0]",
                   "is not \"shard_00000.h5\"");
    expect_refused([](auto& j) { j["content_checksums"].erase("shard_00002.h5"); },
                   "content_checksums.shard_00002.h5", "missing");
    std::filesystem::remove(manifest_path);
    expect_input_error([&] { verify_dataset(o.out_dir, {}); }, "manifest.json", "",
                       "not a finished dataset");
}

// A dataset's identity is the content its spec names, not the spec's text alone (issue
// 50, item 9): two of three shards made, then a phantom the spec names edited (a radius
// 5 -> 9), the next run refuses the old shards (exit 1 from the CLI) instead of mixing
// frames of two phantoms into one dataset; the same phantom restored, the run resumes
// them. A phantom copied byte for byte under another name keeps the identity only if its
// spec names the same path (the path is part of the spec).
TEST(Dataset, ShardsOfAnEditedPhantomAreRefusedNotMixed) {
    ScratchDir dir;
    const std::string phantom = dir / "cysts.json";
    const std::string original = bytes_of(kPhantoms + "/cyst_and_stone.json");
    std::ofstream(phantom, std::ios::binary) << original;
    nlohmann::json j = small_spec();
    j["sources"] = {{{"phantom", phantom}}};
    const Spec spec = parse_spec(j, "spec");
    RunOptions o;
    o.out_dir = dir / "out";
    make_dataset(spec, o);
    std::filesystem::remove(shard_path(o.out_dir, 2));
    std::string edited = original;
    const std::size_t at = edited.find("\"radius\": 5");
    ASSERT_NE(at, std::string::npos) << "the catalogue phantom changed: pick another edit";
    edited.replace(at, 12, "\"radius\": 9");
    std::ofstream(phantom, std::ios::binary | std::ios::trunc) << edited;
    const Spec changed = parse_spec(j, "spec");
    EXPECT_NE(changed.digest(), spec.digest());
    expect_input_error([&] { make_dataset(changed, o); }, "shard_00000", "spec_digest",
                       "is not a shard of this spec");
    std::ofstream(phantom, std::ios::binary | std::ios::trunc) << original;
    const RunReport resumed = make_dataset(parse_spec(j, "spec"), o);
    EXPECT_EQ(resumed.shards_written, 1u);
}

}  // namespace
}  // namespace sonotrace::dataset
