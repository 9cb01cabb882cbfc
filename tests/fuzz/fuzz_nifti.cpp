// NIfTI-1 files (.nii): header fields, datatypes, truncation, sizes.
#include "fuzz_util.h"
#include "tissue/nifti_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::string path = fuzz::as_file(data, size, "input.nii");
    return fuzz::only_input_errors([&] { tissue::read_nifti(path); });
}
