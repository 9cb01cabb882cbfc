// Probe poses ('at=X,Y,Z beam=DX,DY,DZ ...'), as given to --pose or in a sweep file.
#include "fuzz_util.h"
#include "probe/pose.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::string text(reinterpret_cast<const char*>(data), size);
    return fuzz::only_input_errors([&] { probe::parse_pose(text, "--pose"); });
}
