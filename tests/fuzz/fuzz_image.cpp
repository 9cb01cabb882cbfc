// Images read as volumes (PNG through OpenImageIO): declared sizes, truncation, bombs.
#include "fuzz_util.h"
#include "tissue/image_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::string path = fuzz::as_file(data, size, "input.png");
    return fuzz::only_input_errors([&] { tissue::read_image(path, glm::dvec3(1.0)); });
}
