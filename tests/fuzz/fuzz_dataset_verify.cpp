// A finished dataset read back (`sonotrace dataset --verify DIR`, and the checks a resumed
// run makes of the shards it keeps): manifest.json and up to three shards, cut from the
// input at fuzz::kFileSeparator. A shard piece that begins with byte 1 gets a sound header
// (spec digest 1, its number, the checksum of the rest), so mutations reach the checks past
// the checksum as well as the header's.
#include "fuzz_util.h"
#include "ui/dataset/dataset.h"
#include "ui/dataset/shard.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    using namespace sonotrace::dataset;
    const std::vector<std::string> files = fuzz::split_files(data, size, 4);
    const std::filesystem::path dir = fuzz::fresh_dir("dataset");
    fuzz::write_bytes(dir / "manifest.json", files[0]);
    for (std::size_t k = 1; k < files.size(); ++k) {
        std::string shard = files[k];
        if (!shard.empty() && shard[0] == '\1') {
            shard = std::string(kShardHeaderBytes, '\0') + shard.substr(1);
            const std::string header = shard_header(1, k - 1, content_checksum(shard));
            std::copy(header.begin(), header.end(), shard.begin());
        }
        fuzz::write_bytes(shard_path(dir.string(), k - 1), shard);
    }
    return fuzz::only_input_errors([&] { (void)verify_dataset(dir.string(), {}); });
}
