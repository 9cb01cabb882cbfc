#include "tissue/raw_io.h"

#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/file_status.h"
#include "tissue/base/json_util.h"
#include "tissue/base/memory.h"

namespace sonotrace::tissue {

namespace {

namespace fs = std::filesystem;

struct RawType {
    const char* name;
    int bytes;
    bool is_float, is_signed;
};
constexpr RawType kRawTypes[] = {
    {"uint8", 1, false, false}, {"int8", 1, false, true},    {"uint16", 2, false, false},
    {"int16", 2, false, true},  {"uint32", 4, false, false}, {"int32", 4, false, true},
    {"float32", 4, true, true}, {"float64", 8, true, true},
};

double decode(const unsigned char* p, const RawType& type, bool swap) {
    unsigned char b[8];
    for (int n = 0; n < type.bytes; ++n) b[n] = swap ? p[type.bytes - 1 - n] : p[n];
    auto as = [&](auto zero) {
        decltype(zero) v;
        std::memcpy(&v, b, sizeof v);
        return double(v);
    };
    if (type.is_float) return type.bytes == 4 ? as(0.0f) : as(0.0);
    switch (type.bytes) {
        case 1:
            return type.is_signed ? as(int8_t()) : as(uint8_t());
        case 2:
            return type.is_signed ? as(int16_t()) : as(uint16_t());
        default:
            return type.is_signed ? as(int32_t()) : as(uint32_t());
    }
}

}  // namespace

Volume read_raw(const std::string& path) {
    fs::path sidecar(path);
    if (sidecar.extension() != ".json") sidecar.replace_extension(".json");
    const std::string source = sidecar.string();
    if (!fs::exists(base::file_status(sidecar, source, ""))) {
        throw base::InputError(source, "",
                               "raw volumes need a JSON sidecar describing them; not found");
    }
    const auto j = base::jsonio::read_file(source);
    base::jsonio::require_known_keys(j,
                                     {"file", "dims", "spacing", "origin", "direction", "datatype",
                                      "byte_order", "header_bytes"},
                                     source, "");
    VolumeGeometry g;
    const glm::dvec3 dims = base::jsonio::get_vec3(j, "dims", source, "");
    for (int a = 0; a < 3; ++a) {
        if (dims[a] < 1 || dims[a] != std::floor(dims[a]) || dims[a] > 1e6) {
            throw base::InputError(source, "dims", "must be three positive integers");
        }
    }
    g.dims = glm::ivec3(dims);
    g.spacing = base::jsonio::get_vec3(j, "spacing", source, "");
    if (j.contains("origin")) g.origin = base::jsonio::get_vec3(j, "origin", source, "");
    if (j.contains("direction")) {
        const auto& d = j.at("direction");
        if (!d.is_array() || d.size() != 3) {
            throw base::InputError(source, "direction", "must be an array of three 3-vectors");
        }
        for (int c = 0; c < 3; ++c) {
            nlohmann::json wrapper = {{"axis", d[c]}};
            g.direction[c] =
                glm::normalize(base::jsonio::get_vec3(wrapper, "axis", source, "direction"));
        }
    }
    g.validate(source);

    const std::string type_name = base::jsonio::get_string(j, "datatype", source, "");
    const RawType* type = nullptr;
    for (const RawType& t : kRawTypes) type = type_name == t.name ? &t : type;
    if (!type) {
        throw base::InputError(
            source, "datatype",
            "unknown datatype '" + type_name +
                "' (use uint8, int8, uint16, int16, uint32, int32, float32, float64)");
    }
    const std::string order =
        j.contains("byte_order") ? base::jsonio::get_string(j, "byte_order", source, "") : "little";
    if (order != "little" && order != "big") {
        throw base::InputError(source, "byte_order", "must be \"little\" or \"big\"");
    }
    const bool swap = (order == "big") != (std::endian::native == std::endian::big);
    const auto header_bytes = std::size_t(
        base::jsonio::get_optional_number(j, "header_bytes", source, "", 0, 1e12).value_or(0));

    fs::path raw = sidecar.parent_path() / (j.contains("file")
                                                ? base::jsonio::get_string(j, "file", source, "")
                                                : sidecar.stem().string() + ".raw");
    const fs::file_status raw_status = base::file_status(raw, source, "file");
    if (!fs::exists(raw_status))
        throw base::InputError(raw.string(), "", "raw data file not found");
    // A directory (an empty "file" names the sidecar's own) or a device has no size to check.
    if (!fs::is_regular_file(raw_status))
        throw base::InputError(source, "file",
                               "'" + raw.string() + "' is not a regular file of voxel data");
    const std::size_t expected = header_bytes + g.voxel_count() * std::size_t(type->bytes);
    const std::size_t actual = fs::file_size(raw);
    if (actual < expected) {
        throw base::InputError(raw.string(), "size",
                               "file is truncated: " + std::to_string(actual) +
                                   " bytes, the sidecar " + source + " describes " +
                                   std::to_string(expected));
    }
    std::ifstream in(raw, std::ios::binary);
    in.seekg(std::streamoff(header_bytes));
    std::vector<unsigned char> bytes(g.voxel_count() * std::size_t(type->bytes));
    in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size()));
    if (!in) throw base::InputError(raw.string(), "", "read error");

    Voxels voxels(g.voxel_count());
    for (std::size_t n = 0; n < voxels.size(); ++n) {
        voxels[n] = float(decode(bytes.data() + n * type->bytes, *type, swap));
    }
    Volume volume(g, std::move(voxels));
    volume.require_finite(raw.string());
    return volume;
}

void write_raw(const Volume& volume, const std::string& raw_path) {
    const VolumeGeometry& g = volume.geometry();
    fs::path sidecar(raw_path);
    sidecar.replace_extension(".json");
    base::OutputTransaction transaction;
    base::write_file(transaction.stage(raw_path), volume.voxels().data(),
                     volume.size() * sizeof(float));
    nlohmann::json j = {
        {"file", fs::path(raw_path).filename().string()},
        {"dims", {g.dims.x, g.dims.y, g.dims.z}},
        {"spacing", {g.spacing.x, g.spacing.y, g.spacing.z}},
        {"origin", {g.origin.x, g.origin.y, g.origin.z}},
        {"direction", nlohmann::json::array()},
        {"datatype", "float32"},
        {"byte_order", std::endian::native == std::endian::little ? "little" : "big"},
    };
    for (int c = 0; c < 3; ++c) {
        j["direction"].push_back({g.direction[c].x, g.direction[c].y, g.direction[c].z});
    }
    const std::string text = j.dump(2) + "\n";
    base::write_file(transaction.stage(sidecar.string()), text.data(), text.size());
    transaction.commit();
}

}  // namespace sonotrace::tissue
