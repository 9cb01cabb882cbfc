// Transfer-function JSON files (intensity or label points, tissues, properties).
#include "fuzz_util.h"
#include "tissue/transfer_function.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::string path = fuzz::as_file(data, size, "tf.json");
    return fuzz::only_input_errors([&] { tissue::load_transfer_function(path); });
}
