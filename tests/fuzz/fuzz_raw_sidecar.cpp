// Raw volume sidecars (.json) next to a fixed 4 x 4 x 4 float32 raw file.
#include <vector>

#include "fuzz_util.h"
#include "tissue/raw_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    static const bool raw_written = [] {
        const std::vector<float> voxels(64, 1.0f);
        fuzz::as_file(reinterpret_cast<const uint8_t*>(voxels.data()), voxels.size() * 4,
                      "volume.raw");
        return true;
    }();
    (void)raw_written;
    const std::string path = fuzz::as_file(data, size, "volume.json");
    return fuzz::only_input_errors([&] { tissue::read_raw(path); });
}
