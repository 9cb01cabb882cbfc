#pragma once
// NIfTI-1 (.nii, .nii.gz, .hdr/.img) through Debian's niftilib.
//
// Geometry follows the NIfTI standard's precedence, as nibabel does: the sform when
// sform_code > 0, else the qform when qform_code > 0, else pixdim scaling with the origin
// at zero. Voxel values are scl_slope * stored + scl_inter when scl_slope is non-zero.
// All real scalar datatypes are read (8/16/32/64-bit integers, float32, float64); complex
// and RGB data are refused with a message. Of a 4D file only the first volume is read.
#include <string>
#include <vector>

#include "tissue/volume.h"

namespace sonotrace::tissue {

struct NiftiReadResult {
    Volume volume;
    std::vector<std::string> warnings;  // e.g. "4D file: only volume 0 was read"
    // The world axes are the subject's (RAS: a qform or sform names them), not pixdim's.
    bool anatomical = false;
};

// Throws base::InputError naming the file and header field on any problem (missing file,
// truncated data, unsupported datatype, bad dimensions or spacing, NaN/Inf voxels,
// more memory than available).
NiftiReadResult read_nifti(const std::string& path);

// Writes float32 voxels with sform and qform set from the geometry. The file appears
// atomically (temporary name, then rename). A ".gz" suffix compresses.
void write_nifti(const Volume& volume, const std::string& path);

}  // namespace sonotrace::tissue
