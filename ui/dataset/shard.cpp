#include "ui/dataset/shard.h"

#include "ui/dataset/hdf5_writer.h"

#include <hdf5.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string_view>

#include "sonotrace_version.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/file_read.h"
#include "tissue/base/hash.h"
#include "tissue/base/isolated.h"

namespace sonotrace::dataset {

using hdf5::Handle;
using hdf5::kImageName;

namespace {

// One row of /frames; zeroed before filling so the padding is the same every time.
struct FrameRow {
    uint64_t index, seed;
    int32_t source;
    char probe[16];
    double frequency_mhz, depth_mm, focus_mm, gain_db, dynamic_range_db;
    double position[3], lateral[3], axial[3], elevation[3];
    double pixel_mm, origin_mm[2];
    int32_t valid_width, valid_height;
};

// The /frames row type in memory and, packed, in the file: a FrameRow, then a double per
// drawn value (the spec's drawn_values, named as they are).
hid_t frame_row_type(const std::vector<DrawnValue>& drawn) {
    const hid_t t = H5Tcreate(H5T_COMPOUND, sizeof(FrameRow) + drawn.size() * sizeof(double));
    const hsize_t three = 3, two = 2;
    const hid_t vec3 = H5Tarray_create2(H5T_NATIVE_DOUBLE, 1, &three);
    const hid_t vec2 = H5Tarray_create2(H5T_NATIVE_DOUBLE, 1, &two);
    const hid_t name = H5Tcopy(H5T_C_S1);
    H5Tset_size(name, sizeof(FrameRow::probe));
    H5Tinsert(t, "index", HOFFSET(FrameRow, index), H5T_NATIVE_UINT64);
    H5Tinsert(t, "seed", HOFFSET(FrameRow, seed), H5T_NATIVE_UINT64);
    H5Tinsert(t, "source", HOFFSET(FrameRow, source), H5T_NATIVE_INT32);
    H5Tinsert(t, "probe", HOFFSET(FrameRow, probe), name);
    H5Tinsert(t, "frequency_mhz", HOFFSET(FrameRow, frequency_mhz), H5T_NATIVE_DOUBLE);
    H5Tinsert(t, "depth_mm", HOFFSET(FrameRow, depth_mm), H5T_NATIVE_DOUBLE);
    H5Tinsert(t, "focus_mm", HOFFSET(FrameRow, focus_mm), H5T_NATIVE_DOUBLE);
    H5Tinsert(t, "gain_db", HOFFSET(FrameRow, gain_db), H5T_NATIVE_DOUBLE);
    H5Tinsert(t, "dynamic_range_db", HOFFSET(FrameRow, dynamic_range_db), H5T_NATIVE_DOUBLE);
    H5Tinsert(t, "position", HOFFSET(FrameRow, position), vec3);
    H5Tinsert(t, "lateral", HOFFSET(FrameRow, lateral), vec3);
    H5Tinsert(t, "axial", HOFFSET(FrameRow, axial), vec3);
    H5Tinsert(t, "elevation", HOFFSET(FrameRow, elevation), vec3);
    H5Tinsert(t, "pixel_mm", HOFFSET(FrameRow, pixel_mm), H5T_NATIVE_DOUBLE);
    H5Tinsert(t, "origin_mm", HOFFSET(FrameRow, origin_mm), vec2);
    H5Tinsert(t, "valid_width", HOFFSET(FrameRow, valid_width), H5T_NATIVE_INT32);
    H5Tinsert(t, "valid_height", HOFFSET(FrameRow, valid_height), H5T_NATIVE_INT32);
    for (std::size_t k = 0; k < drawn.size(); ++k)
        H5Tinsert(t, drawn[k].name.c_str(), sizeof(FrameRow) + k * sizeof(double),
                  H5T_NATIVE_DOUBLE);
    H5Tclose(vec3);
    H5Tclose(vec2);
    H5Tclose(name);
    return t;
}

void copy3(double* to, const glm::dvec3& v) {
    to[0] = v.x, to[1] = v.y, to[2] = v.z;
}

}  // namespace

void write_shard(const std::string& path, const std::string& output_name, const Spec& spec,
                 uint64_t shard, const std::vector<DatasetFrame>& frames) {
    hdf5::ImageWriter w(output_name, kShardHeaderBytes);
    const hsize_t n = frames.size(), h = hsize_t(spec.height), wd = hsize_t(spec.width);
    // A frame-stacked [n, H, W] dataset of the frames' images (memory_type's pixels).
    auto stack = [&](const char* name, cv::Mat DatasetFrame::*image, hid_t file_type,
                     hid_t memory_type) {
        const std::size_t row = wd * H5Tget_size(memory_type);
        std::vector<uint8_t> pixels(n * h * row);
        for (std::size_t f = 0; f < frames.size(); ++f) {
            const cv::Mat& m = frames[f].*image;
            if (m.elemSize() != H5Tget_size(memory_type)) throw std::logic_error(name);
            for (int y = 0; y < spec.height; ++y)
                std::memcpy(&pixels[(f * h + hsize_t(y)) * row], m.ptr<uint8_t>(y), row);
        }
        w.dataset(w.file(), name, file_type, memory_type, {n, h, wd}, {1, h, wd}, pixels.data());
    };
    const auto u8 = std::pair{H5T_STD_U8LE, H5T_NATIVE_UINT8};
    if (spec.write_bmode) stack("bmode", &DatasetFrame::bmode, u8.first, u8.second);
    if (spec.write_labels) stack("labels", &DatasetFrame::labels, u8.first, u8.second);
    if (spec.write_echo_labels)
        stack("labels_echo", &DatasetFrame::echo_labels, u8.first, u8.second);
    if (spec.write_depth)
        stack("depth", &DatasetFrame::true_depth, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT);
    if (spec.write_echogenicity)
        stack("echogenicity", &DatasetFrame::echogenicity, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT);
    if (spec.write_instances)
        stack("instances", &DatasetFrame::instances, H5T_STD_U16LE, H5T_NATIVE_UINT16);

    const std::vector<DrawnValue> names =
        frames.empty() ? std::vector<DrawnValue>{} : drawn_values(spec, frames.front().draw);
    const std::size_t row_bytes = sizeof(FrameRow) + names.size() * sizeof(double);
    std::vector<unsigned char> rows(frames.size() * row_bytes, 0);  // padding zero, as every time
    for (std::size_t f = 0; f < frames.size(); ++f) {
        const DatasetFrame& fr = frames[f];
        FrameRow r;
        std::memset(&r, 0, sizeof r);
        r.index = fr.draw.index;
        r.seed = fr.draw.seed;
        r.source = fr.draw.source;
        std::snprintf(r.probe, sizeof r.probe, "%s", fr.transducer.name.c_str());
        r.frequency_mhz = fr.transducer.frequency_mhz;
        r.depth_mm = fr.transducer.depth_mm;
        r.focus_mm = fr.transducer.focus_mm;
        r.gain_db = fr.gain_db;
        r.dynamic_range_db = fr.draw.dynamic_range_db;
        copy3(r.position, fr.pose.position);
        copy3(r.lateral, fr.pose.lateral());
        copy3(r.axial, fr.pose.axial());
        copy3(r.elevation, fr.pose.elevation());
        r.pixel_mm = fr.pixel_mm;
        r.origin_mm[0] = fr.origin_mm.x;
        r.origin_mm[1] = fr.origin_mm.y;
        r.valid_width = fr.valid_width;
        r.valid_height = fr.valid_height;
        std::memcpy(&rows[f * row_bytes], &r, sizeof r);
        const std::vector<DrawnValue> drawn = drawn_values(spec, fr.draw);
        for (std::size_t k = 0; k < drawn.size(); ++k)
            std::memcpy(&rows[f * row_bytes + sizeof r + k * sizeof(double)], &drawn[k].value,
                        sizeof(double));
    }
    {
        Handle memory(frame_row_type(names), H5Tclose);
        Handle packed(H5Tcopy(memory), H5Tclose);
        H5Tpack(packed);
        w.dataset(w.file(), "frames", packed, memory, {n}, {}, rows.data());
    }
    auto per_frame = [&](const char* group, auto&& data_of) {
        Handle g(w.group(group), H5Gclose);
        for (const DatasetFrame& fr : frames) {
            const auto [values, rows_count, cols] = data_of(fr);
            char name[32];
            std::snprintf(name, sizeof name, "%08llu",
                          static_cast<unsigned long long>(fr.draw.index));
            const std::vector<hsize_t> dims = {hsize_t(rows_count), hsize_t(cols)};
            const bool empty = rows_count == 0 || cols == 0;  // chunks must not be empty
            w.dataset(g, name, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, dims,
                      empty ? std::vector<hsize_t>{} : dims, values);
        }
    };
    struct Array {
        const float* values;
        int rows, cols;
    };
    if (spec.write_envelope)
        per_frame("envelope", [](const DatasetFrame& f) {
            return Array{f.envelope.values.data(), f.envelope.lines, f.envelope.samples};
        });
    if (spec.write_rf)
        per_frame("rf", [](const DatasetFrame& f) {
            return Array{f.rf.values.data(), f.rf.lines, f.rf.samples};
        });
    if (spec.write_channels) {
        // Each frame's channels with what beamforming them needs beyond the frame table
        // (its probe and frequency) and the spec's "transmit" (docs/guide/channel-data.md),
        // and its elements' places and normals (a convex array's lie on its arc).
        Handle g(w.group("channels"), H5Gclose);
        Handle elements(w.group("channel_elements"), H5Gclose);
        for (const DatasetFrame& fr : frames) {
            const imaging::ChannelData& c = *fr.channels;
            char name[32];
            std::snprintf(name, sizeof name, "%08llu",
                          static_cast<unsigned long long>(fr.draw.index));
            const std::vector<hsize_t> dims = {hsize_t(c.transmits), hsize_t(c.elements),
                                               hsize_t(c.samples)};
            w.dataset(g, name, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, dims, {1, dims[1], dims[2]},
                      c.values.data(), true,
                      {{"sampling_frequency_hz", c.fs_hz},
                       {"start_time_s", c.start_s},
                       {"speed_of_sound_m_s", c.speed_m_s},
                       {"centre_frequency_hz", c.frequency_hz},
                       {"pitch_mm", c.pitch_mm}});
            std::vector<double> places;
            for (const probe::ArrayPoint& e : c.element_points)
                places.insert(places.end(), {e.position.x, e.position.y, e.normal.x, e.normal.y});
            w.dataset(elements, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {hsize_t(c.elements), 4},
                      {}, places.data());
        }
    }
    if (spec.write_energy)
        per_frame("energy", [](const DatasetFrame& f) {
            return Array{f.energy.voxels().data(), f.energy.dims().y, f.energy.dims().x};
        });

    w.attribute("spec", spec.canonical);
    w.attribute("spec_digest", spec.digest());
    w.attribute("shard", shard);
    w.attribute("first_frame", frames.empty() ? 0 : frames.front().draw.index);
    w.attribute("frame_count", uint64_t(frames.size()));
    w.attribute("version", std::string(SONOTRACE_VERSION));
    // HDF5's image starts at its superblock; the user block it reserved goes before it.
    std::string bytes(kShardHeaderBytes, '\0');
    bytes += w.image();
    const std::string header = shard_header(spec.digest(), shard, content_checksum(bytes));
    std::copy(header.begin(), header.end(), bytes.begin());
    base::write_file(path, bytes.data(), bytes.size(), base::Durability::synced);
}

uint64_t content_checksum(const std::string& file) {
    uint64_t h = 0x73686172642d6331ull;
    std::size_t at = std::min<std::size_t>(kShardHeaderBytes, file.size());
    for (; at + 8 <= file.size(); at += 8) {
        uint64_t word;
        std::memcpy(&word, file.data() + at, 8);
        h = base::mix64(h ^ word);
    }
    for (; at < file.size(); ++at) h = base::mix64(h ^ uint8_t(file[at]));
    return base::mix64(h ^ file.size());
}

std::string shard_header(uint64_t spec_digest, uint64_t shard, uint64_t checksum) {
    char text[kShardHeaderBytes] = {};
    std::snprintf(text, sizeof text,
                  "sonotrace shard\nspec_digest %016llx\nshard %llu\ncontent_checksum %016llx\n",
                  static_cast<unsigned long long>(spec_digest),
                  static_cast<unsigned long long>(shard),
                  static_cast<unsigned long long>(checksum));
    return std::string(text, sizeof text);
}

std::optional<ShardHeader> parse_shard_header(std::string_view head) {
    if (head.size() < kShardHeaderBytes) return std::nullopt;
    // NUL padded; a damaged header without a NUL must not be read past its end.
    const std::string text(head.data(), strnlen(head.data(), kShardHeaderBytes));
    unsigned long long digest = 0, index = 0, checksum = 0;
    if (std::sscanf(text.c_str(),
                    "sonotrace shard\nspec_digest %16llx\nshard %llu\ncontent_checksum %16llx",
                    &digest, &index, &checksum) != 3 ||
        head.substr(0, kShardHeaderBytes) != shard_header(digest, index, checksum))
        return std::nullopt;
    return ShardHeader{digest, index, checksum};
}

ShardCheck check_shard_bytes(const std::string& bytes, std::optional<uint64_t> spec_digest,
                             std::optional<uint64_t> shard) {
    if (bytes.size() < kShardHeaderBytes) return {ShardCheck::damaged, "shorter than its header"};
    const std::optional<ShardHeader> header = parse_shard_header(bytes);
    if (!header) return {ShardCheck::damaged, "its header is damaged or missing"};
    if (spec_digest && header->spec_digest != *spec_digest)
        return {ShardCheck::foreign, "is a shard of another spec", *header};
    if (shard && header->shard != *shard)
        return {ShardCheck::damaged,
                "holds shard " + std::to_string(header->shard) + ", not shard " +
                    std::to_string(*shard),
                *header};
    if (content_checksum(bytes) != header->content_checksum)
        return {ShardCheck::damaged, "its content does not match its checksum", *header};
    return {ShardCheck::ok, "", *header};
}

ShardCheck check_shard(const std::string& path, uint64_t spec_digest, uint64_t shard) {
    return check_shard_bytes(base::read_regular_file(path, kMaxShardBytes), spec_digest, shard);
}

namespace {

// Reads every dataset and root attribute of a shard image with HDF5, checking first what
// each declares against what the file can hold: nullopt if all of it reads, else why not.
std::optional<std::string> read_every_part(const std::string& bytes) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    const double largest = kShardReadExpansion * double(bytes.size()) + double(1 << 20);
    Handle fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
    H5Pset_fapl_core(fapl, std::size_t(1) << 20, false);
    // HDF5 copies the image (its callbacks are not set): the bytes stay ours.
    if (H5Pset_file_image(fapl, const_cast<char*>(bytes.data()), bytes.size()) < 0)
        return "HDF5 refused its image";
    Handle file(H5Fopen(kImageName, H5F_ACC_RDONLY, fapl), H5Fclose);
    if (!file.ok()) return "HDF5 cannot open it";
    struct Visit {
        double largest;
        std::optional<std::string> why;
    } visit{largest, std::nullopt};
    auto each = [](hid_t root, const char* name, const H5O_info_t* info, void* data) -> herr_t {
        auto& v = *static_cast<Visit*>(data);
        if (info->type != H5O_TYPE_DATASET) return 0;
        const std::string where = std::string("dataset '") + name + "'";
        Handle dataset(H5Dopen2(root, name, H5P_DEFAULT), H5Dclose);
        Handle space(dataset.ok() ? H5Dget_space(dataset) : -1, H5Sclose);
        Handle type(dataset.ok() ? H5Dget_type(dataset) : -1, H5Tclose);
        Handle plist(dataset.ok() ? H5Dget_create_plist(dataset) : -1, H5Pclose);
        if (!space.ok() || !type.ok() || !plist.ok()) return v.why = where + " cannot be opened", 1;
        const int rank = H5Sget_simple_extent_ndims(space);
        const hssize_t points = H5Sget_simple_extent_npoints(space);
        const double size = double(H5Tget_size(type)), declared = double(points) * size;
        if (rank < 0 || points < 0 || !(size > 0.0) || declared > v.largest)
            return v.why = where + " declares more than the file can hold", 1;
        if (H5Pget_layout(plist) == H5D_CHUNKED) {
            // HDF5 allocates a whole chunk, and a selection per chunk it reads.
            hsize_t chunk[H5S_MAX_RANK];
            const int chunk_rank = H5Pget_chunk(plist, H5S_MAX_RANK, chunk);
            std::vector<hsize_t> dims(std::size_t(std::max(rank, 0)));
            H5Sget_simple_extent_dims(space, dims.data(), nullptr);
            if (chunk_rank != rank)
                return v.why = where + " has chunks of " + std::to_string(chunk_rank) +
                               " dimensions and a shape of " + std::to_string(rank),
                       1;
            double chunk_bytes = size, chunks = 1.0;
            for (int a = 0; a < rank; ++a) {
                const double extent = std::max(double(chunk[a]), 1.0);
                chunk_bytes *= extent;
                chunks *= std::ceil(double(dims[std::size_t(a)]) / extent);
            }
            if (chunk_bytes > v.largest || chunks > double(kMaxShardChunks))
                return v.why = where + " is stored in too many or too large chunks", 1;
        }
        std::vector<char> values(static_cast<std::size_t>(declared));
        if (H5Dread(dataset, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()) < 0)
            return v.why = where + " cannot be read", 1;
        return 0;
    };
    if (H5Ovisit2(file, H5_INDEX_NAME, H5_ITER_INC, each, &visit, H5O_INFO_BASIC) < 0 && !visit.why)
        return std::string("HDF5 cannot list its contents");
    if (visit.why) return visit.why;
    H5O_info_t root{};
    if (H5Oget_info2(file, &root, H5O_INFO_NUM_ATTRS) < 0)
        return std::string("HDF5 cannot list its attributes");
    for (hsize_t a = 0; a < root.num_attrs; ++a) {
        Handle attribute(
            H5Aopen_by_idx(file, ".", H5_INDEX_NAME, H5_ITER_INC, a, H5P_DEFAULT, H5P_DEFAULT),
            H5Aclose);
        Handle space(attribute.ok() ? H5Aget_space(attribute) : -1, H5Sclose);
        Handle type(attribute.ok() ? H5Aget_type(attribute) : -1, H5Tclose);
        if (!space.ok() || !type.ok()) return std::string("an attribute cannot be opened");
        const double declared =
            double(H5Sget_simple_extent_npoints(space)) * double(H5Tget_size(type));
        if (!(declared >= 0.0) || declared > largest)
            return std::string("an attribute declares more than the file can hold");
        std::vector<char> value(std::size_t(declared) + 1);
        if (H5Aread(attribute, type, value.data()) < 0)
            return std::string("an attribute cannot be read");
    }
    return std::nullopt;
}

}  // namespace

std::optional<std::string> unreadable_shard(const std::string& bytes) {
    // In a child: HDF5 crashes on some malformed files (a fuzzer's shard, its checksum
    // resealed, made h5py's read segfault), and a file declaring gigabytes would take them.
    return base::in_child_process([&] { return read_every_part(bytes); }, std::size_t(4) << 30);
}

ShardHeader read_shard_header(const std::string& path) {
    const std::optional<ShardHeader> header =
        parse_shard_header(base::read_regular_file_head(path, kShardHeaderBytes));
    if (!header) throw base::InputError(path, "", "has no sound shard header");
    return *header;
}

}  // namespace sonotrace::dataset
