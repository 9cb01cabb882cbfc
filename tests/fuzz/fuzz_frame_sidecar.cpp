// Frame sidecars (bmode.json) as render --frame reads them, next to a fixed frame PNG.
#include <vector>

#include "fuzz_util.h"
#include "imaging/pbvr/overlay.h"
#include "tissue/image_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    static const bool png_written = [] {
        tissue::write_gray_image((fuzz::scratch() / "bmode.png").string(), 8, 8,
                                 std::vector<float>(64, 100.0f), 8);
        return true;
    }();
    (void)png_written;
    const std::string path = fuzz::as_file(data, size, "bmode.json");
    return fuzz::only_input_errors([&] { imaging::pbvr::load_frame_overlay(path); });
}
