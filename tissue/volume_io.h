#pragma once
// One entry point for every volume source the CLI accepts.
#include <optional>
#include <string>
#include <vector>

#include "tissue/volume.h"

namespace sonotrace::tissue {

// The embedded default: the Colin27 T1 head MRI (1 mm, 181x217x181, MNI space) from
// Debian's mricron-data package.
inline constexpr const char* kDefaultVolumeName = "default";
inline constexpr const char* kDefaultVolumePath = "/usr/share/mricron/templates/ch2.nii.gz";

struct VolumeRequest {
    // "default", a NIfTI file (.nii, .nii.gz, .hdr), a raw sidecar (.json) or raw file (.raw),
    // a DICOM file or a directory holding one DICOM series, a 2D image, a directory of
    // numbered images, or a printf pattern ("img_%03d.png").
    std::string spec = kDefaultVolumeName;
    // Pixel and slice spacing in mm; required for image inputs, ignored otherwise.
    std::optional<glm::dvec3> image_spacing;
};

struct LoadedVolume {
    Volume volume;
    std::string path;    // the file or pattern actually read
    std::string format;  // "nifti", "dicom", "image", "image-stack", "raw"
    std::vector<std::string> warnings;
    // World axes are the subject's, RAS (x to the right, y anterior, z superior): NIfTI
    // with a qform or sform, DICOM. Other formats have only their index axes.
    bool anatomical = false;
    std::string modality;  // DICOM (0008,0060), e.g. "CT", "MR"; empty for other formats
};

// Throws base::InputError naming the file/field on every failure.
LoadedVolume load_volume(const VolumeRequest& request);

}  // namespace sonotrace::tissue
