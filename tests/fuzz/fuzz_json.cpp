// The one JSON reader every JSON input goes through (scene files, phantoms, sidecars):
// size and depth caps, numbers beyond double, duplicate keys.
#include "fuzz_util.h"
#include "tissue/base/json_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::string path = fuzz::as_file(data, size, "scene.json");
    return fuzz::only_input_errors([&] { base::jsonio::read_file(path); });
}
