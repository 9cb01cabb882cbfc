// NIfTI-1 loading: round trips for every supported datatype, header transforms (qform,
// sform, units), scaling, and every bad-input case with its message.
// Test files are written with niftilib directly, not with our writer, so reader bugs
// cannot cancel writer bugs.
#include <gtest/gtest.h>
#include <nifti1_io.h>
#include <zlib.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <vector>

#include "tests/test_util.h"
#include "tissue/nifti_io.h"
#include "tissue/volume_io.h"

namespace sonotrace::tissue {
namespace {

using test::expect_input_error;
using test::ScratchDir;

struct NiftiSpec {
    int nx = 4, ny = 3, nz = 2, nt = 1;
    int datatype = DT_FLOAT32;
    float pixdim[3] = {1.0f, 1.0f, 1.0f};
    float slope = 0.0f, inter = 0.0f;
    int qform_code = 0, sform_code = 0;
    float quatern[3] = {0, 0, 0};  // b, c, d
    float qoffset[3] = {0, 0, 0};
    float qfac = 1.0f;
    float srow[3][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}};
    int xyz_units = NIFTI_UNITS_MM;
};

template <typename T>
void fill(void* data, const std::vector<double>& values) {
    T* out = static_cast<T*>(data);
    for (std::size_t n = 0; n < values.size(); ++n) out[n] = T(values[n]);
}

// Writes `values` (stored values, before scaling) with niftilib.
void write_with_niftilib(const std::string& path, const NiftiSpec& s,
                         const std::vector<double>& values) {
    int dims[8] = {s.nt > 1 ? 4 : 3, s.nx, s.ny, s.nz, s.nt, 1, 1, 1};
    nifti_image* nim = nifti_make_new_nim(dims, s.datatype, 1);
    ASSERT_NE(nim, nullptr);
    ASSERT_EQ(values.size(), std::size_t(nim->nvox));
    switch (s.datatype) {
        case DT_UINT8:
            fill<uint8_t>(nim->data, values);
            break;
        case DT_INT8:
            fill<int8_t>(nim->data, values);
            break;
        case DT_UINT16:
            fill<uint16_t>(nim->data, values);
            break;
        case DT_INT16:
            fill<int16_t>(nim->data, values);
            break;
        case DT_UINT32:
            fill<uint32_t>(nim->data, values);
            break;
        case DT_INT32:
            fill<int32_t>(nim->data, values);
            break;
        case DT_UINT64:
            fill<uint64_t>(nim->data, values);
            break;
        case DT_INT64:
            fill<int64_t>(nim->data, values);
            break;
        case DT_FLOAT32:
            fill<float>(nim->data, values);
            break;
        case DT_FLOAT64:
            fill<double>(nim->data, values);
            break;
        default:
            std::memset(nim->data, 0, nim->nvox * nim->nbyper);
    }
    nim->dx = nim->pixdim[1] = s.pixdim[0];
    nim->dy = nim->pixdim[2] = s.pixdim[1];
    nim->dz = nim->pixdim[3] = s.pixdim[2];
    nim->scl_slope = s.slope;
    nim->scl_inter = s.inter;
    nim->qform_code = s.qform_code;
    nim->quatern_b = s.quatern[0], nim->quatern_c = s.quatern[1], nim->quatern_d = s.quatern[2];
    nim->qoffset_x = s.qoffset[0], nim->qoffset_y = s.qoffset[1], nim->qoffset_z = s.qoffset[2];
    nim->qfac = s.qfac;
    nim->sform_code = s.sform_code;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 4; ++c) nim->sto_xyz.m[r][c] = s.srow[r][c];
    }
    nim->xyz_units = s.xyz_units;
    ASSERT_EQ(nifti_set_filenames(nim, path.c_str(), 0, 1), 0);
    nifti_image_write(nim);
    nifti_image_free(nim);
}

std::vector<double> ramp(std::size_t count, double start, double step) {
    std::vector<double> v(count);
    for (std::size_t n = 0; n < count; ++n) v[n] = start + step * double(n);
    return v;
}

template <typename T>
void patch(const std::string& path, std::streamoff offset, T value) {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(offset);
    f.write(reinterpret_cast<const char*>(&value), sizeof value);
}

// ---- round trips --------------------------------------------------------------------

struct DatatypeCase {
    int datatype;
    double start, step;  // stored values start + step*n, exactly representable
};

class NiftiDatatypes : public ::testing::TestWithParam<DatatypeCase> {};

TEST_P(NiftiDatatypes, RoundTripIsExactForNiiAndNiiGz) {
    ScratchDir dir;
    const DatatypeCase c = GetParam();
    NiftiSpec spec;
    spec.datatype = c.datatype;
    const std::vector<double> values = ramp(24, c.start, c.step);
    for (const char* name : {"v.nii", "v.nii.gz"}) {
        const std::string path = dir / name;
        write_with_niftilib(path, spec, values);
        const Volume v = read_nifti(path).volume;
        ASSERT_EQ(v.dims(), glm::ivec3(4, 3, 2));
        for (std::size_t n = 0; n < values.size(); ++n) {
            ASSERT_EQ(double(v.voxels()[n]), double(float(values[n]))) << name << " voxel " << n;
        }
    }
}

INSTANTIATE_TEST_SUITE_P(
    AllScalarTypes, NiftiDatatypes,
    ::testing::Values(DatatypeCase{DT_UINT8, 0, 10}, DatatypeCase{DT_INT8, -100, 8},
                      DatatypeCase{DT_UINT16, 0, 2800}, DatatypeCase{DT_INT16, -30000, 2600},
                      DatatypeCase{DT_UINT32, 0, 100000}, DatatypeCase{DT_INT32, -1000000, 80000},
                      DatatypeCase{DT_UINT64, 0, 4096}, DatatypeCase{DT_INT64, -40960, 4096},
                      DatatypeCase{DT_FLOAT32, -1.5, 0.25}, DatatypeCase{DT_FLOAT64, -3.0, 0.125}));

TEST(NiftiIo, OurWriterRoundTripsVoxelsAndGeometry) {
    ScratchDir dir;
    VolumeGeometry g;
    g.dims = {5, 4, 3};
    g.spacing = {0.5, 1.25, 2.0};
    g.origin = {-10.0, 3.5, 7.25};
    const double a = glm::radians(30.0);  // rotation about z
    g.direction = glm::dmat3(glm::dvec3(std::cos(a), std::sin(a), 0),
                             glm::dvec3(-std::sin(a), std::cos(a), 0), glm::dvec3(0, 0, 1));
    Volume v(g);
    for (std::size_t n = 0; n < v.size(); ++n) v.voxels()[n] = float(n) * 0.75f - 4.0f;
    write_nifti(v, dir / "w.nii.gz");
    const Volume r = read_nifti(dir / "w.nii.gz").volume;
    EXPECT_EQ(r.voxels(), v.voxels());
    for (const glm::dvec3 ijk : {glm::dvec3(0, 0, 0), glm::dvec3(4, 3, 2), glm::dvec3(1, 2, 0)}) {
        const glm::dvec3 expected = g.index_to_world(ijk), got = r.geometry().index_to_world(ijk);
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], expected[k], 1e-5);  // float32 sform
    }
}

// ---- header transforms and scaling ---------------------------------------------------

TEST(NiftiIo, AppliesSclSlopeAndInter) {
    ScratchDir dir;
    NiftiSpec spec;
    spec.datatype = DT_UINT8;
    spec.slope = 0.5f;
    spec.inter = -10.0f;
    const auto stored = ramp(24, 0, 10);
    write_with_niftilib(dir / "s.nii", spec, stored);
    const Volume v = read_nifti(dir / "s.nii").volume;
    for (std::size_t n = 0; n < stored.size(); ++n)
        EXPECT_EQ(v.voxels()[n], float(0.5 * stored[n] - 10.0));
}

TEST(NiftiIo, QformRotationPixdimOffsetAndQfac) {
    ScratchDir dir;
    NiftiSpec spec;
    spec.qform_code = NIFTI_XFORM_SCANNER_ANAT;
    // Quaternion (a, b, c, d) = (cos 45, 0, 0, sin 45): 90 degrees about z, x -> y.
    spec.quatern[2] = float(std::sin(M_PI / 4));
    spec.qoffset[0] = 10, spec.qoffset[1] = 20, spec.qoffset[2] = 30;
    spec.pixdim[0] = 2, spec.pixdim[1] = 3, spec.pixdim[2] = 4;
    for (float qfac : {1.0f, -1.0f}) {
        spec.qfac = qfac;
        write_with_niftilib(dir / "q.nii", spec, ramp(24, 0, 1));
        const VolumeGeometry g = read_nifti(dir / "q.nii").volume.geometry();
        auto near = [](glm::dvec3 a, glm::dvec3 b) { return glm::length(a - b) < 1e-5; };
        EXPECT_TRUE(near(g.index_to_world({0, 0, 0}), {10, 20, 30}));
        EXPECT_TRUE(near(g.index_to_world({1, 0, 0}), {10, 22, 30}));  // R*(2,0,0) = (0,2,0)
        EXPECT_TRUE(near(g.index_to_world({0, 1, 0}), {7, 20, 30}));   // R*(0,3,0) = (-3,0,0)
        EXPECT_TRUE(near(g.index_to_world({0, 0, 1}), {10, 20, 30 + 4 * qfac}));
        EXPECT_NEAR(g.spacing.x, 2.0, 1e-6);
        EXPECT_NEAR(g.spacing.z, 4.0, 1e-6);
        // world -> index is the exact inverse.
        const glm::dvec3 back = g.world_to_index(g.index_to_world({1.5, 0.25, 1.0}));
        EXPECT_NEAR(back.x, 1.5, 1e-9);
        EXPECT_NEAR(back.y, 0.25, 1e-9);
        EXPECT_NEAR(back.z, 1.0, 1e-9);
    }
}

TEST(NiftiIo, SformTakesPrecedenceOverQform) {
    ScratchDir dir;
    NiftiSpec spec;
    spec.qform_code = 1;
    spec.qoffset[0] = 100;
    spec.sform_code = 2;
    // Sheared sform: column j has an x component.
    float srow[3][4] = {{2, 0.5f, 0, -5}, {0, 1, 0, 6}, {0, 0, 3, 7}};
    std::memcpy(spec.srow, srow, sizeof srow);
    write_with_niftilib(dir / "s.nii", spec, ramp(24, 0, 1));
    const VolumeGeometry g = read_nifti(dir / "s.nii").volume.geometry();
    const glm::dvec3 p = g.index_to_world({1, 2, 1});
    EXPECT_NEAR(p.x, 2 * 1 + 0.5 * 2 - 5, 1e-6);
    EXPECT_NEAR(p.y, 2 + 6, 1e-6);
    EXPECT_NEAR(p.z, 3 + 7, 1e-6);
}

TEST(NiftiIo, WithoutTransformsUsesPixdimAndWarns) {
    ScratchDir dir;
    NiftiSpec spec;
    spec.pixdim[0] = 0.7f;
    write_with_niftilib(dir / "n.nii", spec, ramp(24, 0, 1));
    const NiftiReadResult r = read_nifti(dir / "n.nii");
    EXPECT_NEAR(r.volume.geometry().index_to_world({2, 1, 1}).x, 1.4, 1e-6);
    EXPECT_EQ(r.volume.geometry().origin, glm::dvec3(0.0));
    ASSERT_EQ(r.warnings.size(), 1u);
}

TEST(NiftiIo, ConvertsMetresAndMicronsToMillimetres) {
    ScratchDir dir;
    NiftiSpec spec;
    spec.qform_code = 1;
    spec.pixdim[0] = spec.pixdim[1] = spec.pixdim[2] = 0.002f;  // 2 mm in metres
    spec.xyz_units = NIFTI_UNITS_METER;
    write_with_niftilib(dir / "m.nii", spec, ramp(24, 0, 1));
    EXPECT_NEAR(read_nifti(dir / "m.nii").volume.geometry().spacing.x, 2.0, 1e-5);
    spec.pixdim[0] = spec.pixdim[1] = spec.pixdim[2] = 500.0f;  // 0.5 mm in microns
    spec.xyz_units = NIFTI_UNITS_MICRON;
    write_with_niftilib(dir / "u.nii", spec, ramp(24, 0, 1));
    EXPECT_NEAR(read_nifti(dir / "u.nii").volume.geometry().spacing.y, 0.5, 1e-6);
}

TEST(NiftiIo, FourDimensionalFileKeepsFirstVolumeAndWarns) {
    ScratchDir dir;
    NiftiSpec spec;
    spec.nt = 3;
    write_with_niftilib(dir / "t.nii", spec, ramp(72, 0, 1));
    const NiftiReadResult r = read_nifti(dir / "t.nii");
    ASSERT_EQ(r.volume.size(), 24u);
    EXPECT_EQ(r.volume.voxels().back(), 23.0f);
    ASSERT_FALSE(r.warnings.empty());
    EXPECT_NE(r.warnings[0].find("only the first 3D volume"), std::string::npos) << r.warnings[0];
}

TEST(NiftiIo, DefaultColin27LoadsWithMniGeometry) {
    // Colin27 as shipped by mricron-data: 181x217x181 at 1 mm, MNI origin (-90,-126,-72).
    const LoadedVolume v = load_volume({kDefaultVolumeName, std::nullopt});
    EXPECT_EQ(v.volume.dims(), glm::ivec3(181, 217, 181));
    EXPECT_NEAR(v.volume.geometry().spacing.x, 1.0, 1e-6);
    // MNI (0,0,0) (the anterior commissure) lies inside the volume, near its centre.
    const glm::dvec3 ac = v.volume.geometry().world_to_index({0, 0, 0});
    EXPECT_NEAR(ac.x, 90, 1.5);
    EXPECT_GT(ac.y, 100);
    EXPECT_LT(ac.y, 130);
}

// ---- bad input -------------------------------------------------------------------------

TEST(NiftiErrors, MissingFile) {
    expect_input_error([] { read_nifti("/nonexistent/head.nii.gz"); }, "/nonexistent/head.nii.gz",
                       "", "not found");
}

TEST(NiftiErrors, TruncatedDataUncompressedAndCompressed) {
    ScratchDir dir;
    NiftiSpec spec;
    spec.nx = spec.ny = spec.nz = 16;
    write_with_niftilib(dir / "t.nii", spec, ramp(4096, 0, 1));
    std::filesystem::resize_file(dir / "t.nii", 352 + 4096 * 2);  // half the data
    expect_input_error([&] { read_nifti(dir / "t.nii"); }, "t.nii", "data", "truncated");

    // The same truncated bytes, gzip-compressed.
    std::ifstream in(dir / "t.nii", std::ios::binary);
    std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
    gzFile gz = gzopen((dir / "t.nii.gz").c_str(), "wb");
    gzwrite(gz, bytes.data(), unsigned(bytes.size()));
    gzclose(gz);
    expect_input_error([&] { read_nifti(dir / "t.nii.gz"); }, "t.nii.gz", "data", "truncated");

    // A header declaring 1000^3 float voxels in an 8.5 kB file is refused before 4 GB are
    // allocated (dim[1..3] are int16 at bytes 42-47).
    {
        std::fstream f(dir / "t.nii", std::ios::binary | std::ios::in | std::ios::out);
        const int16_t dims[3] = {1000, 1000, 1000};
        f.seekp(42);
        f.write(reinterpret_cast<const char*>(dims), sizeof dims);
    }
    expect_input_error([&] { read_nifti(dir / "t.nii"); }, "t.nii", "data",
                       "dim declares 4e+09 voxel bytes");
}

// vox_offset (a float at byte 108) out of an int's range wraps in niftilib's conversion;
// a wrapped negative offset made any declared size seem to fit, and the reader allocated
// it before failing (a 362-byte fuzz input declaring 400 MB). Refused, naming vox_offset,
// before the voxels are allocated.
TEST(NiftiErrors, AVoxelOffsetOutsideTheFileIsRefused) {
    ScratchDir dir;
    NiftiSpec spec;
    spec.nx = spec.ny = spec.nz = 8;
    // Without the magic (an ANALYZE 7.5 header, as niftilib reads it) the offset is taken
    // as it is; with it, niftilib mends offsets below the header but not those beyond.
    for (const auto& [offset, analyze] :
         {std::pair{7.9e34f, true}, std::pair{-4096.0f, true}, std::pair{1e6f, false}}) {
        write_with_niftilib(dir / "o.nii", spec, ramp(512, 0, 1));
        patch<float>(dir / "o.nii", 108, offset);
        if (analyze) patch<int32_t>(dir / "o.nii", 344, 0);
        expect_input_error([&] { read_nifti(dir / "o.nii"); }, "o.nii", "vox_offset", "outside");
    }
}

TEST(NiftiErrors, TruncatedHeaderAndGarbage) {
    ScratchDir dir;
    std::ofstream(dir / "short.nii") << "too short";
    expect_input_error([&] { read_nifti(dir / "short.nii"); }, "short.nii", "sizeof_hdr",
                       "truncated header");
    std::ofstream garbage(dir / "garbage.nii", std::ios::binary);
    for (int n = 0; n < 1000; ++n) garbage.put(char(n * 37 + 11));
    garbage.close();
    expect_input_error([&] { read_nifti(dir / "garbage.nii"); }, "garbage.nii", "sizeof_hdr",
                       "not a NIfTI-1");
}

TEST(NiftiErrors, Nifti2IsNamed) {
    ScratchDir dir;
    write_with_niftilib(dir / "n2.nii", NiftiSpec{}, ramp(24, 0, 1));
    patch<int32_t>(dir / "n2.nii", 0, 540);
    expect_input_error([&] { read_nifti(dir / "n2.nii"); }, "n2.nii", "sizeof_hdr", "NIfTI-2");
}

TEST(NiftiErrors, UnsupportedDatatypes) {
    ScratchDir dir;
    for (int datatype : {DT_COMPLEX64, DT_RGB24, DT_FLOAT128}) {
        NiftiSpec spec;
        spec.datatype = datatype;
        std::string name = "datatype_";  // built stepwise: GCC 12 warns falsely on a + b + c
        name += std::to_string(datatype);
        name += ".nii";
        const std::string path = dir / name;
        write_with_niftilib(path, spec, ramp(24, 0, 0));
        expect_input_error([&] { read_nifti(path); }, path, "datatype", "unsupported datatype");
    }
}

TEST(NiftiErrors, ZeroAndNegativeSpacing) {
    ScratchDir dir;
    for (float bad : {0.0f, -1.0f, std::numeric_limits<float>::quiet_NaN()}) {
        write_with_niftilib(dir / "p.nii", NiftiSpec{}, ramp(24, 0, 1));
        patch<float>(dir / "p.nii", 76 + 4 * 2, bad);  // pixdim[2]
        expect_input_error([&] { read_nifti(dir / "p.nii"); }, "p.nii", "pixdim[2]", "spacing");
    }
}

TEST(NiftiErrors, DimensionsBeyondAvailableMemory) {
    ScratchDir dir;
    write_with_niftilib(dir / "big.nii", NiftiSpec{}, ramp(24, 0, 1));
    for (int d = 1; d <= 3; ++d)
        patch<int16_t>(dir / "big.nii", 40 + 2 * d, 32000);  // 3.3e13 voxels
    expect_input_error([&] { read_nifti(dir / "big.nii"); }, "big.nii", "dim", "memory");
}

TEST(NiftiErrors, NanAndInfVoxelsAreNamed) {
    ScratchDir dir;
    for (double bad :
         {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
        auto values = ramp(24, 0, 1);
        values[1 + 4 * 2] = bad;  // voxel (1, 2, 0)
        write_with_niftilib(dir / "nan.nii", NiftiSpec{}, values);
        expect_input_error([&] { read_nifti(dir / "nan.nii"); }, "nan.nii", "data", "(1, 2, 0)");
    }
}

}  // namespace
}  // namespace sonotrace::tissue
