// Fault injection end to end, without privileges:
//  - a full disk: a file-size limit (ulimit -f with SIGXFSZ ignored) makes every write past
//    a few kilobytes fail with EFBIG, as a full file system fails them with ENOSPC;
//  - a killed run: SIGKILL part-way through a sweep;
// and what must follow: exit 1 naming the output, no partial or hidden file left, and the
// next run into the same directory cleaning up after the killed one. (A rename that fails
// part-way: CliTrace.CollidingOrBlockedOutputsLeaveNothing.)
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>
#include <opencv2/videoio.hpp>

#include "tests/test_util.h"

namespace sonotrace {
namespace {

using test::files_in;
using test::ScratchDir;
using test::slurp;

// Runs `args` under a file-size limit of 8 blocks (4 KiB in sh's 512-byte units, 8 KiB in
// bash's), SIGXFSZ ignored so that writes fail instead of killing the process.
test::RunResult run_with_small_disk(const ScratchDir& dir, const std::string& args,
                                    int blocks = 8) {
    const std::string cmd = "sh -c \"trap '' XFSZ; ulimit -f " + std::to_string(blocks) +
                            "; exec " + std::string(SONOTRACE_BINARY) + " " + args + "\" > " +
                            (dir / "stdout.txt") + " 2> " + (dir / "stderr.txt");
    const int status = std::system(cmd.c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(dir / "stdout.txt"),
            slurp(dir / "stderr.txt")};
}

TEST(CliFaults, AFullDiskIsAnErrorAndLeavesNothing) {
    ScratchDir dir;
    const std::string phantom = std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/cyst_and_stone.json";
    const std::pair<std::string, std::string> commands[] = {
        // arguments, output directory
        {"simulate -q --quality interactive --phantom " + phantom + " --out " + (dir / "simulate"),
         dir / "simulate"},
        {"trace -q --config fig2 --out " + (dir / "trace"), dir / "trace"},
        {"tissue -q --out " + (dir / "tissue"), dir / "tissue"},
        // The render and its reference: a PNG each, written only if both fit.
        {"render -q --width 160 --height 128 --repetitions 2 --reference " +
             (dir / "render/reference.png") + " --out " + (dir / "render/render.png"),
         dir / "render"},
    };
    for (const auto& [args, out] : commands) {
        const auto r = run_with_small_disk(dir, args);
        EXPECT_EQ(r.exit_code, 1) << args << ": " << r.err;
        EXPECT_NE(r.err.find("File too large"), std::string::npos) << args << ": " << r.err;
        EXPECT_EQ(r.err.find(".partial-"), std::string::npos) << "a hidden name: " << r.err;
        EXPECT_TRUE(files_in(out).empty()) << args;
    }
    // Room for each frame (28 kB) but not for the sweep's video (80 kB): OpenCV reports no
    // write error, the read-back does. The frames committed so far stay, complete.
    const std::string out = dir / "video";
    const auto r = run_with_small_disk(dir,
                                       "simulate -q --quality interactive --phantom " + phantom +
                                           " --sweep lateral:20:0.5 --out " + out,
                                       100);
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("bmode.mp4: the video could not be written completely"), std::string::npos)
        << r.err;
    for (const std::string& name : files_in(out))
        EXPECT_NE(name.find(".png"), std::string::npos) << "left behind: " << name;
}

// A dataset's shards on a full disk. HDF5 used to write the file itself: its close failed,
// and its exit handler then crashed (SIGSEGV) closing the file again. Shards are built in
// memory and written by our checked writer now. A FIFO where a shard is expected blocked
// the next run in open() for ever; it is refused as not a regular file.
TEST(CliFaults, ADatasetOnAFullDiskOrBesideAFifoIsAnErrorNamingTheShard) {
    ScratchDir dir;
    const std::string spec = dir / "spec.json";
    std::ofstream(spec) << R"({"frames": 3, "frames_per_shard": 2, "seed": 5,
        "image": {"width": 48, "height": 40}, "quality": "interactive", "transducer": {"focus": 15},
        "sources": [{"phantom": ")"
                        << SONOTRACE_SOURCE_DIR << R"(/phantoms/cyst_and_stone.json"}]})";
    const std::string out = dir / "out";
    auto r = run_with_small_disk(dir, "dataset -q " + spec + " --out " + out);
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("shard_00000.h5: cannot write the file: File too large"),
              std::string::npos)
        << r.err;
    EXPECT_TRUE(files_in(out).empty());

    ASSERT_EQ(::mkfifo((dir / "out/shard_00001.h5").c_str(), 0600), 0);
    const auto start = std::chrono::steady_clock::now();
    r = test::run(dir, "dataset -q " + spec + " --out " + out);
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("shard_00001.h5: is not a regular file"), std::string::npos) << r.err;
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(60));
}

TEST(CliFaults, AKilledSweepLeavesCompleteFramesAndTheNextRunCleansUp) {
    ScratchDir dir;
    const std::string phantom = std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/cyst_and_stone.json";
    const std::string sweep = std::string(SONOTRACE_BINARY) +
                              " simulate -q --quality interactive --phantom " + phantom +
                              " --sweep lateral:20:0.5 --out " + (dir / "sweep");
    // SIGKILL once two frames are under their names (or after 60 s): the run cannot clean
    // up after itself.
    const std::string out = dir / "sweep";
    const std::string killed = "(" + sweep + " 2> /dev/null & pid=$!; i=0; while [ $(ls " + out +
                               " 2> /dev/null | grep -c png) -lt 2 ] && [ $i -lt 600 ]; do " +
                               "sleep 0.1; i=$((i+1)); done; kill -9 $pid; wait $pid)";
    const int status = std::system(("sh -c '" + killed + "'").c_str());
    ASSERT_TRUE(WIFEXITED(status));
    ASSERT_EQ(WEXITSTATUS(status), 128 + 9) << "the sweep finished before the kill";
    // Under final names only complete frames: a staged file is renamed only once written.
    int frames = 0, partials = 0;
    for (const auto& e : std::filesystem::directory_iterator(dir / "sweep")) {
        const std::string name = e.path().filename().string();
        if (name.rfind(".partial-", 0) == 0) {
            ++partials;
            continue;
        }
        if (e.path().extension() == ".png") {
            ++frames;
            const auto r = test::run(dir, "tissue -q --volume " + e.path().string() +
                                              " --spacing 0.1,0.1 --out " + (dir / "check"));
            EXPECT_EQ(r.exit_code, 0) << name << " does not decode: " << r.err;
        }
    }
    EXPECT_GE(frames, 2) << "each frame is committed when written";
    // The next run into the directory removes the killed run's temporaries.
    const auto r = test::run(dir, "simulate -q --quality interactive --phantom " + phantom +
                                      " --out " + (dir / "sweep"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const auto& e : std::filesystem::directory_iterator(dir / "sweep"))
        EXPECT_NE(e.path().filename().string().rfind(".partial-", 0), 0u)
            << "left behind: " << e.path();
    RecordProperty("frames_before_the_kill", frames);
    RecordProperty("temporaries_left_by_the_kill", partials);
}

// SIGINT (and SIGTERM) finish the frame in flight, write a valid video of the frames so far
// and the record, and exit 130.
TEST(CliFaults, AnInterruptedSweepWritesTheFramesSoFarAndAValidVideo) {
    ScratchDir dir;
    const std::string phantom = std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/cyst_and_stone.json";
    for (const char* signal_name : {"INT", "TERM"}) {
        const std::string out = dir / (std::string("sweep_") + signal_name);
        const std::string sweep = std::string(SONOTRACE_BINARY) +
                                  " simulate -q --quality interactive --phantom " + phantom +
                                  " --sweep lateral:20:0.5 --out " + out;
        const std::string interrupted =
            "(" + sweep + " 2> /dev/null & pid=$!; i=0; while [ $(ls " + out +
            " 2> /dev/null | grep -c png) -lt 2 ] && [ $i -lt 600 ]; do sleep 0.1; i=$((i+1)); " +
            "done; kill -" + signal_name + " $pid; wait $pid)";
        const int status = std::system(("sh -c '" + interrupted + "'").c_str());
        ASSERT_TRUE(WIFEXITED(status));
        EXPECT_EQ(WEXITSTATUS(status), 130) << signal_name;
        const auto record = nlohmann::json::parse(slurp(out + "/bmode.json"));
        const auto& sweep_record = record.at("sweep");
        EXPECT_TRUE(sweep_record.at("interrupted").get<bool>()) << signal_name;
        const int frames = int(sweep_record.at("frames").size());
        EXPECT_GE(frames, 2) << signal_name;
        EXPECT_LT(frames, sweep_record.at("frames_planned").get<int>()) << signal_name;
        int pngs = 0;
        for (const auto& e : std::filesystem::directory_iterator(out)) {
            EXPECT_NE(e.path().filename().string().rfind(".partial-", 0), 0u) << e.path();
            pngs += e.path().extension() == ".png";
        }
        EXPECT_EQ(pngs, frames) << signal_name;
        cv::VideoCapture video(out + "/bmode.mp4");
        ASSERT_TRUE(video.isOpened()) << signal_name << ": the video does not open";
        int decoded = 0;
        for (cv::Mat image; video.read(image);) ++decoded;
        EXPECT_EQ(decoded, frames) << signal_name;
    }
}

// --resume after an interrupt gives what an uninterrupted sweep gives, byte for byte:
// every frame and the video (rebuilt from the kept png8 frames).
TEST(CliFaults, AResumedSweepIsByteIdenticalToAnUninterruptedOne) {
    ScratchDir dir;
    const std::string phantom = std::string(SONOTRACE_SOURCE_DIR) + "/phantoms/cyst_and_stone.json";
    const std::string args =
        "simulate -q --quality interactive --phantom " + phantom + " --sweep lateral:8:0.25 --out ";
    ASSERT_EQ(test::run(dir, args + (dir / "whole")).exit_code, 0);
    const std::string out = dir / "resumed";
    std::string interrupted = "(";  // appended piecewise: GCC 12's -Wrestrict misfires on a chain
    interrupted += SONOTRACE_BINARY;
    interrupted += " " + args + out;
    interrupted += " 2> /dev/null & pid=$!; i=0; while [ $(ls " + out;
    // Polled every 20 ms: a frame of this phantom takes a few tens, so a slower poll (or
    // a poll starved by other tests on the cores) could see a short sweep finish first;
    // 33 frames leave it most of a second.
    interrupted += " 2> /dev/null | grep -c png) -lt 3 ] && [ $i -lt 3000 ]; do sleep 0.02; ";
    interrupted += "i=$((i+1)); done; kill -INT $pid; wait $pid)";
    const int status = std::system(("sh -c '" + interrupted + "'").c_str());
    ASSERT_TRUE(WIFEXITED(status));
    ASSERT_EQ(WEXITSTATUS(status), 130) << "the sweep finished before the interrupt";
    const auto r = test::run(dir, args + out + " --resume");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto record = nlohmann::json::parse(slurp(out + "/bmode.json"));
    int resumed = 0;
    for (const auto& frame : record.at("sweep").at("frames"))
        resumed += frame.value("resumed", false);
    EXPECT_GE(resumed, 3) << "the kept frames were simulated again";
    int compared = 0;
    for (const auto& e : std::filesystem::directory_iterator(dir / "whole")) {
        if (e.path().extension() == ".json") continue;  // timings differ
        const std::filesystem::path twin = std::filesystem::path(out) / e.path().filename();
        EXPECT_EQ(slurp(e.path().string()), slurp(twin.string())) << e.path().filename();
        ++compared;
    }
    EXPECT_EQ(compared, 34) << "33 frames and the video";
    // --resume without a sweep is refused.
    const auto bad = test::run(dir, "simulate -q --quality interactive --resume --out " + out);
    EXPECT_EQ(bad.exit_code, 1);
    EXPECT_NE(bad.err.find("--resume"), std::string::npos) << bad.err;
}

}  // namespace
}  // namespace sonotrace
