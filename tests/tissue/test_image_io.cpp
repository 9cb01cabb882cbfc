// 2D images and numbered stacks through OpenImageIO: stored integer values are kept,
// colour becomes Rec. 709 luminance, stacks are ordered numerically, spacing is the user's.
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include "tests/test_util.h"
#include "tissue/base/atomic_output.h"
#include "tissue/image_io.h"
#include "tissue/volume_io.h"

namespace sonotrace::tissue {
namespace {

using test::expect_input_error;
using test::ScratchDir;

// Writes raw channel values with OIIO (independent of our writer).
template <typename T>
void write_oiio(const std::string& path, int w, int h, int channels, OIIO::TypeDesc type,
                const std::vector<T>& values) {
    auto out = OIIO::ImageOutput::create(path);
    ASSERT_TRUE(out) << OIIO::geterror();
    OIIO::ImageSpec spec(w, h, channels, type);
    spec.attribute("oiio:UnassociatedAlpha", 1);  // store colour as given, not divided by alpha
    ASSERT_TRUE(out->open(path, spec));
    ASSERT_TRUE(out->write_image(type, values.data()));
    ASSERT_TRUE(out->close());
}

TEST(ImageIo, EightAndSixteenBitPngKeepStoredValues) {
    ScratchDir dir;
    std::vector<uint8_t> v8 = {0, 1, 2, 100, 200, 255};
    write_oiio(dir / "a.png", 3, 2, 1, OIIO::TypeDesc::UINT8, v8);
    const Volume a = read_image(dir / "a.png", {0.5, 0.25, 1.0});
    ASSERT_EQ(a.dims(), glm::ivec3(3, 2, 1));
    for (int n = 0; n < 6; ++n) EXPECT_EQ(a.voxels()[n], float(v8[n]));
    EXPECT_EQ(a.at(1, 1), 200.0f);  // i = column, j = row
    EXPECT_NEAR(a.geometry().index_to_world({2, 1, 0}).x, 1.0, 1e-12);
    EXPECT_NEAR(a.geometry().index_to_world({2, 1, 0}).y, 0.25, 1e-12);

    std::vector<uint16_t> v16 = {0, 1, 1000, 40000, 65535, 12345};
    write_oiio(dir / "b.png", 2, 3, 1, OIIO::TypeDesc::UINT16, v16);
    const Volume b = read_image(dir / "b.png", {1, 1, 1});
    for (int n = 0; n < 6; ++n) EXPECT_EQ(b.voxels()[n], float(v16[n]));
}

TEST(ImageIo, TiffExrAndColourLuminance) {
    ScratchDir dir;
    std::vector<uint16_t> t = {5, 6, 7, 8};
    write_oiio(dir / "t.tif", 2, 2, 1, OIIO::TypeDesc::UINT16, t);
    EXPECT_EQ(read_image(dir / "t.tif", {1, 1, 1}).voxels(), Voxels({5, 6, 7, 8}));

    std::vector<float> e = {-1.5f, 0.25f, 1e3f, 3.0f};
    write_oiio(dir / "e.exr", 4, 1, 1, OIIO::TypeDesc::FLOAT, e);
    EXPECT_EQ(read_image(dir / "e.exr", {1, 1, 1}).voxels(), Voxels(e.begin(), e.end()));

    // RGBA pixel (100, 200, 50, 7): luminance 0.2126*100 + 0.7152*200 + 0.0722*50; alpha ignored.
    std::vector<uint8_t> rgba = {100, 200, 50, 7};
    write_oiio(dir / "c.png", 1, 1, 4, OIIO::TypeDesc::UINT8, rgba);
    EXPECT_NEAR(read_image(dir / "c.png", {1, 1, 1}).voxels()[0],
                0.2126 * 100 + 0.7152 * 200 + 0.0722 * 50, 1e-3);
}

TEST(ImageIo, JpegIsReadWithinCompressionError) {
    ScratchDir dir;
    std::vector<uint8_t> flat(64, 128);
    write_oiio(dir / "j.jpg", 8, 8, 1, OIIO::TypeDesc::UINT8, flat);
    const Volume jpeg = read_image(dir / "j.jpg", {1, 1, 1});
    for (float v : jpeg.voxels()) EXPECT_NEAR(v, 128.0f, 2.0f);
}

TEST(ImageIo, StacksFromDirectoryAndPatternInNumericOrder) {
    ScratchDir dir;
    std::filesystem::create_directories(dir / "stack");
    // Indices 1..11 so that lexical order (1, 10, 11, 2, ...) differs from numeric order.
    for (int k = 1; k <= 11; ++k) {
        write_oiio(dir / ("stack/slice_" + std::to_string(k) + ".png"), 2, 2, 1,
                   OIIO::TypeDesc::UINT8, std::vector<uint8_t>(4, uint8_t(k * 10)));
    }
    LoadedVolume v = load_volume({dir / "stack", glm::dvec3(0.5, 0.5, 2.0)});
    ASSERT_EQ(v.volume.dims(), glm::ivec3(2, 2, 11));
    for (int k = 0; k < 11; ++k) EXPECT_EQ(v.volume.at(1, 1, k), float((k + 1) * 10));
    EXPECT_NEAR(v.volume.geometry().index_to_world({0, 0, 3}).z, 6.0, 1e-12);
    EXPECT_EQ(v.format, "image-stack");

    v = load_volume({dir / "stack/slice_%d.png", glm::dvec3(1, 1, 1)});
    ASSERT_EQ(v.volume.dims().z, 11);
    EXPECT_EQ(v.volume.at(0, 0, 10), 110.0f);

    // The first index is found from one listing of the directory: zero-padded wider than
    // four digits, starting at 7, beside files the pattern does not match.
    std::filesystem::create_directories(dir / "padded");
    for (int k = 7; k <= 9; ++k) {
        char name[32];
        std::snprintf(name, sizeof name, "padded/s%06d.png", k);
        write_oiio(dir / name, 1, 1, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>{uint8_t(k)});
    }
    write_oiio(dir / "padded/s3.png", 1, 1, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>{3});
    write_oiio(dir / "padded/s00000x.png", 1, 1, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>{1});
    v = load_volume({dir / "padded/s%06d.png", glm::dvec3(1)});
    EXPECT_EQ(v.volume.voxels(), Voxels({7, 8, 9}));
}

TEST(ImageIo, OurGrayWriterRoundTrips) {
    ScratchDir dir;
    const std::vector<float> values = {0, 17, 255, 3};
    write_gray_image(dir / "g8.png", 2, 2, values, 8);
    EXPECT_EQ(read_image(dir / "g8.png", {1, 1, 1}).voxels(), Voxels(values.begin(), values.end()));
    const std::vector<float> big = {0, 1000, 65535, 42};
    write_gray_image(dir / "g16.png", 2, 2, big, 16);
    EXPECT_EQ(read_image(dir / "g16.png", {1, 1, 1}).voxels(), Voxels(big.begin(), big.end()));
}

TEST(ImageIoErrors, SpacingIsRequiredAndValidated) {
    ScratchDir dir;
    write_oiio(dir / "a.png", 2, 2, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(4, 1));
    expect_input_error(
        [&] {
            load_volume({dir / "a.png", std::nullopt});
        },
        "a.png", "--spacing", "mm");
    expect_input_error(
        [&] {
            load_volume({dir / "a.png", glm::dvec3(1, 0, 1)});
        },
        "a.png", "spacing[j]");
}

TEST(ImageIoErrors, MismatchedSlicesMissingAndCorruptFiles) {
    ScratchDir dir;
    std::filesystem::create_directories(dir / "s");
    write_oiio(dir / "s/i0.png", 2, 2, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(4, 1));
    write_oiio(dir / "s/i1.png", 3, 2, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(6, 1));
    expect_input_error(
        [&] {
            load_volume({dir / "s", glm::dvec3(1)});
        },
        "i1.png", "size", "differs");
    expect_input_error(
        [&] {
            load_volume({dir / "none_%03d.png", glm::dvec3(1)});
        },
        "none_%03d.png", "", "no file matches");
    expect_input_error(
        [&] {
            load_volume({dir / "missing.png", glm::dvec3(1)});
        },
        "missing.png", "", "not found");
    std::ofstream(dir / "bad.png") << "this is not a PNG file at all";
    expect_input_error([&] { load_volume({dir / "bad.png", glm::dvec3(1)}); }, "bad.png", "");
    std::filesystem::create_directories(dir / "empty");
    expect_input_error(
        [&] {
            load_volume({dir / "empty", glm::dvec3(1)});
        },
        "empty", "", "no image files");
}

// A stack pattern is the user's text: it is parsed, never given to printf. Conversions
// that made snprintf read or write through missing arguments (%s, %n) crashed the program,
// and a field width of 10^8 ran for minutes. Each is refused at once, naming the pattern.
TEST(ImageIoErrors, APatternIsNeverAFormat) {
    ScratchDir dir;
    for (const std::string bad :
         {"a%s%s%s%s.png", "a%n.png", "x%99999999d.png", "x%10d.png", "a%d_%d.png", "a%x.png",
          "a%.png", "a%-3d.png", "a%ld.png", "a%5"}) {
        const auto start = std::chrono::steady_clock::now();
        expect_input_error(
            [&] {
                load_volume({dir / bad, glm::dvec3(1)});
            },
            bad, "", "takes one index as %d, %Nd or %0Nd");
        // Generous for a loaded machine; the bug took 32 s at a width of 10^6.
        EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2)) << bad;
    }
    // The accepted forms number files as printf would: zero or space padding, and %% a '%'.
    EXPECT_EQ(parse_image_pattern("s/i_%03d.png").name(7), "s/i_007.png");
    EXPECT_EQ(parse_image_pattern("i%3d.png").name(42), "i 42.png");
    EXPECT_EQ(parse_image_pattern("100%%_%d.png").name(1234), "100%_1234.png");
    EXPECT_EQ(parse_image_pattern("i%2d.png").name(12345), "i12345.png");  // width is a minimum
    // A file whose name holds a '%' is an image, not a pattern.
    write_oiio(dir / "50%s.png", 2, 1, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>{3, 4});
    EXPECT_EQ(load_volume({dir / "50%s.png", glm::dvec3(1)}).volume.voxels(), Voxels({3, 4}));
    // And a pattern with %% reads its stack.
    write_oiio(dir / "p%_0.png", 1, 1, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>{5});
    write_oiio(dir / "p%_1.png", 1, 1, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>{6});
    EXPECT_EQ(load_volume({dir / "p%%_%d.png", glm::dvec3(1)}).volume.voxels(), Voxels({5, 6}));
}

// Formats beyond the documented PNG, TIFF, JPEG and EXR are refused whatever the file's
// name, before decoding: this 21-byte lossless WebP (a fuzz input) declares 16384 x 16384
// RGBA pixels, and decoding it took 5.8 s and 2.2 GB.
TEST(ImageIoErrors, OtherFormatsAreRefusedBeforeDecoding) {
    ScratchDir dir;
    const unsigned char webp[] = {0x2f, 0xff, 0xff, 0xff, 0x1f, 0x10, 0x10, 0x3f, 0x10, 0x10, 0x7a,
                                  0x23, 0x00, 0x00, 0x66, 0x08, 0x70, 0x23, 0x3f, 0x07, 0x07};
    std::ofstream(dir / "bomb.png", std::ios::binary)
        .write(reinterpret_cast<const char*>(webp), sizeof webp);
    expect_input_error(
        [&] {
            read_image(dir / "bomb.png", {1, 1, 1});
        },
        "bomb.png", "format", "not a PNG, TIFF, JPEG or EXR");
    // A fuzzed file that begins almost as a PNG: OpenImageIO's open() went on to try its
    // other readers, and RLA's aborted the process on its header. It is refused by its
    // first bytes now (the input is kept in tests/fuzz/seeds/image).
    std::ifstream found(
        std::string(SONOTRACE_SOURCE_DIR) + "/tests/fuzz/seeds/image/rla_abort_png_name",
        std::ios::binary);
    const std::string bytes{std::istreambuf_iterator<char>(found), {}};
    ASSERT_GT(bytes.size(), 1000u);
    std::ofstream(dir / "fuzzed.png", std::ios::binary)
        .write(bytes.data(), std::streamsize(bytes.size()));
    expect_input_error(
        [&] {
            read_image(dir / "fuzzed.png", {1, 1, 1});
        },
        "fuzzed.png", "format", "not a PNG, TIFF, JPEG or EXR");
}

TEST(ImageIoErrors, NanPixelsInExr) {
    ScratchDir dir;
    write_oiio(dir / "n.exr", 2, 1, 1, OIIO::TypeDesc::FLOAT,
               std::vector<float>{1.0f, std::nanf("")});
    expect_input_error([&] { read_image(dir / "n.exr", {1, 1, 1}); }, "n.exr", "data", "(1, 0, 0)");
}

}  // namespace
}  // namespace sonotrace::tissue

namespace sonotrace::tissue {
namespace {

// Every output goes through base::write_file(), which checks each write and the close: on a full
// disk (/dev/full answers every write with ENOSPC) it throws naming the output, where an
// unchecked stream left a truncated PNG reported as written. A staged temporary is named
// by its final path.
TEST(OutputErrors, AFullDiskIsAnErrorNamingTheOutput) {
    if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "no /dev/full on this system";
    test::ScratchDir dir;
    const std::string bytes(100000, 'x');
    test::expect_input_error([&] { base::write_file("/dev/full", bytes.data(), bytes.size()); },
                             "/dev/full", "", "No space left on device");
    EXPECT_TRUE(std::filesystem::exists("/dev/full")) << "a device is never removed";
    // Through the image encoder: the PNG is encoded in memory, then written and checked.
    std::filesystem::create_symlink("/dev/full", dir / "frame.png");
    const std::vector<float> pixels(64 * 64, 0.5f);
    const OIIO::ImageSpec spec(64, 64, 1, OIIO::TypeDesc::UINT8);
    test::expect_input_error(
        [&] { write_image_file(dir / "frame.png", spec, OIIO::TypeDesc::FLOAT, pixels.data()); },
        "frame.png", "", "No space left on device");
    // A staged name in a message is the final one.
    EXPECT_EQ(base::output_name("/out/.partial-123-4-bmode.png"), "/out/bmode.png");
    EXPECT_EQ(base::output_name("/out/bmode.png"), "/out/bmode.png");
}

}  // namespace
}  // namespace sonotrace::tissue
