// Dataset specs (`sonotrace dataset SPEC`): keys, ranges, sources, pose, outputs, and the
// digest of the files a spec names. The spec is read from scratch()/spec/spec.json beside
// links to the repository's phantoms, so "../cyst_and_stone.json" (as in
// phantoms/datasets/example.json, a seed) names a real file.
#include "fuzz_util.h"
#include "ui/dataset/dataset.h"
#include "ui/dataset/spec.h"

namespace {

void link_phantoms() {
    static const bool linked = [] {
        const std::filesystem::path phantoms = SONOTRACE_SOURCE_DIR "/phantoms";
        for (const auto& entry : std::filesystem::directory_iterator(phantoms))
            if (entry.path().extension() == ".json")
                std::filesystem::create_symlink(
                    entry.path(), sonotrace::fuzz::scratch() / entry.path().filename());
        std::filesystem::create_directories(sonotrace::fuzz::scratch() / "spec");
        return true;
    }();
    (void)linked;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    link_phantoms();
    const std::string path = fuzz::as_file(data, size, "spec/spec.json");
    return fuzz::only_input_errors([&] {
        const dataset::Spec spec = dataset::read_spec(path);
        dataset::check_shard_fits_memory(spec);
        (void)spec.digest();
        for (uint64_t i = 0; i < std::min<uint64_t>(spec.frames, 8); ++i)
            (void)dataset::draw_frame(spec, i);
    });
}
