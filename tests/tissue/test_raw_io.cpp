// Raw volumes with JSON sidecars: round trip, datatypes and byte order, and errors.
#include <gtest/gtest.h>

#include <fstream>

#include "tests/test_util.h"
#include "tissue/raw_io.h"
#include "tissue/volume_io.h"

namespace sonotrace::tissue {
namespace {

using test::expect_input_error;
using test::ScratchDir;

void write_text(const std::string& path, const std::string& text) {
    std::ofstream(path) << text;
}

TEST(RawIo, RoundTripWithGeometry) {
    ScratchDir dir;
    VolumeGeometry g;
    g.dims = {3, 2, 2};
    g.spacing = {0.5, 0.75, 1.5};
    g.origin = {1, 2, 3};
    g.direction = glm::dmat3(glm::dvec3(0, 1, 0), glm::dvec3(-1, 0, 0), glm::dvec3(0, 0, 1));
    Volume v(g);
    for (std::size_t n = 0; n < v.size(); ++n) v.voxels()[n] = float(n) - 5.5f;
    write_raw(v, dir / "v.raw");
    for (const char* name : {"v.raw", "v.json"}) {
        const Volume r = load_volume({dir / name, std::nullopt}).volume;
        EXPECT_EQ(r.voxels(), v.voxels());
        EXPECT_EQ(r.geometry().index_to_world({1, 1, 1}), g.index_to_world({1, 1, 1}));
    }
}

TEST(RawIo, BigEndianInt16WithHeaderBytes) {
    ScratchDir dir;
    // Two header bytes, then int16 big-endian values 1, -2, 300, -32768.
    const unsigned char bytes[] = {0xAA, 0xBB, 0x00, 0x01, 0xFF, 0xFE, 0x01, 0x2C, 0x80, 0x00};
    std::ofstream(dir / "b.raw", std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes), sizeof bytes);
    write_text(dir / "b.json", R"({"dims": [4, 1, 1], "spacing": [1, 1, 1], "datatype": "int16",
                                   "byte_order": "big", "header_bytes": 2})");
    EXPECT_EQ(read_raw(dir / "b.json").voxels(), Voxels({1, -2, 300, -32768}));
}

TEST(RawIoErrors, EachProblemNamesFileAndField) {
    ScratchDir dir;
    std::ofstream(dir / "d.raw", std::ios::binary) << std::string(8, '\0');
    const std::string json = dir / "d.json";
    auto check = [&](const std::string& text, const std::string& field, const std::string& what) {
        write_text(json, text);
        expect_input_error([&] { read_raw(json); }, "d.json", field, what);
    };
    check(R"({"dims": [2,2,1], "spacing": [1,1,1], "datatype": "uint8", "colour": 1})", "colour",
          "unknown key");
    check(R"({"dims": [2,2,1], "spacing": [1,0,1], "datatype": "uint8"})", "spacing[j]",
          "positive");
    check(R"({"dims": [2,2,1], "spacing": [1,-1,1], "datatype": "uint8"})", "spacing[j]",
          "positive");
    check(R"({"dims": [2,2,1], "spacing": [1,1,1], "datatype": "complex"})", "datatype",
          "unknown datatype");
    check(R"({"dims": [2,2], "spacing": [1,1,1], "datatype": "uint8"})", "dims", "3 numbers");
    check(R"({"dims": [2,2,1], "spacing": [1,1,1]})", "datatype", "required");
    check(R"({"dims": [2,2,1], "spacing": [1,1,1], "datatype": "uint8", "byte_order": "middle"})",
          "byte_order", "");
    check(R"({"dims": [2,2,1], "spacing": [1,1,1], "datatype": "uint8",)", "",
          "invalid JSON at line 1");
    check(R"({"dims": [90000,90000,90000], "spacing": [1,1,1], "datatype": "uint8"})", "dims",
          "memory");
    // Truncated data: 8 bytes present, 4 float32 voxels need 16.
    write_text(json, R"({"dims": [2,2,1], "spacing": [1,1,1], "datatype": "float32"})");
    expect_input_error([&] { read_raw(json); }, "d.raw", "size", "truncated");
    expect_input_error([&] { read_raw(dir / "nothing.raw"); }, "nothing.json", "", "sidecar");
    // Data that is not a regular file: an empty "file" names the sidecar's directory (a
    // fuzz finding: the size query threw a filesystem_error, an internal error).
    check(R"({"file": "", "dims": [2,2,1], "spacing": [1,1,1], "datatype": "uint8"})", "file",
          "not a regular file");
    // A name longer than the system allows (a fuzz finding: exists() threw
    // filesystem_error): refused naming the sidecar's field, with the system's reason.
    check(R"({"file": ")" + std::string(300, 'v') + R"(.raw", "dims": [2,2,1], "spacing": [1,1,1],
             "datatype": "uint8"})",
          "file", "File name too long");
}

}  // namespace
}  // namespace sonotrace::tissue
