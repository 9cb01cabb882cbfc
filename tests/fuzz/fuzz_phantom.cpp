// Phantom files (phantoms/*.json): background, shapes, targets, probe, source.
#include "fuzz_util.h"
#include "phantoms/phantom.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::string path = fuzz::as_file(data, size, "phantom.json");
    return fuzz::only_input_errors([&] { phantoms::load_phantom(path); });
}
