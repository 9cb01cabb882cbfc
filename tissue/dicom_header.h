#pragma once
// The header of one DICOM file, read without its pixel data, and what reading one safely
// takes: the attributes messages name, the check of declared lengths before GDCM reads
// the file, the address-space budget of a GDCM call, GDCM's collected warnings. Private
// to tissue/dicom_io.cpp, which assembles files into series and decodes their pixels.
#include <sys/resource.h>
#include <unistd.h>

#include <gdcmDataSet.h>
#include <gdcmTag.h>

#include "tissue/base/error.h"

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <glm/glm.hpp>

namespace sonotrace::tissue::dicom {

// A DICOM attribute as messages name it: its keyword and its (group,element) tag.
struct Attribute {
    std::uint16_t group;
    std::uint16_t element;
    const char* keyword;

    gdcm::Tag tag() const { return gdcm::Tag(group, element); }
    std::string field() const {
        char text[80];
        std::snprintf(text, sizeof text, "%s (%04X,%04X)", keyword, group, element);
        return text;
    }
};

inline constexpr Attribute kModality{0x0008, 0x0060, "Modality"};
inline constexpr Attribute kSeriesDescription{0x0008, 0x103E, "SeriesDescription"};
inline constexpr Attribute kSliceThickness{0x0018, 0x0050, "SliceThickness"};
inline constexpr Attribute kSeriesInstanceUid{0x0020, 0x000E, "SeriesInstanceUID"};
inline constexpr Attribute kImagePosition{0x0020, 0x0032, "ImagePositionPatient"};
inline constexpr Attribute kImageOrientation{0x0020, 0x0037, "ImageOrientationPatient"};
inline constexpr Attribute kNumberOfFrames{0x0028, 0x0008, "NumberOfFrames"};
inline constexpr Attribute kRows{0x0028, 0x0010, "Rows"};
inline constexpr Attribute kPixelSpacing{0x0028, 0x0030, "PixelSpacing"};
inline constexpr Attribute kRescaleIntercept{0x0028, 0x1052, "RescaleIntercept"};
inline constexpr Attribute kRescaleSlope{0x0028, 0x1053, "RescaleSlope"};
inline constexpr Attribute kPixelData{0x7FE0, 0x0010, "PixelData"};

// DICOM's patient coordinates (LPS) to the RAS world of NIfTI and of every other loader.
// 0 - x rather than -x: no negative zeros in sidecars.
inline glm::dvec3 lps_to_ras(const glm::dvec3& v) {
    return {0.0 - v.x, 0.0 - v.y, v.z};
}

// What the header of one slice file says, read without its pixel data.
struct SliceHeader {
    std::string file;
    std::string series_uid;
    std::string modality;
    std::string description;
    std::optional<glm::dvec3> position;  // LPS, mm
    std::optional<std::vector<double>> orientation;
    std::optional<std::vector<double>> pixel_spacing;  // row spacing, column spacing
    std::optional<double> slice_thickness;
    double slope = 1.0, intercept = 0.0;  // RescaleSlope, RescaleIntercept
    int frames = 1;
    double along_normal = 0.0;     // position projected on the slice normal, mm
    double declared_pixels = 0.0;  // rows x columns x frames
};

// How far a file's pixel data may expand when decoded: deflate's limit is 1032:1 and
// RLE's 128:1; JPEG 2000 packs a uniform image tighter, so the bound is looser still. A
// 766-byte RLE file declaring 40000 x 40000 pixels (3.2 GB decoded) is refused by it
// before any decoding.
inline constexpr double kMaxDecodedPerFileByte = 10000.0;

// GDCM allocates what a header declares, and a malformed header that the walk above
// cannot follow may declare gigabytes in a file of a few hundred bytes. Each GDCM call
// (made in the child process, read_dicom) runs with an address-space limit of what the
// process already maps plus a budget from the file's size: 32 times it (decompression),
// at least 256 MB; beyond it the allocation fails and the file is refused.
class AllocationBudget {
  public:
    explicit AllocationBudget(const std::string& file) {
        std::error_code error;
        const double file_bytes = double(std::filesystem::file_size(file, error));
        std::ifstream statm("/proc/self/statm");
        double pages = 0.0;
        if (!(statm >> pages) || ::getrlimit(RLIMIT_AS, &saved_) != 0) return;
        const double budget = std::max(256.0 * (1 << 20), 32.0 * (error ? 0.0 : file_bytes));
        const double limit = pages * double(::sysconf(_SC_PAGESIZE)) + budget;
        if (saved_.rlim_cur != RLIM_INFINITY && double(saved_.rlim_cur) <= limit) return;
        rlimit tighter = saved_;
        tighter.rlim_cur = rlim_t(limit);
        active_ = ::setrlimit(RLIMIT_AS, &tighter) == 0;
    }
    ~AllocationBudget() {
        if (active_) ::setrlimit(RLIMIT_AS, &saved_);
    }
    AllocationBudget(const AllocationBudget&) = delete;
    AllocationBudget& operator=(const AllocationBudget&) = delete;

  private:
    rlimit saved_{};
    bool active_ = false;
};

// GDCM's warning stream, collected (one of its warnings is the only sign of truncated
// pixel data); DICOM reading is serialized, so one stream serves.
std::ostringstream& gdcm_warnings();
// The text of a string-valued attribute without DICOM's padding, or nothing when the
// attribute is absent or empty.
std::optional<std::string> text_of(const gdcm::DataSet& data, const Attribute& attribute);
// A decimal-string attribute of exactly `count` finite values, or nothing when absent;
// throws base::InputError naming `file` and the attribute otherwise.
std::optional<std::vector<double>> numbers_of(const gdcm::DataSet& data, const Attribute& attribute,
                                              std::size_t count, const std::string& file);
// Refuses a file whose elements declare more bytes than it holds, before GDCM reads it.
void check_declared_lengths(const std::string& file);
// The header of `file`, or nothing when it is not a DICOM image; throws base::InputError
// naming the file and attribute for a malformed one.
std::optional<SliceHeader> read_header(const std::string& file);

}  // namespace sonotrace::tissue::dicom
