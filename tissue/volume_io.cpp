#include "tissue/volume_io.h"

#include <filesystem>

#include "tissue/base/error.h"
#include "tissue/base/file_status.h"
#include "tissue/dicom_io.h"
#include "tissue/image_io.h"
#include "tissue/nifti_io.h"
#include "tissue/raw_io.h"

namespace sonotrace::tissue {

namespace {

bool ends_with(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

glm::dvec3 require_spacing(const VolumeRequest& request) {
    if (!request.image_spacing) {
        throw base::InputError(
            request.spec, "--spacing",
            "images carry no physical size: give the pixel spacing in mm, "
            "e.g. --spacing 0.5,0.5 (and the slice spacing for stacks: 0.5,0.5,1)");
    }
    return *request.image_spacing;
}

}  // namespace

LoadedVolume load_volume(const VolumeRequest& request) {
    LoadedVolume loaded;
    const std::string& spec = request.spec;
    if (spec.empty()) throw base::InputError("--volume", "", "no volume given");
    if (spec == kDefaultVolumeName) {
        loaded.path = kDefaultVolumePath;
        if (!std::filesystem::exists(loaded.path)) {
            throw base::InputError(loaded.path, "",
                                   "the default Colin27 volume is missing; install Debian's "
                                   "mricron-data package (scripts/setup.sh does)");
        }
    } else {
        loaded.path = spec;
    }
    const std::string& path = loaded.path;
    const std::filesystem::file_status status = base::file_status(path, path, "");
    if (ends_with(path, ".nii") || ends_with(path, ".nii.gz") || ends_with(path, ".hdr") ||
        ends_with(path, ".img")) {
        NiftiReadResult r = read_nifti(path);
        loaded.volume = std::move(r.volume);
        loaded.warnings = std::move(r.warnings);
        loaded.anatomical = r.anatomical;
        loaded.format = "nifti";
    } else if (ends_with(path, ".json") || ends_with(path, ".raw")) {
        loaded.volume = read_raw(path);
        loaded.format = "raw";
    } else if (ends_with(path, ".dcm") || is_dicom_directory(path) ||
               (std::filesystem::is_regular_file(status) && is_dicom_file(path))) {
        DicomReadResult r = read_dicom(path);
        loaded.volume = std::move(r.volume);
        loaded.warnings = std::move(r.warnings);
        loaded.anatomical = true;  // patient coordinates (LPS), read as RAS
        loaded.modality = r.modality;
        loaded.format = "dicom";
    } else if (std::filesystem::is_directory(status) ||
               (path.find('%') != std::string::npos && !std::filesystem::is_regular_file(status))) {
        loaded.volume = read_image_stack(list_image_stack(path), require_spacing(request), path);
        loaded.format = "image-stack";
    } else if (has_image_extension(path)) {
        glm::dvec3 spacing = require_spacing(request);
        loaded.volume = read_image(path, spacing);
        loaded.format = "image";
    } else if (!std::filesystem::exists(status)) {
        throw base::InputError(path, "", "file not found");
    } else {
        throw base::InputError(
            path, "",
            "unknown volume format (expected .nii, .nii.gz, .hdr, .json/.raw, a DICOM "
            "file or series directory, an image file, a directory of images or an image "
            "pattern)");
    }
    return loaded;
}

}  // namespace sonotrace::tissue
