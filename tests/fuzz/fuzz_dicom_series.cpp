// DICOM series of several files (a directory, as `--volume DIR` reads it): up to eight
// files cut from the input at fuzz::kFileSeparator, so positions, orientations, spacings,
// series UIDs and frame counts disagree between files. Seeds: series written by
// tests/tissue/test_dicom_io.cpp (DicomIo.SeriesSeedOfTheFuzzerIsASoundSeries reads them back).
#include "fuzz_util.h"
#include "tissue/dicom_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::vector<std::string> files = fuzz::split_files(data, size, 8);
    const std::filesystem::path dir = fuzz::fresh_dir("series");
    for (std::size_t k = 0; k < files.size(); ++k)
        fuzz::write_bytes(dir / ("IM" + std::to_string(k)), files[k]);
    return fuzz::only_input_errors([&] { tissue::read_dicom(dir.string()); });
}
