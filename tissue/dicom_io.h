#pragma once
// DICOM input through Debian's GDCM: a series of single-frame slices in one directory, or
// one multi-frame file.
//
// Geometry (DICOM PS3.3 C.7.6.2, Image Plane module), converted from DICOM's patient
// coordinates (LPS: +x left, +y posterior) to the NIfTI world every other loader uses
// (RAS: +x right, +y anterior) by negating x and y, as nibabel and dcm2niix do:
// - index i runs along a row (increasing column), in the direction of the first triplet of
//   ImageOrientationPatient (0020,0037); j runs down the columns, along its second triplet;
// - PixelSpacing (0028,0030) is "row spacing \ column spacing": the distance between rows
//   (along j) first, then between columns (along i);
// - slices are ordered by the projection of ImagePositionPatient (0020,0032) onto the
//   plane's normal (row x column direction), whatever the file names or InstanceNumber
//   say; k runs from the first slice to the last, with their mean distance as the slice
//   spacing. A tilted gantry (positions not along the normal) gives a sheared direction
//   matrix, which Volume supports.
// Voxel values are RescaleSlope * stored + RescaleIntercept (0028,1053 / 0028,1052), per
// slice: Hounsfield units for CT, the scanner's units for MR.
//
// Refused, each with the file and the tag: files of more than one series (SeriesInstance
// UID), differing orientation, size or pixel spacing, two slices at one position (echoes
// or time points of one series), non-uniform slice spacing (a missing slice), missing
// geometry tags in a series, colour data, and anything GDCM cannot decode.
#include <string>
#include <vector>

#include "tissue/volume.h"

namespace sonotrace::tissue {

struct DicomReadResult {
    Volume volume;
    std::string modality;  // (0008,0060), e.g. "MR", "CT"; empty when absent
    std::string series_description;
    int slice_count = 0;  // files read (1 for a multi-frame file)
    std::vector<std::string> warnings;
};

// True when `path` is a DICOM Part 10 file ("DICM" after the 128-byte preamble).
bool is_dicom_file(const std::string& path);
// True when `path` is a directory holding at least one DICOM Part 10 file (not looking
// into sub-directories).
bool is_dicom_directory(const std::string& path);

// Reads a series directory or a single file. Throws base::InputError naming the file and
// the DICOM tag on every failure.
DicomReadResult read_dicom(const std::string& path);

}  // namespace sonotrace::tissue
