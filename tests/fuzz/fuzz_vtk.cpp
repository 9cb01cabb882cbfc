// VTK legacy unstructured grids (ASCII and BINARY), as given to render --volume.
#include "fuzz_util.h"
#include "imaging/pbvr/tetra.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::string path = fuzz::as_file(data, size, "mesh.vtk");
    return fuzz::only_input_errors([&] { imaging::pbvr::read_vtk_unstructured(path); });
}
