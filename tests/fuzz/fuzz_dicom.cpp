// DICOM files through GDCM: preamble, header attributes (geometry text, rescale, frames),
// pixel data length and encoding. The seeds are small files written by tests/test_dicom_io.
#include "fuzz_util.h"
#include "tissue/dicom_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::string path = fuzz::as_file(data, size, "input.dcm");
    return fuzz::only_input_errors([&] { tissue::read_dicom(path); });
}
