// Surface meshes for phantoms' "mesh" shapes: STL, OBJ and PLY (Assimp, in a child
// process) and VTK polydata, then the checks and the hierarchy (phantoms/mesh.h). The
// file's name follows what its bytes look like, so a mutation can move an input between
// readers as a user's misnamed file would not.
#include "fuzz_util.h"
#include "phantoms/mesh.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
    using namespace sonotrace;
    const std::string_view head(reinterpret_cast<const char*>(data),
                                std::min<std::size_t>(size, 16));
    const char* name = head.starts_with("ply")     ? "mesh.ply"
                       : head.starts_with("# vtk") ? "mesh.vtk"
                       : head.starts_with("solid") || size >= 84 && head.find('\0') != head.npos
                           ? "mesh.stl"
                           : "mesh.obj";
    const std::string path = fuzz::as_file(data, size, name);
    return fuzz::only_input_errors(
        [&] { phantoms::MeshShape(phantoms::read_mesh_file(path), path); });
}
