#include "ui/dataset/dataset.h"

#include <cstdio>
#include <filesystem>

#include "sonotrace_version.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/file_status.h"
#include "tissue/base/json_util.h"
#include "tissue/base/memory.h"
#include "tissue/transfer_function.h"
#include "ui/dataset/frames.h"
#include "ui/dataset/shard.h"

namespace sonotrace::dataset {

std::string shard_path(const std::string& dir, uint64_t shard) {
    char name[32];
    std::snprintf(name, sizeof name, "shard_%05llu.h5", static_cast<unsigned long long>(shard));
    return (std::filesystem::path(dir) / name).string();
}

namespace {

std::string hex16(uint64_t value) {
    char text[24];
    std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(value));
    return text;
}

// The manifest of the shards in `dir`, each checked by this run or written by it: their
// checksums are read from their headers.
nlohmann::json manifest(const Spec& spec, const std::string& dir) {
    nlohmann::json shards = nlohmann::json::array(), sources = nlohmann::json::array();
    nlohmann::json checksums = nlohmann::json::object();
    for (uint64_t k = 0; k < spec.shards(); ++k) {
        const std::string name = std::filesystem::path(shard_path("", k)).filename().string();
        shards.push_back(name);
        checksums[name] = hex16(read_shard_header(shard_path(dir, k)).content_checksum);
    }
    for (const SourceSpec& s : spec.sources) sources.push_back(s.label);
    return {{"version", SONOTRACE_VERSION},
            {"spec", nlohmann::json::parse(spec.canonical)},
            {"spec_digest", hex16(spec.digest())},
            {"frames", spec.frames},
            {"frames_per_shard", spec.frames_per_shard},
            {"image", {{"width", spec.width}, {"height", spec.height}}},
            {"shards", shards},
            {"content_checksums", checksums},
            {"sources", sources},
            {"labels", tissue::label_legend()},
            {"layout",
             "each shard: bmode and labels (and labels_echo on request: where the echoes show the "
             "anatomy) uint8 [n, height, width]; on request depth (mm) and echogenicity "
             "float32 and instances uint16 [n, height, width]; frames: a table of n rows "
             "(index, seed, source = index into sources, probe, frequency_mhz, depth_mm, "
             "focus_mm, gain_db, dynamic_range_db, position, lateral, axial, elevation in "
             "world mm, pixel_mm, origin_mm = probe-plane position of pixel (0, 0) as "
             "(lateral, depth), valid_width, valid_height = the scanned grid in the top-left "
             "corner; then a column per value the spec draws: transducer.KEY, tgc.slope, "
             "tgc.sliderK (dB), noise_snr_db, tissues.TISSUE.PROPERTY (the value the tissue "
             "got)); envelope, rf, energy: float32 per frame under /<name>/<index>; a "
             "512-byte user block (spec_digest, shard, content_checksum) before the HDF5, "
             "checked by `sonotrace dataset --verify DIR`"}};
}

}  // namespace

std::vector<uint64_t> missing_shards(const Spec& spec, const std::string& dir, uint64_t* kept,
                                     std::vector<std::string>* damaged) {
    std::vector<uint64_t> missing;
    for (uint64_t k = 0; k < spec.shards(); ++k) {
        const std::string path = shard_path(dir, k);
        if (base::file_status(path, path, "").type() == std::filesystem::file_type::not_found) {
            missing.push_back(k);
            continue;
        }
        const ShardCheck check = check_shard(path, spec.digest(), k);
        if (check.verdict == ShardCheck::foreign)
            throw base::InputError(path, "spec_digest",
                                   "is not a shard of this spec (the spec, a file it names or "
                                   "the program's version differs): make the dataset in "
                                   "another --out, or remove the old shards");
        if (check.verdict == ShardCheck::damaged) {  // made again, replacing it
            missing.push_back(k);
            if (damaged) damaged->push_back(path + ": " + check.why);
            continue;
        }
        if (kept) ++*kept;
    }
    return missing;
}

bool write_one_shard(const FrameMaker& maker, uint64_t k, const std::string& dir,
                     const std::function<bool()>& stop, const std::function<void()>& frame_done) {
    const Spec& spec = maker.spec();
    const uint64_t first = spec.first_frame(k), end = first + spec.frames_in_shard(k);
    std::vector<DatasetFrame> frames;
    for (uint64_t i = first; i < end; ++i) {
        if (stop && stop()) return false;
        frames.push_back(maker.make(i));
        if (frame_done) frame_done();
    }
    base::OutputTransaction transaction;
    const std::string path = shard_path(dir, k);
    write_shard(transaction.stage(path), path, spec, k, frames);
    transaction.commit();
    return true;
}

std::string write_manifest(const Spec& spec, const std::string& dir) {
    base::OutputTransaction transaction;
    const std::string path = (std::filesystem::path(dir) / "manifest.json").string();
    // The shards' renames reach the disk before the manifest that names them.
    base::sync_directory(dir);
    const std::string text = manifest(spec, dir).dump(2) + "\n";
    base::write_file(transaction.stage(path), text.data(), text.size());
    transaction.commit();
    return path;
}

void check_shard_fits_memory(const Spec& spec) {
    // A shard's frames are held until it is written, then its image beside them: the
    // per-pixel maps (bmode, labels and echo labels one byte each, depth and echogenicity
    // four, instances two) twice over, before the optional per-frame arrays.
    const double per_pixel =
        3.0 + 4.0 * (spec.write_depth + spec.write_echogenicity) + 2.0 * spec.write_instances;
    const double bytes = 2.0 * per_pixel * double(spec.frames_per_shard) * spec.width * spec.height;
    base::check_allocation(bytes, spec.path, "frames_per_shard");
}

namespace {

uint64_t parse_hex16(const nlohmann::json& value, const std::string& source,
                     const std::string& field) {
    const std::string text = value.is_string() ? value.get<std::string>() : "";
    if (text.size() != 16 || text.find_first_not_of("0123456789abcdef") != std::string::npos)
        throw base::InputError(source, field, "is not 16 lower-case hex digits");
    return std::stoull(text, nullptr, 16);
}

}  // namespace

VerifyReport verify_dataset(const std::string& dir,
                            const std::function<void(uint64_t done, uint64_t total)>& progress) {
    const std::string path = (std::filesystem::path(dir) / "manifest.json").string();
    if (base::file_status(path, path, "").type() == std::filesystem::file_type::not_found)
        throw base::InputError(path, "",
                               "file not found: not a finished dataset (a run that stopped "
                               "writes its manifest when the same command completes it)");
    const nlohmann::json m = base::jsonio::read_file(path);
    base::jsonio::require_object(m, path, "");
    for (const char* key : {"spec_digest", "shards", "content_checksums"})
        if (!m.contains(key)) throw base::InputError(path, key, "missing");
    const uint64_t digest = parse_hex16(m["spec_digest"], path, "spec_digest");
    const nlohmann::json& shards = m["shards"];
    const nlohmann::json& checksums = m["content_checksums"];
    if (!shards.is_array()) throw base::InputError(path, "shards", "is not an array");
    if (!checksums.is_object())
        throw base::InputError(path, "content_checksums", "is not an object");
    VerifyReport report;
    report.shards = shards.size();
    for (uint64_t k = 0; k < shards.size(); ++k) {
        const std::string field = "shards[" + std::to_string(k) + "]";
        const std::string file = shard_path(dir, k);
        const std::string name = std::filesystem::path(file).filename().string();
        // Only the names this program writes, in order: never a path out of `dir`.
        if (!shards[k].is_string() || shards[k].get<std::string>() != name)
            throw base::InputError(path, field, "is not \"" + name + "\"");
        if (!checksums.contains(name))
            throw base::InputError(path, "content_checksums." + name, "missing");
        const uint64_t listed = parse_hex16(checksums[name], path, "content_checksums." + name);
        try {
            const ShardCheck check = check_shard(file, digest, k);
            if (check.verdict != ShardCheck::ok)
                report.problems.push_back(file + ": " + check.why);
            else if (check.header.content_checksum != listed)
                report.problems.push_back(file + ": its checksum is not the manifest's");
        } catch (const base::InputError& e) {  // missing, not a regular file, unreadable
            report.problems.push_back(e.what());
        }
        if (progress) progress(k + 1, shards.size());
    }
    return report;
}

RunReport make_dataset(const Spec& spec, const RunOptions& options) {
    check_shard_fits_memory(spec);
    RunReport report;
    const std::vector<uint64_t> missing =
        missing_shards(spec, options.out_dir, &report.shards_kept, &report.damaged);
    uint64_t total = 0, done = 0;
    for (uint64_t k : missing) total += spec.frames_in_shard(k);
    if (!missing.empty()) {
        const FrameMaker maker(spec);
        for (uint64_t k : missing) {
            const bool complete = write_one_shard(maker, k, options.out_dir, options.stop, [&] {
                ++done;
                if (options.progress) options.progress(done, total);
            });
            if (!complete) {
                report.stopped = true;
                return report;
            }
            ++report.shards_written;
        }
    }
    report.manifest = write_manifest(spec, options.out_dir);
    return report;
}

}  // namespace sonotrace::dataset
