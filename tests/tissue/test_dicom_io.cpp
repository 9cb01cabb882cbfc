// DICOM series loading: geometry from the Image Plane module (PS3.3 C.7.6.2) converted to
// the RAS world, slice order from positions, rescaling, multi-frame files, and every
// refusal with its file and tag.
// Test files are written with GDCM's low-level writer from hand-made attributes (the
// standard's text, e.g. PixelSpacing "row\column"), not through gdcm::Image's geometry, so
// a convention error in the reader cannot be cancelled by the same error in the writer.
// Expected positions follow the standard's equation: voxel (column i, row j) of a slice at
// ImagePositionPatient P lies at P + i * column_spacing * row_cosine + j * row_spacing *
// column_cosine (LPS), and RAS = (-x, -y, z).
#include <gdcmAttribute.h>
#include <gdcmDataElement.h>
#include <gdcmFileMetaInformation.h>
#include <gdcmImageChangeTransferSyntax.h>
#include <gdcmImageReader.h>
#include <gdcmTransferSyntax.h>
#include <gdcmWriter.h>
#include <gtest/gtest.h>

#include <chrono>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <optional>
#include <vector>

#include "tests/test_util.h"
#if defined(__SANITIZE_ADDRESS__)
#define SONOTRACE_TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SONOTRACE_TEST_ASAN 1
#endif
#endif
#ifdef SONOTRACE_TEST_ASAN
#include <sanitizer/common_interface_defs.h>
#endif
#include "tissue/dicom_io.h"
#include "tissue/volume_io.h"

namespace sonotrace::tissue {
namespace {

using test::expect_input_error;
using test::ScratchDir;

struct SliceSpec {
    std::string series_uid = "1.2.826.0.1.3680043.2.1125.1";
    std::optional<std::string> position = "0\\0\\0";
    std::optional<std::string> orientation = "1\\0\\0\\0\\1\\0";
    std::optional<std::string> pixel_spacing = "0.8\\0.5";  // row spacing \ column spacing
    std::optional<std::string> slope, intercept;
    std::optional<std::string> frames;
    std::optional<std::string> spacing_between_slices;
    std::string photometric = "MONOCHROME2";
    std::string modality = "MR";
    int samples_per_pixel = 1;
    int rows = 3, columns = 4;
    int instance_number = 1;
    std::vector<std::int16_t> stored;  // rows * columns * frames * samples values
};

void put_text(gdcm::DataSet& data, std::uint16_t group, std::uint16_t element, gdcm::VR vr,
              std::string value) {
    if (value.size() % 2 == 1) value += vr == gdcm::VR::UI ? '\0' : ' ';
    gdcm::DataElement attribute(gdcm::Tag(group, element));
    attribute.SetVR(vr);
    attribute.SetByteValue(value.data(), std::uint32_t(value.size()));
    data.Replace(attribute);
}

void put_us(gdcm::DataSet& data, std::uint16_t group, std::uint16_t element, std::uint16_t value) {
    gdcm::DataElement attribute(gdcm::Tag(group, element));
    attribute.SetVR(gdcm::VR::US);
    attribute.SetByteValue(reinterpret_cast<const char*>(&value), 2);
    data.Replace(attribute);
}

void write_slice(const std::string& path, const SliceSpec& s) {
    gdcm::Writer writer;
    gdcm::DataSet& data = writer.GetFile().GetDataSet();
    static int instance = 0;
    put_text(data, 0x0008, 0x0016, gdcm::VR::UI, "1.2.840.10008.5.1.4.1.1.4");  // MR Image
    put_text(data, 0x0008, 0x0018, gdcm::VR::UI,
             "1.2.826.0.1.3680043.2.1125.2." + std::to_string(++instance));
    put_text(data, 0x0008, 0x0060, gdcm::VR::CS, s.modality);
    put_text(data, 0x0008, 0x103E, gdcm::VR::LO, "test series");
    put_text(data, 0x0020, 0x000D, gdcm::VR::UI, "1.2.826.0.1.3680043.2.1125.3");
    put_text(data, 0x0020, 0x000E, gdcm::VR::UI, s.series_uid);
    put_text(data, 0x0020, 0x0013, gdcm::VR::IS, std::to_string(s.instance_number));
    if (s.position) put_text(data, 0x0020, 0x0032, gdcm::VR::DS, *s.position);
    if (s.orientation) put_text(data, 0x0020, 0x0037, gdcm::VR::DS, *s.orientation);
    if (s.spacing_between_slices) {
        put_text(data, 0x0018, 0x0088, gdcm::VR::DS, *s.spacing_between_slices);
    }
    put_us(data, 0x0028, 0x0002, std::uint16_t(s.samples_per_pixel));
    put_text(data, 0x0028, 0x0004, gdcm::VR::CS, s.photometric);
    if (s.samples_per_pixel > 1) put_us(data, 0x0028, 0x0006, 0);
    if (s.frames) put_text(data, 0x0028, 0x0008, gdcm::VR::IS, *s.frames);
    put_us(data, 0x0028, 0x0010, std::uint16_t(s.rows));
    put_us(data, 0x0028, 0x0011, std::uint16_t(s.columns));
    if (s.pixel_spacing) put_text(data, 0x0028, 0x0030, gdcm::VR::DS, *s.pixel_spacing);
    put_us(data, 0x0028, 0x0100, 16);
    put_us(data, 0x0028, 0x0101, 16);
    put_us(data, 0x0028, 0x0102, 15);
    put_us(data, 0x0028, 0x0103, 1);  // signed
    if (s.intercept) put_text(data, 0x0028, 0x1052, gdcm::VR::DS, *s.intercept);
    if (s.slope) put_text(data, 0x0028, 0x1053, gdcm::VR::DS, *s.slope);
    gdcm::DataElement pixels(gdcm::Tag(0x7FE0, 0x0010));
    pixels.SetVR(gdcm::VR::OW);
    pixels.SetByteValue(reinterpret_cast<const char*>(s.stored.data()),
                        std::uint32_t(s.stored.size() * sizeof(std::int16_t)));
    data.Replace(pixels);
    writer.GetFile().GetHeader().SetDataSetTransferSyntax(
        gdcm::TransferSyntax::ExplicitVRLittleEndian);
    writer.SetFileName(path.c_str());
    ASSERT_TRUE(writer.Write()) << path;
}

// A value that identifies voxel (i, j, k).
std::int16_t stored_value(int i, int j, int k) {
    return std::int16_t(i + 10 * j + 100 * k - 50);
}

std::vector<std::int16_t> slice_values(const SliceSpec& s, int k) {
    std::vector<std::int16_t> values;
    for (int j = 0; j < s.rows; ++j) {
        for (int i = 0; i < s.columns; ++i) values.push_back(stored_value(i, j, k));
    }
    return values;
}

std::string ds_triplet(const glm::dvec3& v) {
    char text[96];
    std::snprintf(text, sizeof text, "%.6f\\%.6f\\%.6f", v.x, v.y, v.z);
    return text;
}

glm::dvec3 lps_to_ras(const glm::dvec3& v) {
    return {-v.x, -v.y, v.z};
}

void expect_near(const glm::dvec3& got, const glm::dvec3& expected, double tolerance,
                 const std::string& what) {
    EXPECT_LT(glm::length(got - expected), tolerance)
        << what << ": got (" << got.x << ", " << got.y << ", " << got.z << "), expected ("
        << expected.x << ", " << expected.y << ", " << expected.z << ")";
}

// An oblique plane: the row and column cosines of an axial plane turned 30 degrees about
// the LPS z axis and tilted 20 degrees about the x axis.
struct ObliquePlane {
    glm::dvec3 row, column, normal;
    ObliquePlane() {
        const double a = 30.0 * M_PI / 180.0, b = 20.0 * M_PI / 180.0;
        const glm::dvec3 r(std::cos(a), std::sin(a), 0.0), c(-std::sin(a), std::cos(a), 0.0);
        auto tilt = [&](const glm::dvec3& v) {
            return glm::dvec3(v.x, std::cos(b) * v.y - std::sin(b) * v.z,
                              std::sin(b) * v.y + std::cos(b) * v.z);
        };
        row = tilt(r);
        column = tilt(c);
        normal = glm::cross(row, column);
    }
    std::string orientation() const {
        char text[160];
        std::snprintf(text, sizeof text, "%.8f\\%.8f\\%.8f\\%.8f\\%.8f\\%.8f", row.x, row.y, row.z,
                      column.x, column.y, column.z);
        return text;
    }
};

// Writes `count` slices of an oblique series stepping by `step` (LPS mm) from `first`, in
// file names that run against the slice order and instance numbers that run with neither.
void write_series(const ScratchDir& dir, const ObliquePlane& plane, const glm::dvec3& first,
                  const glm::dvec3& step, int count, SliceSpec spec = {}) {
    spec.orientation = plane.orientation();
    for (int k = 0; k < count; ++k) {
        spec.position = ds_triplet(first + double(k) * step);
        spec.instance_number = (k * 7) % count + 1;
        spec.stored = slice_values(spec, k);
        write_slice(dir / ("IM" + std::to_string(count - k)), spec);
    }
}

TEST(DicomIo, ObliqueSeriesHasTheStandardsGeometryAndRescaledValues) {
    ScratchDir dir;
    const ObliquePlane plane;
    const glm::dvec3 first(-12.5, 30.25, 8.0);
    const double slice_gap = 2.0;
    SliceSpec spec;
    spec.slope = "2";
    spec.intercept = "-1024";
    write_series(dir, plane, first, slice_gap * plane.normal, 5, spec);

    const DicomReadResult result = read_dicom(dir.path().string());
    const Volume& volume = result.volume;
    ASSERT_EQ(volume.dims(), glm::ivec3(4, 3, 5));
    EXPECT_EQ(result.modality, "MR");
    EXPECT_EQ(result.slice_count, 5);
    const double column_spacing = 0.5, row_spacing = 0.8;
    for (int k = 0; k < 5; ++k) {
        for (int j = 0; j < 3; ++j) {
            for (int i = 0; i < 4; ++i) {
                const glm::dvec3 lps = first + double(k) * slice_gap * plane.normal +
                                       double(i) * column_spacing * plane.row +
                                       double(j) * row_spacing * plane.column;
                expect_near(volume.geometry().index_to_world(glm::dvec3(i, j, k)), lps_to_ras(lps),
                            1e-5,
                            "voxel " + std::to_string(i) + "," + std::to_string(j) + "," +
                                std::to_string(k));
                EXPECT_FLOAT_EQ(volume.at(i, j, k), 2.0f * stored_value(i, j, k) - 1024.0f);
            }
        }
    }
}

TEST(DicomIo, SlicesAreOrderedByPositionWhateverTheirNamesOrNumbers) {
    // The same series stepping against the normal: k must still run along the normal.
    ScratchDir dir;
    const ObliquePlane plane;
    const glm::dvec3 first(0.0, 0.0, 40.0);
    write_series(dir, plane, first, -1.5 * plane.normal, 4);
    const Volume volume = read_dicom(dir.path().string()).volume;
    const glm::dvec3 lowest = first + 3.0 * -1.5 * plane.normal;
    expect_near(volume.geometry().origin, lps_to_ras(lowest), 1e-5, "origin");
    expect_near(volume.geometry().direction[2], lps_to_ras(plane.normal), 1e-6, "k axis");
    EXPECT_NEAR(volume.geometry().spacing.z, 1.5, 1e-6);
    // The slice written as k = 3 (the lowest) is the volume's first.
    EXPECT_FLOAT_EQ(volume.at(0, 0, 0), float(stored_value(0, 0, 3)));
    EXPECT_FLOAT_EQ(volume.at(0, 0, 3), float(stored_value(0, 0, 0)));
}

TEST(DicomIo, TiltedGantryGivesASlantedSliceAxis) {
    ScratchDir dir;
    const ObliquePlane plane;
    // Each slice steps 2 mm along the normal and 0.5 mm along the columns.
    const glm::dvec3 step = 2.0 * plane.normal + 0.5 * plane.column;
    write_series(dir, plane, glm::dvec3(1, 2, 3), step, 4);
    const Volume volume = read_dicom(dir.path().string()).volume;
    for (int k = 0; k < 4; ++k) {
        expect_near(volume.geometry().index_to_world(glm::dvec3(0, 0, k)),
                    lps_to_ras(glm::dvec3(1, 2, 3) + double(k) * step), 1e-5,
                    "slice " + std::to_string(k));
    }
}

// Issue 50, item 14: a sheared stack (5 mm in-plane shift per 2 mm slice) is read with
// its slanted slice axis, each slice's voxels at the positions its file records (the
// expected positions are the ones written), and the reader says so; an orthogonal series
// draws no such warning.
TEST(DicomIo, AShearedStackKeepsItsSlantedAxisAndIsReported) {
    ScratchDir dir;
    const ObliquePlane plane;
    const glm::dvec3 step = 2.0 * plane.normal + 5.0 * plane.column;
    write_series(dir, plane, glm::dvec3(1, 2, 3), step, 4);
    const DicomReadResult sheared = read_dicom(dir.path().string());
    for (int k = 0; k < 4; ++k)
        for (const glm::dvec3& ij : {glm::dvec3(0, 0, 0), glm::dvec3(3, 2, 0)})
            expect_near(sheared.volume.geometry().index_to_world(ij + glm::dvec3(0, 0, k)),
                        lps_to_ras(glm::dvec3(1, 2, 3) + double(k) * step + ij.x * 0.5 * plane.row +
                                   ij.y * 0.8 * plane.column),
                        1e-5, "slice " + std::to_string(k));
    ASSERT_EQ(sheared.warnings.size(), 1u);
    EXPECT_NE(sheared.warnings[0].find("step 2 mm along their normal and 5 mm across it"),
              std::string::npos)
        << sheared.warnings[0];

    ScratchDir straight;
    write_series(straight, plane, glm::dvec3(1, 2, 3), 2.0 * plane.normal, 3);
    EXPECT_TRUE(read_dicom(straight.path().string()).warnings.empty());
}

// The fuzzer's series seed (tests/fuzz/seeds/dicom_series: files joined by the fuzz
// targets' separator) is a readable series, so the fuzzer starts from a sound one.
TEST(DicomIo, SeriesSeedOfTheFuzzerIsASoundSeries) {
    std::ifstream in(SONOTRACE_SOURCE_DIR "/tests/fuzz/seeds/dicom_series/four_sheared_slices",
                     std::ios::binary);
    const std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string separator = "\n#sonotrace-next-file#\n";
    ScratchDir dir;
    std::size_t at = 0, files = 0;
    for (std::size_t next; (next = all.find(separator, at)) != std::string::npos;
         at = next + separator.size())
        std::ofstream(dir / ("IM" + std::to_string(files++)), std::ios::binary)
            << all.substr(at, next - at);
    std::ofstream(dir / ("IM" + std::to_string(files++)), std::ios::binary) << all.substr(at);
    ASSERT_EQ(files, 4u);
    EXPECT_EQ(read_dicom(dir.path().string()).volume.dims(), glm::ivec3(4, 3, 4));
}

TEST(DicomIo, OneSliceIsATwoDimensionalVolume) {
    ScratchDir dir;
    SliceSpec spec;
    spec.position = "10\\20\\30";
    spec.stored = slice_values(spec, 0);
    write_slice(dir / "one.dcm", spec);
    const LoadedVolume loaded = load_volume({dir / "one.dcm", std::nullopt});
    EXPECT_EQ(loaded.format, "dicom");
    EXPECT_TRUE(loaded.volume.is_2d());
    EXPECT_FLOAT_EQ(loaded.volume.at(3, 2), float(stored_value(3, 2, 0)));
    expect_near(loaded.volume.geometry().index_to_world(glm::dvec3(1, 1, 0)),
                lps_to_ras(glm::dvec3(10.5, 20.8, 30)), 1e-9, "voxel 1,1");
}

TEST(DicomIo, LoadVolumeRecognisesSeriesDirectoriesAndFilesWithoutExtension) {
    ScratchDir dir;
    write_series(dir, ObliquePlane(), glm::dvec3(0.0), glm::dvec3(0, 0, 1), 3);
    {
        std::ofstream(dir / "notes.txt") << "not a DICOM file";  // ignored
    }
    const LoadedVolume series = load_volume({dir.path().string(), std::nullopt});
    EXPECT_EQ(series.format, "dicom");
    EXPECT_EQ(series.volume.dims().z, 3);
    const LoadedVolume one = load_volume({dir / "IM1", std::nullopt});
    EXPECT_EQ(one.format, "dicom");
    EXPECT_TRUE(one.volume.is_2d());
    // Patient coordinates and the modality travel with the volume: the default pose and
    // transfer function follow them (a CT series is read in Hounsfield units).
    EXPECT_TRUE(series.anatomical);
    EXPECT_EQ(series.modality, "MR");
    ScratchDir ct;
    SliceSpec spec;
    spec.modality = "CT";
    write_series(ct, ObliquePlane(), glm::dvec3(0.0), glm::dvec3(0, 0, 1), 2, spec);
    EXPECT_EQ(load_volume({ct.path().string(), std::nullopt}).modality, "CT");
}

TEST(DicomIo, MultiFrameFileIsAVolume) {
    ScratchDir dir;
    SliceSpec spec;
    spec.frames = "3";
    spec.position = "5\\6\\7";
    spec.spacing_between_slices = "2.5";
    for (int k = 0; k < 3; ++k) {
        const auto values = slice_values(spec, k);
        spec.stored.insert(spec.stored.end(), values.begin(), values.end());
    }
    write_slice(dir / "multi.dcm", spec);
    const DicomReadResult result = read_dicom(dir / "multi.dcm");
    ASSERT_EQ(result.volume.dims(), glm::ivec3(4, 3, 3));
    EXPECT_FLOAT_EQ(result.volume.at(2, 1, 2), float(stored_value(2, 1, 2)));
    EXPECT_NEAR(result.volume.geometry().spacing.x, 0.5, 1e-9);
    EXPECT_NEAR(result.volume.geometry().spacing.y, 0.8, 1e-9);
    EXPECT_NEAR(result.volume.geometry().spacing.z, 2.5, 1e-9);
    expect_near(result.volume.geometry().origin, lps_to_ras(glm::dvec3(5, 6, 7)), 1e-9, "origin");
}

TEST(DicomIo, CompressedTransferSyntaxesDecodeToTheSameValues) {
    // Lossless compression must give back the stored values exactly.
    ScratchDir dir;
    SliceSpec spec;
    spec.rows = 16;
    spec.columns = 16;
    spec.slope = "1.5";
    for (int j = 0; j < spec.rows; ++j) {
        for (int i = 0; i < spec.columns; ++i) spec.stored.push_back(std::int16_t(37 * i - 91 * j));
    }
    write_slice(dir / "plain.dcm", spec);
    const Volume plain = read_dicom(dir / "plain.dcm").volume;
    const std::pair<const char*, gdcm::TransferSyntax::TSType> syntaxes[] = {
        {"jpeg-lossless", gdcm::TransferSyntax::JPEGLosslessProcess14_1},
        {"rle", gdcm::TransferSyntax::RLELossless},
        {"jpeg2000-lossless", gdcm::TransferSyntax::JPEG2000Lossless},
    };
    for (const auto& [name, syntax] : syntaxes) {
        SCOPED_TRACE(name);
        gdcm::ImageReader reader;
        reader.SetFileName((dir / "plain.dcm").c_str());
        ASSERT_TRUE(reader.Read());
        gdcm::ImageChangeTransferSyntax change;
        change.SetTransferSyntax(syntax);
        change.SetInput(reader.GetImage());
        ASSERT_TRUE(change.Change());
        // Our attributes with the compressed pixel data (gdcm::ImageWriter would rewrite
        // the geometry from its own model).
        gdcm::Writer writer;
        writer.SetFile(reader.GetFile());
        writer.GetFile().GetDataSet().Replace(change.GetOutput().GetDataElement());
        writer.GetFile().GetHeader().SetDataSetTransferSyntax(syntax);
        writer.GetFile().GetHeader().Remove(gdcm::Tag(0x0002, 0x0010));  // refilled on write
        const std::string path = dir / (std::string(name) + ".dcm");
        writer.SetFileName(path.c_str());
        ASSERT_TRUE(writer.Write());
        gdcm::Reader check;
        check.SetFileName(path.c_str());
        ASSERT_TRUE(check.Read());
        ASSERT_EQ(check.GetFile().GetHeader().GetDataSetTransferSyntax(), syntax)
            << "the file must really be compressed";
        const Volume compressed = read_dicom(path).volume;
        EXPECT_EQ(compressed.voxels(), plain.voxels());
        EXPECT_FLOAT_EQ(compressed.at(3, 2), 1.5f * float(37 * 3 - 91 * 2));
    }
}

TEST(DicomIo, TheDefaultHeadWrittenAsASeriesReadsBackAsTheNifti) {
    // The Colin27 NIfTI (geometry from niftilib's sform, RAS) written as axial DICOM
    // slices by the standard's equations in LPS; reading the series must give the same
    // voxels at the same world positions.
    const LoadedVolume nifti = load_volume({kDefaultVolumeName, std::nullopt});
    const VolumeGeometry& g = nifti.volume.geometry();
    ScratchDir dir;
    SliceSpec spec;
    spec.columns = g.dims.x;
    spec.rows = g.dims.y;
    spec.slope = "0.5";
    spec.intercept = "3";
    auto to_lps = [](const glm::dvec3& ras) { return glm::dvec3(-ras.x, -ras.y, ras.z); };
    const glm::dvec3 row = to_lps(g.direction[0]), column = to_lps(g.direction[1]);
    char text[200];
    std::snprintf(text, sizeof text, "%.9f\\%.9f\\%.9f\\%.9f\\%.9f\\%.9f", row.x, row.y, row.z,
                  column.x, column.y, column.z);
    spec.orientation = text;
    std::snprintf(text, sizeof text, "%.9f\\%.9f", g.spacing.y, g.spacing.x);
    spec.pixel_spacing = text;
    for (int k = 0; k < g.dims.z; ++k) {
        spec.position = ds_triplet(to_lps(g.index_to_world(glm::dvec3(0, 0, k))));
        spec.stored.clear();
        for (int j = 0; j < g.dims.y; ++j) {
            for (int i = 0; i < g.dims.x; ++i) {
                const float value = nifti.volume.at(i, j, k);
                ASSERT_EQ(value, std::round(value)) << "Colin27 holds whole numbers";
                spec.stored.push_back(std::int16_t((value - 3.0f) * 2.0f));
            }
        }
        write_slice(dir / ("slice" + std::to_string(1000 + k)), spec);
    }
    const LoadedVolume dicom = load_volume({dir.path().string(), std::nullopt});
    ASSERT_EQ(dicom.volume.dims(), g.dims);
    EXPECT_EQ(dicom.volume.voxels(), nifti.volume.voxels());
    for (const glm::dvec3 ijk :
         {glm::dvec3(0, 0, 0), glm::dvec3(g.dims - 1), glm::dvec3(90, 40, 7)}) {
        // Positions are written with six decimals.
        expect_near(dicom.volume.geometry().index_to_world(ijk), g.index_to_world(ijk), 1e-5,
                    "world position");
    }
}

// ---- refusals ----

TEST(DicomIo, MixedSeriesAreRefusedWithTheirUids) {
    ScratchDir dir;
    SliceSpec a, b;
    b.series_uid = "1.2.826.0.1.3680043.2.1125.99";
    a.stored = slice_values(a, 0);
    b.stored = slice_values(b, 0);
    b.position = "0\\0\\1";
    write_slice(dir / "a", a);
    write_slice(dir / "b", b);
    expect_input_error([&] { read_dicom(dir.path().string()); }, dir.path().string(),
                       "SeriesInstanceUID (0020,000E)", "1.2.826.0.1.3680043.2.1125.99");
}

TEST(DicomIo, TwoSlicesAtOnePositionAreRefused) {
    ScratchDir dir;
    SliceSpec spec;
    spec.stored = slice_values(spec, 0);
    write_slice(dir / "echo1", spec);
    write_slice(dir / "echo2", spec);
    expect_input_error([&] { read_dicom(dir.path().string()); }, "echo2",
                       "ImagePositionPatient (0020,0032)", "same position");
}

TEST(DicomIo, AMissingSliceIsRefused) {
    ScratchDir dir;
    SliceSpec spec;
    for (int k : {0, 1, 2, 4}) {
        spec.position = ds_triplet(glm::dvec3(0.0, 0.0, 2.0 * k));
        spec.stored = slice_values(spec, k);
        write_slice(dir / (std::string(1, char('a' + k))), spec);
    }
    expect_input_error([&] { read_dicom(dir.path().string()); }, "not uniform",
                       "ImagePositionPatient (0020,0032)", "missing slice");
}

TEST(DicomIo, DifferingOrientationSizeOrSpacingIsRefused) {
    struct Case {
        const char* name;
        void (*change)(SliceSpec&);
        const char* field;
    };
    const Case cases[] = {
        {"orientation", [](SliceSpec& s) { s.orientation = "1\\0\\0\\0\\0\\1"; },
         "ImageOrientationPatient (0020,0037)"},
        {"spacing", [](SliceSpec& s) { s.pixel_spacing = "0.9\\0.5"; }, "PixelSpacing (0028,0030)"},
        {"size", [](SliceSpec& s) { s.rows = 5; }, "Rows (0028,0010)"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        ScratchDir dir;
        SliceSpec first;
        first.stored = slice_values(first, 0);
        write_slice(dir / "a", first);
        SliceSpec second;
        second.position = "0\\0\\1";
        c.change(second);
        second.stored = slice_values(second, 1);
        write_slice(dir / "b", second);
        expect_input_error([&] { read_dicom(dir.path().string()); }, "b", c.field);
    }
}

TEST(DicomIo, BadOrMissingGeometryTagsNameTheFileAndTag) {
    struct Case {
        const char* name;
        void (*change)(SliceSpec&);
        const char* field;
        const char* text;
    };
    const Case cases[] = {
        {"two numbers", [](SliceSpec& s) { s.position = "1\\2"; },
         "ImagePositionPatient (0020,0032)", "expected 3"},
        {"NaN", [](SliceSpec& s) { s.position = "nan\\0\\1"; }, "ImagePositionPatient (0020,0032)",
         "finite"},
        {"text", [](SliceSpec& s) { s.pixel_spacing = "abc\\0.5"; }, "PixelSpacing (0028,0030)",
         "finite"},
        {"missing position", [](SliceSpec& s) { s.position.reset(); },
         "ImagePositionPatient (0020,0032)", "missing"},
        {"not unit", [](SliceSpec& s) { s.orientation = "2\\0\\0\\0\\1\\0"; },
         "ImageOrientationPatient (0020,0037)", "unit"},
        {"zero slope", [](SliceSpec& s) { s.slope = "0"; }, "RescaleSlope (0028,1053)", "non-zero"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        ScratchDir dir;
        SliceSpec good;
        good.stored = slice_values(good, 0);
        write_slice(dir / "a", good);
        SliceSpec bad;
        bad.position = "0\\0\\1";
        c.change(bad);
        bad.stored = slice_values(bad, 1);
        write_slice(dir / "b", bad);
        expect_input_error([&] { read_dicom(dir.path().string()); }, "", c.field, c.text);
    }
}

TEST(DicomIo, ColourImagesAreRefused) {
    ScratchDir dir;
    SliceSpec spec;
    spec.photometric = "RGB";
    spec.samples_per_pixel = 3;
    spec.stored.assign(3 * 4 * 3, 7);
    write_slice(dir / "rgb.dcm", spec);
    expect_input_error([&] { read_dicom(dir / "rgb.dcm"); }, "rgb.dcm",
                       "PhotometricInterpretation (0028,0004)", "greyscale");
}

TEST(DicomIo, TruncatedAndForeignFilesAreRefused) {
    ScratchDir dir;
    SliceSpec spec;
    spec.rows = 64;
    spec.columns = 64;
    spec.stored = slice_values(spec, 0);
    write_slice(dir / "full.dcm", spec);
    const auto size = std::filesystem::file_size(dir / "full.dcm");
    std::filesystem::copy_file(dir / "full.dcm", dir / "cut.dcm");
    std::filesystem::resize_file(dir / "cut.dcm", size - 1000);
    expect_input_error([&] { read_dicom(dir / "cut.dcm"); }, "cut.dcm", "");
    { std::ofstream(dir / "fake.dcm") << "plain text, no preamble"; }
    expect_input_error([&] { read_dicom(dir / "fake.dcm"); }, "fake.dcm", "", "not a DICOM");
    ScratchDir empty;
    { std::ofstream(empty / "readme.txt") << "nothing"; }
    expect_input_error([&] { read_dicom(empty.path().string()); }, empty.path().string(), "",
                       "no DICOM files");
    expect_input_error([&] { read_dicom(dir / "absent"); }, "absent", "", "not found");
}

TEST(DicomIo, FilesThatCrashOrExhaustGdcmAreRefused) {
    // Fuzz findings. A file meta header that trips an assertion in Debian's GDCM (an
    // abort): its declared lengths are now checked first, and what passes the check is
    // read in a child process where an abort is a refusal. A 714-byte file whose header
    // made GDCM allocate 4 GB: refused within the reading's memory budget.
    for (const char* name : {"gdcm_assertion_in_meta_header.dcm", "gdcm_allocates_gigabytes.dcm"}) {
        const std::string file =
            std::string(SONOTRACE_SOURCE_DIR) + "/tests/fuzz/seeds/dicom/" + name;
        expect_input_error([&] { read_dicom(file); }, file, "");
    }
    // A 680-byte file declaring 12546 x 19716 pixels with 72 bytes of native pixel data:
    // GDCM decodes it "successfully" into the declared buffer (27 s and 14 GB before the
    // slice failed); refused from its header, before decoding: 12546 x 19716 x 2 bytes
    // cannot be in 680.
    const std::string short_pixels = std::string(SONOTRACE_SOURCE_DIR) +
                                     "/tests/fuzz/seeds/dicom/gdcm_short_native_pixel_data.dcm";
    expect_input_error([&] { read_dicom(short_pixels); }, short_pixels, "Rows",
                       "declares 19716 x 12546 x 1 pixels (494713872 bytes), more than its 680");
}

// Issue 50, item 13: compressed files declaring huge images (a 766-byte RLE file of
// 40000 x 40000 pixels cost 3.2 GB and seconds before the refusal) are refused from their
// header before any decoding: more pixels than any lossless encoding of the file's bytes
// can hold (kMaxDecodedPerFileByte, 10,000:1). Timed: under a second for four such files.
TEST(DicomIo, CompressedFilesDeclaringHugeImagesAreRefusedBeforeDecoding) {
    ScratchDir dir;
    SliceSpec spec;
    spec.rows = 16;
    spec.columns = 16;
    spec.stored.assign(16 * 16, 7);
    write_slice(dir / "plain.dcm", spec);
    gdcm::ImageReader reader;
    reader.SetFileName((dir / "plain.dcm").c_str());
    ASSERT_TRUE(reader.Read());
    gdcm::ImageChangeTransferSyntax change;
    change.SetTransferSyntax(gdcm::TransferSyntax::RLELossless);
    change.SetInput(reader.GetImage());
    ASSERT_TRUE(change.Change());
    gdcm::Writer writer;
    writer.SetFile(reader.GetFile());
    gdcm::DataSet& data = writer.GetFile().GetDataSet();
    data.Replace(change.GetOutput().GetDataElement());
    gdcm::Attribute<0x0028, 0x0010> rows{40000};
    gdcm::Attribute<0x0028, 0x0011> columns{40000};
    data.Replace(rows.GetAsDataElement());
    data.Replace(columns.GetAsDataElement());
    writer.GetFile().GetHeader().SetDataSetTransferSyntax(gdcm::TransferSyntax::RLELossless);
    writer.GetFile().GetHeader().Remove(gdcm::Tag(0x0002, 0x0010));
    std::filesystem::create_directories(dir / "series");
    for (int k = 0; k < 4; ++k) {
        const std::string path = dir / ("series/huge" + std::to_string(k) + ".dcm");
        writer.SetFileName(path.c_str());
        ASSERT_TRUE(writer.Write());
    }
    const auto start = std::chrono::steady_clock::now();
    expect_input_error([&] { read_dicom(dir / "series"); }, "huge", "Rows",
                       "more than any lossless encoding");
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 1.0);
}

// In a sanitizer build, the reading child's death (ASan's operator new dies where the
// memory budget makes GDCM's gigabyte allocation fail) must not run the parent's death
// callback: a fuzzer's recorded every such refusal as a crash of its own.
TEST(DicomIo, UnderASanTheReadingChildsDeathStaysTheChilds) {
#ifdef SONOTRACE_TEST_ASAN
    static std::string marker;
    ScratchDir dir;
    marker = dir / "death_callback_ran";
    __sanitizer_set_death_callback([] { std::ofstream(marker) << "ran"; });
    const std::string file =
        std::string(SONOTRACE_SOURCE_DIR) + "/tests/fuzz/seeds/dicom/gdcm_allocates_gigabytes.dcm";
    expect_input_error([&] { read_dicom(file); }, file, "");
    __sanitizer_set_death_callback(nullptr);
    EXPECT_FALSE(std::filesystem::exists(marker));
#else
    GTEST_SKIP() << "only a sanitizer build has death callbacks";
#endif
}

}  // namespace
}  // namespace sonotrace::tissue
