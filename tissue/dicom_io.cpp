#include "tissue/dicom_io.h"

#include <sys/resource.h>
#include <unistd.h>

#include <gdcmAttribute.h>
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmReader.h>
#include <gdcmTrace.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
#include <tuple>

#include "tissue/base/error.h"
#include "tissue/base/file_status.h"
#include "tissue/base/isolated.h"
#include "tissue/base/memory.h"

namespace fs = std::filesystem;

namespace sonotrace::tissue {

namespace {

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

constexpr Attribute kModality{0x0008, 0x0060, "Modality"};
constexpr Attribute kSeriesDescription{0x0008, 0x103E, "SeriesDescription"};
constexpr Attribute kSliceThickness{0x0018, 0x0050, "SliceThickness"};
constexpr Attribute kSeriesInstanceUid{0x0020, 0x000E, "SeriesInstanceUID"};
constexpr Attribute kImagePosition{0x0020, 0x0032, "ImagePositionPatient"};
constexpr Attribute kImageOrientation{0x0020, 0x0037, "ImageOrientationPatient"};
constexpr Attribute kNumberOfFrames{0x0028, 0x0008, "NumberOfFrames"};
constexpr Attribute kRows{0x0028, 0x0010, "Rows"};
constexpr Attribute kPixelSpacing{0x0028, 0x0030, "PixelSpacing"};
constexpr Attribute kRescaleIntercept{0x0028, 0x1052, "RescaleIntercept"};
constexpr Attribute kRescaleSlope{0x0028, 0x1053, "RescaleSlope"};
constexpr Attribute kPixelData{0x7FE0, 0x0010, "PixelData"};

// DICOM's patient coordinates (LPS) to the RAS world of NIfTI and of every other loader.
// 0 - x rather than -x: no negative zeros in sidecars.
glm::dvec3 lps_to_ras(const glm::dvec3& v) {
    return {0.0 - v.x, 0.0 - v.y, v.z};
}

// GDCM reports problems on its warning stream, on stderr by default. Ours become
// InputErrors; GDCM's warnings are collected here because one of them is the only sign
// of a truncated pixel data element, which GDCM pads with zeros and reads "successfully".
// DICOM reading is serialized (read_dicom holds a lock), so one stream serves.
std::ostringstream& gdcm_warnings() {
    static std::ostringstream* stream = [] {
        auto* s = new std::ostringstream;  // never destroyed: GDCM keeps a reference
        gdcm::Trace::SetDebug(false);
        gdcm::Trace::SetError(false);
        gdcm::Trace::SetWarning(true);
        gdcm::Trace::SetWarningStream(*s);
        return s;
    }();
    return *stream;
}

// The text of a string-valued attribute without DICOM's padding, or nothing when the
// attribute is absent or empty.
std::optional<std::string> text_of(const gdcm::DataSet& data, const Attribute& attribute) {
    if (!data.FindDataElement(attribute.tag())) return std::nullopt;
    const gdcm::ByteValue* bytes = data.GetDataElement(attribute.tag()).GetByteValue();
    if (bytes == nullptr || bytes->GetPointer() == nullptr || bytes->GetLength() == 0) {
        return std::nullopt;
    }
    std::string text(bytes->GetPointer(), bytes->GetLength());
    const std::string padding(" \0", 2);
    const auto first = text.find_first_not_of(padding);
    if (first == std::string::npos) return std::nullopt;
    return text.substr(first, text.find_last_not_of(padding) - first + 1);
}

// A decimal-string attribute of exactly `count` finite values ("a\b\c"), or nothing when
// absent.
std::optional<std::vector<double>> numbers_of(const gdcm::DataSet& data, const Attribute& attribute,
                                              std::size_t count, const std::string& file) {
    const std::optional<std::string> text = text_of(data, attribute);
    if (!text) return std::nullopt;
    std::vector<double> values;
    std::size_t start = 0;
    while (start <= text->size()) {
        const std::size_t end = std::min(text->find('\\', start), text->size());
        std::string token = text->substr(start, end - start);
        token.erase(0, token.find_first_not_of(' '));
        token.erase(token.find_last_not_of(' ') + 1);
        char* parsed_end = nullptr;
        const double value = std::strtod(token.c_str(), &parsed_end);
        if (token.empty() || parsed_end != token.c_str() + token.size() || !std::isfinite(value)) {
            throw base::InputError(file, attribute.field(),
                                   "'" + text->substr(0, 80) + "' is not " + std::to_string(count) +
                                       " finite number(s)");
        }
        values.push_back(value);
        start = end + 1;
    }
    if (values.size() != count) {
        throw base::InputError(file, attribute.field(),
                               "expected " + std::to_string(count) + " value(s), got " +
                                   std::to_string(values.size()));
    }
    return values;
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
constexpr double kMaxDecodedPerFileByte = 10000.0;

// An unsigned short element (US), if present (GDCM swaps a big-endian file's bytes).
template <std::uint16_t Group, std::uint16_t Element>
std::optional<unsigned> unsigned_short_of(const gdcm::DataSet& data) {
    if (!data.FindDataElement(gdcm::Tag(Group, Element))) return std::nullopt;
    const gdcm::ByteValue* value = data.GetDataElement(gdcm::Tag(Group, Element)).GetByteValue();
    if (!value || value->GetLength() != 2) return std::nullopt;
    gdcm::Attribute<Group, Element> a;
    a.SetFromDataSet(data);
    return unsigned(a.GetValue());
}

// Refuses a file whose elements declare more bytes than it holds, before GDCM reads it:
// GDCM allocates a declared length before it finds the file short (a 714-byte file
// declaring gigabytes cost 4 GB and seconds). Walks the elements flat: sequences and
// their items are stepped into, the fragments of encapsulated pixel data skipped. Where
// the walk cannot follow the encoding (deflated data, unknown VRs, UN of undefined
// length) it stops and leaves the file to GDCM.
void check_declared_lengths(const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    in.seekg(0, std::ios::end);
    const std::uint64_t size = std::uint64_t(std::max<std::streamoff>(in.tellg(), 0));
    std::uint64_t pos = 132;  // preamble and "DICM"
    bool meta = true, explicit_vr = true, big_endian = false, fragments = false;
    std::string syntax;
    auto read_at = [&](std::uint64_t at, void* out, std::size_t n) {
        in.clear();
        in.seekg(std::streamoff(at));
        return bool(in.read(static_cast<char*>(out), std::streamsize(n)));
    };
    auto number = [&](const unsigned char* b, int n) {
        std::uint32_t v = 0;
        for (int i = 0; i < n; ++i) v |= std::uint32_t(b[big_endian ? n - 1 - i : i]) << (8 * i);
        return v;
    };
    while (pos + 8 <= size) {
        unsigned char head[12] = {};
        if (!read_at(pos, head, std::min<std::uint64_t>(12, size - pos))) return;
        const bool meta_le = meta;  // the file meta group is always explicit little endian
        const bool saved = big_endian;
        if (meta_le) big_endian = false;
        const std::uint32_t group = number(head, 2), element = number(head + 2, 2);
        if (meta && group != 0x0002) {
            meta = false;
            big_endian = saved;
            if (syntax == "1.2.840.10008.1.2.1.99") return;  // deflated: not walkable
            explicit_vr = syntax != "1.2.840.10008.1.2";
            big_endian = syntax == "1.2.840.10008.1.2.2";
            continue;
        }
        char tag_text[16];
        std::snprintf(tag_text, sizeof tag_text, "(%04X,%04X)", unsigned(group), unsigned(element));
        auto require_fits = [&](std::uint64_t header, std::uint64_t length) {
            if (pos + header + length > size) {
                throw base::InputError(file, tag_text,
                                       "declares " + std::to_string(length) + " bytes where " +
                                           std::to_string(size - std::min(size, pos + header)) +
                                           " remain: the file is truncated or corrupt");
            }
        };
        if (group == 0xFFFE) {  // item and delimiters: a 4-byte length, no VR
            const std::uint32_t length = number(head + 4, 4);
            if (element == 0xE000 && fragments) {
                if (length == 0xFFFFFFFFu) return;
                require_fits(8, length);
                pos += 8 + length;
            } else {
                if (element == 0xE0DD) fragments = false;
                pos += 8;
            }
            if (meta_le) big_endian = saved;
            continue;
        }
        std::uint64_t header = 8, length = 0;
        std::string vr;
        if (explicit_vr || meta_le) {
            vr.assign(reinterpret_cast<const char*>(head + 4), 2);
            if (!std::isupper(static_cast<unsigned char>(vr[0])) ||
                !std::isupper(static_cast<unsigned char>(vr[1])))
                return;  // not an encoding this walk follows
            static const std::set<std::string> long_vrs = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ",
                                                           "SV", "UC", "UN", "UR", "UT", "UV"};
            if (long_vrs.count(vr)) {
                if (pos + 12 > size) require_fits(12, 0);
                header = 12;
                length = number(head + 8, 4);
            } else {
                length = number(head + 6, 2);
            }
        } else {
            length = number(head + 4, 4);
        }
        if (meta_le) big_endian = saved;
        if (length == 0xFFFFFFFFu) {
            if (vr == "UN") return;  // implicit VR inside: not followed
            fragments = group == 0x7FE0 && element == 0x0010;
            pos += header;  // step into the sequence or the fragments
            continue;
        }
        if (vr == "SQ") {
            pos += header;  // step into its items
            continue;
        }
        require_fits(header, length);
        if (group == 0x0002 && element == 0x0010 && length < 128) {
            syntax.resize(length);
            if (!read_at(pos + header, syntax.data(), length)) return;
            while (!syntax.empty() && (syntax.back() == '\0' || syntax.back() == ' '))
                syntax.pop_back();
        }
        pos += header + length;
    }
}

// GDCM allocates what a header declares, and a malformed header that the walk above
// cannot follow may declare gigabytes in a file of a few hundred bytes. Each GDCM call
// (made in the child process, read_dicom) runs with an address-space limit of what the
// process already maps plus a budget from the file's size: 32 times it (decompression),
// at least 256 MB; beyond it the allocation fails and the file is refused.
class AllocationBudget {
  public:
    explicit AllocationBudget(const std::string& file) {
        std::error_code error;
        const double file_bytes = double(fs::file_size(file, error));
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

std::optional<SliceHeader> read_header(const std::string& file) {
    check_declared_lengths(file);
    gdcm::Reader reader;
    reader.SetFileName(file.c_str());
    bool read = false;
    try {
        const AllocationBudget budget(file);
        read = reader.ReadUpToTag(kPixelData.tag(), std::set<gdcm::Tag>{});
    } catch (const std::exception& e) {
        throw base::InputError(file, "",
                               std::string("GDCM could not read the header: ") + e.what());
    }
    if (!read) throw base::InputError(file, "", "GDCM could not read the DICOM header (corrupt?)");
    const gdcm::DataSet& data = reader.GetFile().GetDataSet();
    // Objects without an image (reports, presentation states, DICOMDIR) carry no Rows.
    if (!data.FindDataElement(kRows.tag())) return std::nullopt;
    SliceHeader header;
    header.file = file;
    header.series_uid = text_of(data, kSeriesInstanceUid).value_or("");
    header.modality = text_of(data, kModality).value_or("");
    header.description = text_of(data, kSeriesDescription).value_or("");
    if (auto p = numbers_of(data, kImagePosition, 3, file)) {
        header.position = glm::dvec3((*p)[0], (*p)[1], (*p)[2]);
    }
    header.orientation = numbers_of(data, kImageOrientation, 6, file);
    header.pixel_spacing = numbers_of(data, kPixelSpacing, 2, file);
    if (auto t = numbers_of(data, kSliceThickness, 1, file)) header.slice_thickness = (*t)[0];
    if (auto slope = numbers_of(data, kRescaleSlope, 1, file)) {
        if ((*slope)[0] == 0.0) {
            throw base::InputError(file, kRescaleSlope.field(), "must be non-zero");
        }
        header.slope = (*slope)[0];
    }
    if (auto intercept = numbers_of(data, kRescaleIntercept, 1, file)) {
        header.intercept = (*intercept)[0];
    }
    if (auto f = numbers_of(data, kNumberOfFrames, 1, file)) {
        if (!((*f)[0] >= 1 && (*f)[0] <= 1e6 && (*f)[0] == std::floor((*f)[0]))) {
            throw base::InputError(
                file, kNumberOfFrames.field(),
                "must be a whole number in [1, 1e6], got " + base::number_text((*f)[0]));
        }
        header.frames = int((*f)[0]);
    }
    // What decoding would allocate, refused before it: more than the file can encode.
    const unsigned rows = unsigned_short_of<0x0028, 0x0010>(data).value_or(0),
                   columns = unsigned_short_of<0x0028, 0x0011>(data).value_or(0),
                   bits = unsigned_short_of<0x0028, 0x0100>(data).value_or(16);
    header.declared_pixels = double(rows) * columns * header.frames;
    const double declared_bytes = header.declared_pixels * std::max(1u, (bits + 7) / 8);
    std::error_code error;
    const double file_bytes = double(std::filesystem::file_size(file, error));
    const bool encapsulated =
        reader.GetFile().GetHeader().GetDataSetTransferSyntax().IsEncapsulated();
    const double holds = error ? 0.0 : (encapsulated ? kMaxDecodedPerFileByte : 1.0) * file_bytes;
    if (!error && declared_bytes > holds)
        throw base::InputError(file, kRows.field(),
                               "declares " + std::to_string(columns) + " x " +
                                   std::to_string(rows) + " x " + std::to_string(header.frames) +
                                   " pixels (" + std::to_string(std::uint64_t(declared_bytes)) +
                                   " bytes), more than " +
                                   (encapsulated ? "any lossless encoding of its " : "its ") +
                                   std::to_string(std::uint64_t(file_bytes)) + " bytes holds");
    return header;
}

// The unit row and column directions (LPS) of ImageOrientationPatient.
std::pair<glm::dvec3, glm::dvec3> plane_axes(const std::vector<double>& orientation,
                                             const std::string& file) {
    const glm::dvec3 row(orientation[0], orientation[1], orientation[2]);
    const glm::dvec3 column(orientation[3], orientation[4], orientation[5]);
    const double row_length = glm::length(row), column_length = glm::length(column);
    // Scanners write the cosines with about six decimals.
    if (std::abs(row_length - 1.0) > 1e-3 || std::abs(column_length - 1.0) > 1e-3 ||
        std::abs(glm::dot(row, column)) > 1e-3) {
        throw base::InputError(file, kImageOrientation.field(),
                               "is not two orthogonal unit vectors");
    }
    return {row / row_length, column / column_length};
}

// Pixel values of one decoded frame buffer as float, rescaled.
void convert_pixels(const gdcm::Image& image, const std::vector<char>& buffer, std::size_t count,
                    double slope, double intercept, float* out, const std::string& file) {
    auto convert = [&](auto sample) {
        using T = decltype(sample);
        for (std::size_t n = 0; n < count; ++n) {
            T stored;
            std::memcpy(&stored, buffer.data() + n * sizeof(T), sizeof(T));
            out[n] = float(slope * double(stored) + intercept);
        }
    };
    switch (image.GetPixelFormat().GetScalarType()) {
        case gdcm::PixelFormat::UINT8:
            convert(std::uint8_t{});
            break;
        case gdcm::PixelFormat::INT8:
            convert(std::int8_t{});
            break;
        case gdcm::PixelFormat::UINT16:
            convert(std::uint16_t{});
            break;
        case gdcm::PixelFormat::INT16:
            convert(std::int16_t{});
            break;
        case gdcm::PixelFormat::UINT32:
            convert(std::uint32_t{});
            break;
        case gdcm::PixelFormat::INT32:
            convert(std::int32_t{});
            break;
        case gdcm::PixelFormat::UINT64:
            convert(std::uint64_t{});
            break;
        case gdcm::PixelFormat::INT64:
            convert(std::int64_t{});
            break;
        case gdcm::PixelFormat::FLOAT32:
            convert(float{});
            break;
        case gdcm::PixelFormat::FLOAT64:
            convert(double{});
            break;
        default:
            throw base::InputError(file, "BitsAllocated (0028,0100)",
                                   std::string("pixel format ") +
                                       image.GetPixelFormat().GetScalarTypeAsString() +
                                       " is not supported");
    }
}

// One file's decoded pixel data: its size, frames and format checked.
struct DecodedImage {
    gdcm::Image image;
    std::vector<char> buffer;
    glm::ivec3 dims{1, 1, 1};  // columns, rows, frames
};

DecodedImage decode(const std::string& file) {
    gdcm_warnings().str("");
    gdcm::ImageReader reader;
    reader.SetFileName(file.c_str());
    bool read = false;
    try {
        const AllocationBudget budget(file);
        read = reader.Read();
    } catch (const std::exception& e) {
        throw base::InputError(file, kPixelData.field(), std::string("GDCM: ") + e.what());
    }
    if (!read) {
        throw base::InputError(file, kPixelData.field(),
                               "GDCM could not read the image (corrupt, truncated, or an "
                               "unsupported compression)");
    }
    if (gdcm_warnings().str().find("Incomplete Pixel Data") != std::string::npos) {
        throw base::InputError(file, kPixelData.field(), "the file ends inside the pixel data");
    }
    DecodedImage decoded;
    decoded.image = reader.GetImage();
    const gdcm::Image& image = decoded.image;
    const unsigned dimensions = image.GetNumberOfDimensions();
    if (dimensions != 2 && dimensions != 3) {
        throw base::InputError(file, kRows.field(),
                               "has " + std::to_string(dimensions) + " dimensions");
    }
    for (unsigned d = 0; d < dimensions; ++d) {
        const unsigned size = image.GetDimension(d);
        if (size < 1 || size > 65535) {
            throw base::InputError(file, d == 2 ? kNumberOfFrames.field() : kRows.field(),
                                   "size " + std::to_string(size) + " is outside [1, 65535]");
        }
        decoded.dims[int(d)] = int(size);
    }
    const gdcm::PhotometricInterpretation photometric = image.GetPhotometricInterpretation();
    if (image.GetPixelFormat().GetSamplesPerPixel() != 1 ||
        (photometric != gdcm::PhotometricInterpretation::MONOCHROME1 &&
         photometric != gdcm::PhotometricInterpretation::MONOCHROME2)) {
        throw base::InputError(file, "PhotometricInterpretation (0028,0004)",
                               std::string("only greyscale images (MONOCHROME1/2) can be "
                                           "mapped to tissue, got ") +
                                   gdcm::PhotometricInterpretation::GetPIString(photometric));
    }
    const double sample_bytes = image.GetPixelFormat().GetPixelSize();
    const double expected = double(decoded.dims.x) * decoded.dims.y * decoded.dims.z * sample_bytes;
    base::check_allocation(expected, file, kPixelData.field());
    auto short_of = [&](std::uint64_t holds) {
        return base::InputError(file, kPixelData.field(),
                                "holds " + std::to_string(holds) +
                                    " bytes where its header implies " +
                                    std::to_string(std::uint64_t(expected)));
    };
    if (double(image.GetBufferLength()) != expected) throw short_of(image.GetBufferLength());
    // Native (uncompressed) pixel data must hold what the header declares: GDCM decodes
    // a short element "successfully" into the declared buffer, so a file of a few hundred
    // bytes could cost the gigabytes its header declares.
    const gdcm::DataElement& pixels =
        reader.GetFile().GetDataSet().GetDataElement(kPixelData.tag());
    if (const gdcm::ByteValue* native = pixels.GetByteValue();
        native != nullptr && double(native->GetLength()) < expected)
        throw short_of(native->GetLength());
    decoded.buffer.resize(image.GetBufferLength());
    bool decoded_ok = false;
    try {
        decoded_ok = image.GetBuffer(decoded.buffer.data());
    } catch (const std::exception& e) {
        throw base::InputError(file, kPixelData.field(), std::string("GDCM: ") + e.what());
    }
    if (!decoded_ok) {
        throw base::InputError(file, kPixelData.field(),
                               "GDCM could not decode the pixel data (truncated or an "
                               "unsupported compression)");
    }
    return decoded;
}

void require_finite_rescale(const gdcm::Image& image, const std::string& file) {
    if (!std::isfinite(image.GetSlope()) || image.GetSlope() == 0.0) {
        throw base::InputError(
            file, kRescaleSlope.field(),
            "must be finite and non-zero, got " + base::number_text(image.GetSlope()));
    }
    if (!std::isfinite(image.GetIntercept())) {
        throw base::InputError(file, kRescaleIntercept.field(), "must be finite");
    }
}

// One multi-frame file (enhanced CT/MR): GDCM gathers its geometry from the functional
// groups.
DicomReadResult read_multiframe(const SliceHeader& header, DecodedImage decoded) {
    const std::string& file = header.file;
    const gdcm::Image& image = decoded.image;
    require_finite_rescale(image, file);
    VolumeGeometry geometry;
    geometry.dims = decoded.dims;
    const double* spacing = image.GetSpacing();
    const double* origin = image.GetOrigin();
    const double* cosines = image.GetDirectionCosines();
    // GDCM orders the spacing as the index axes: columns (i), rows (j), frames (k).
    geometry.spacing = {spacing[0], spacing[1], spacing[2]};
    std::vector<double> orientation(cosines, cosines + 6);
    const auto [row, column] = plane_axes(orientation, file);
    geometry.origin = lps_to_ras({origin[0], origin[1], origin[2]});
    geometry.direction =
        glm::dmat3(lps_to_ras(row), lps_to_ras(column), lps_to_ras(glm::cross(row, column)));
    geometry.validate(file);
    Volume volume(geometry);
    convert_pixels(image, decoded.buffer, geometry.voxel_count(), image.GetSlope(),
                   image.GetIntercept(), volume.voxels().data(), file);
    volume.require_finite(file);
    DicomReadResult result;
    result.volume = std::move(volume);
    result.modality = header.modality;
    result.series_description = header.description;
    result.slice_count = 1;
    return result;
}

std::string describe_series(const std::vector<SliceHeader>& slices) {
    std::string text =
        "'" +
        (slices.front().series_uid.empty() ? std::string("(none)") : slices.front().series_uid) +
        "' (" + std::to_string(slices.size()) + " files";
    if (!slices.front().description.empty()) text += ", \"" + slices.front().description + "\"";
    return text + ")";
}

// Orders the slices along their normal and derives the volume's geometry from their
// positions; refuses what does not form one regular grid.
VolumeGeometry series_geometry(std::vector<SliceHeader>& slices, const std::string& source) {
    const SliceHeader& first = slices.front();
    VolumeGeometry geometry;
    if (!first.pixel_spacing) {
        throw base::InputError(first.file, kPixelSpacing.field(),
                               "missing: the image has no physical size");
    }
    const double row_spacing = (*first.pixel_spacing)[0];
    const double column_spacing = (*first.pixel_spacing)[1];
    glm::dvec3 row(1, 0, 0), column(0, 1, 0);
    if (first.orientation) std::tie(row, column) = plane_axes(*first.orientation, first.file);
    const glm::dvec3 normal = glm::cross(row, column);
    for (SliceHeader& slice : slices) {
        if (slices.size() > 1) {
            if (!slice.position) {
                throw base::InputError(slice.file, kImagePosition.field(),
                                       "missing: a series cannot be ordered without it");
            }
            if (!slice.orientation) {
                throw base::InputError(slice.file, kImageOrientation.field(),
                                       "missing: a series cannot be ordered without it");
            }
        }
        if (slice.orientation) {
            plane_axes(*slice.orientation, slice.file);
            for (int c = 0; c < 6; ++c) {
                if (std::abs((*slice.orientation)[c] - (*first.orientation)[c]) > 1e-4) {
                    throw base::InputError(
                        slice.file, kImageOrientation.field(),
                        "differs from that of " + first.file + ": the files are not one volume");
                }
            }
        }
        if (!slice.pixel_spacing ||
            std::abs((*slice.pixel_spacing)[0] - row_spacing) > 1e-4 * row_spacing ||
            std::abs((*slice.pixel_spacing)[1] - column_spacing) > 1e-4 * column_spacing) {
            throw base::InputError(slice.file, kPixelSpacing.field(),
                                   "differs from that of " + first.file);
        }
        slice.along_normal = slice.position ? glm::dot(*slice.position, normal) : 0.0;
    }
    std::stable_sort(slices.begin(), slices.end(), [](const SliceHeader& a, const SliceHeader& b) {
        return a.along_normal < b.along_normal;
    });
    const std::size_t n = slices.size();
    geometry.spacing = {column_spacing, row_spacing, first.slice_thickness.value_or(1.0)};
    glm::dvec3 slice_direction = normal;
    if (n > 1) {
        const double mean_gap =
            (slices.back().along_normal - slices.front().along_normal) / double(n - 1);
        // Positions are written with a few decimals; a missing slice doubles a gap.
        const double tolerance = std::max(0.01 * mean_gap, 0.01);
        for (std::size_t k = 1; k < n; ++k) {
            const double gap = slices[k].along_normal - slices[k - 1].along_normal;
            if (gap < tolerance) {
                throw base::InputError(
                    source, kImagePosition.field(),
                    slices[k - 1].file + " and " + slices[k].file +
                        " lie at the same position: a series of several echoes, phases or "
                        "time points; put each in a directory of its own");
            }
            if (std::abs(gap - mean_gap) > tolerance) {
                throw base::InputError(source, kImagePosition.field(),
                                       "slice spacing is not uniform: " + base::number_text(gap) +
                                           " mm between " + slices[k - 1].file + " and " +
                                           slices[k].file + " where the series averages " +
                                           base::number_text(mean_gap) + " mm (a missing slice?)");
            }
        }
        const glm::dvec3 step =
            (*slices.back().position - *slices.front().position) / double(n - 1);
        for (std::size_t k = 0; k < n; ++k) {
            const glm::dvec3 expected = *slices.front().position + double(k) * step;
            if (glm::length(*slices[k].position - expected) > tolerance) {
                throw base::InputError(slices[k].file, kImagePosition.field(),
                                       "is off the line through the other slices' positions");
            }
        }
        geometry.spacing.z = glm::length(step);
        // A tilted gantry steps sideways as well: k is then not normal to the plane.
        slice_direction = step / geometry.spacing.z;
    }
    geometry.origin = lps_to_ras(first.position.value_or(glm::dvec3(0.0)));
    geometry.direction =
        glm::dmat3(lps_to_ras(row), lps_to_ras(column), lps_to_ras(slice_direction));
    return geometry;
}

DicomReadResult read_series(std::vector<SliceHeader> slices, const std::string& source) {
    std::map<std::string, std::vector<SliceHeader>> by_series;
    for (SliceHeader& slice : slices) by_series[slice.series_uid].push_back(std::move(slice));
    if (by_series.size() > 1) {
        std::string listing;
        int listed = 0;
        for (const auto& [uid, members] : by_series) {
            if (listed++ == 4) {
                listing += ", ...";
                break;
            }
            listing += (listing.empty() ? "" : ", ") + describe_series(members);
        }
        throw base::InputError(source, kSeriesInstanceUid.field(),
                               "the directory holds " + std::to_string(by_series.size()) +
                                   " series: " + listing +
                                   "; put the one to read in a directory of its own");
    }
    slices = std::move(by_series.begin()->second);
    for (const SliceHeader& slice : slices) {
        if (slice.frames > 1 && slices.size() > 1) {
            throw base::InputError(slice.file, kNumberOfFrames.field(),
                                   "a multi-frame file in a series of several files");
        }
    }
    if (slices.size() == 1 && slices.front().frames > 1) {
        return read_multiframe(slices.front(), decode(slices.front().file));
    }

    DicomReadResult result;
    VolumeGeometry geometry = series_geometry(slices, source);
    if (slices.size() > 1) {
        // A tilted gantry or a sheared stack: the slice axis is kept slanted (every voxel at
        // its recorded position); said, since a viewer that assumes orthogonal axes (or a
        // NIfTI qform) shows such a volume straightened.
        const glm::dvec3 k_axis = geometry.direction[2];
        const glm::dvec3 normal = glm::cross(geometry.direction[0], geometry.direction[1]);
        const double across = glm::length(glm::cross(k_axis, normal)) * geometry.spacing.z;
        if (across > 1e-3 * geometry.spacing.z + 1e-4)
            result.warnings.push_back(
                source + ": the slices step " +
                base::number_text(std::abs(glm::dot(k_axis, normal)) * geometry.spacing.z) +
                " mm along their normal and " + base::number_text(across) +
                " mm across it (a tilted gantry or a sheared stack): the volume keeps the "
                "slanted slice axis, every voxel at the position its file records");
    }
    if (!slices.front().position && slices.size() == 1) {
        result.warnings.push_back(slices.front().file + ": no " + kImagePosition.field() +
                                  "; the image is placed at the origin");
    }
    if (!slices.front().orientation && slices.size() == 1) {
        result.warnings.push_back(slices.front().file + ": no " + kImageOrientation.field() +
                                  "; the image is taken as axial");
    }
    Volume volume;
    for (std::size_t k = 0; k < slices.size(); ++k) {
        const std::string& file = slices[k].file;
        DecodedImage decoded = decode(file);
        if (decoded.dims.z != 1) {
            throw base::InputError(file, kNumberOfFrames.field(),
                                   "a multi-frame file in a series of several files");
        }
        if (k == 0) {
            geometry.dims = {decoded.dims.x, decoded.dims.y, int(slices.size())};
            geometry.validate(source);
            base::check_allocation(double(geometry.voxel_count()) * sizeof(float), source,
                                   kRows.field());
            volume = Volume(geometry);
        } else if (decoded.dims.x != geometry.dims.x || decoded.dims.y != geometry.dims.y) {
            throw base::InputError(
                file, kRows.field(),
                "the image is " + std::to_string(decoded.dims.x) + "x" +
                    std::to_string(decoded.dims.y) + " where " + slices.front().file + " is " +
                    std::to_string(geometry.dims.x) + "x" + std::to_string(geometry.dims.y));
        }
        const std::size_t per_slice = std::size_t(geometry.dims.x) * std::size_t(geometry.dims.y);
        convert_pixels(decoded.image, decoded.buffer, per_slice, slices[k].slope,
                       slices[k].intercept, volume.voxels().data() + k * per_slice, file);
    }
    volume.require_finite(source);
    result.volume = std::move(volume);
    result.modality = slices.front().modality;
    result.series_description = slices.front().description;
    result.slice_count = int(slices.size());
    return result;
}

}  // namespace

bool is_dicom_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    char bytes[132];
    if (!in.read(bytes, sizeof bytes)) return false;
    return std::memcmp(bytes + 128, "DICM", 4) == 0;
}

bool is_dicom_directory(const std::string& path) {
    std::error_code error;
    if (!fs::is_directory(path, error)) return false;
    for (const auto& entry : fs::directory_iterator(path, error)) {
        if (entry.is_regular_file(error) && is_dicom_file(entry.path().string())) return true;
    }
    return false;
}

namespace {

DicomReadResult read_dicom_here(const std::string& path) {
    static std::mutex one_reader;  // GDCM's warning stream is global
    const std::lock_guard<std::mutex> lock(one_reader);
    std::error_code error;
    const fs::file_status status = base::file_status(path, path, "");
    if (!fs::exists(status)) throw base::InputError(path, "", "file not found");
    std::vector<std::string> files;
    if (fs::is_directory(status)) {
        for (const auto& entry : fs::directory_iterator(path, error)) {
            if (entry.is_regular_file(error) && is_dicom_file(entry.path().string())) {
                files.push_back(entry.path().string());
            }
        }
        if (files.empty()) {
            throw base::InputError(path, "",
                                   "holds no DICOM files (Part 10, \"DICM\" after the "
                                   "preamble; sub-directories are not searched)");
        }
        // The order only matters for messages; the slices are ordered by position.
        std::sort(files.begin(), files.end());
    } else {
        if (!is_dicom_file(path)) {
            throw base::InputError(path, "",
                                   "not a DICOM Part 10 file (no \"DICM\" after the preamble)");
        }
        files.push_back(path);
    }
    std::vector<SliceHeader> slices;
    std::size_t skipped = 0;
    for (const std::string& file : files) {
        if (std::optional<SliceHeader> header = read_header(file)) {
            slices.push_back(std::move(*header));
        } else {
            ++skipped;
        }
    }
    if (slices.empty()) {
        throw base::InputError(path, kRows.field(),
                               "no DICOM file here holds an image (reports, presentation "
                               "states and DICOMDIR files have none)");
    }
    // The whole series' voxels (as floats) against the free memory, before any decoding.
    double declared_voxels = 0.0;
    for (const SliceHeader& slice : slices) declared_voxels += slice.declared_pixels;
    base::check_allocation(declared_voxels * sizeof(float), path, kRows.field());
    DicomReadResult result = read_series(std::move(slices), path);
    if (skipped > 0) {
        result.warnings.push_back(path + ": " + std::to_string(skipped) +
                                  " DICOM file(s) without an image skipped");
    }
    return result;
}

// The child's answer through a pipe: a status byte, then the result or the error.
void send_result(base::PipeWriter& out, const DicomReadResult& r) {
    const VolumeGeometry& g = r.volume.geometry();
    out.value(std::uint8_t(0));
    out.value(g);
    out.text(r.modality);
    out.text(r.series_description);
    out.value(r.slice_count);
    out.value(std::uint64_t(r.warnings.size()));
    for (const std::string& w : r.warnings) out.text(w);
    out.bytes(r.volume.voxels().data(), r.volume.voxels().size() * sizeof(float));
}

}  // namespace

DicomReadResult read_dicom(const std::string& path) {
    // Debian's GDCM keeps its assertions, and some malformed files trip them (an abort),
    // and its decoders are C code fed with the file's bytes: the file is read in a child
    // process, so that a crash there is a refusal of the file here.
    std::uint8_t status = 255;
    bool complete = false;
    DicomReadResult result;
    std::string source, field, what;
    const std::optional<std::string> ended = base::run_forked(
        [&](int fd) {
            base::PipeWriter out(fd);
            try {
                send_result(out, read_dicom_here(path));
            } catch (const std::bad_alloc&) {
                out.value(std::uint8_t(1));
                out.text(path);
                out.text("");
                out.text(
                    "declares more data than it holds (beyond the reading's memory budget): "
                    "the file is malformed");
            } catch (const base::InputError& e) {
                out.value(std::uint8_t(1));
                out.text(e.source());
                out.text(e.field());
                out.text(e.what());
            } catch (const std::exception& e) {
                out.value(std::uint8_t(2));
                out.text(e.what());
            }
        },
        [&](int fd) {
            base::PipeReader in(fd);
            complete = in.value(status);
            if (complete && status == 0) {
                VolumeGeometry g;
                std::uint64_t warnings = 0;
                complete = in.value(g) && in.text(result.modality) &&
                           in.text(result.series_description) && in.value(result.slice_count) &&
                           in.value(warnings) && warnings < 1000;
                for (std::uint64_t w = 0; complete && w < warnings; ++w)
                    complete = in.text(result.warnings.emplace_back());
                if (complete) {
                    result.volume = Volume(g);
                    complete = in.bytes(result.volume.voxels().data(),
                                        result.volume.voxels().size() * sizeof(float));
                }
            } else if (complete && status == 1) {
                complete = in.text(source) && in.text(field) && in.text(what);
            } else if (complete && status == 2) {
                complete = in.text(what);
            }
        },
        0, /*quiet: GDCM's assertion messages are not ours to print*/ true);
    if (!complete || ended)
        throw base::InputError(path, "",
                               "GDCM failed reading it (" + ended.value_or("exit status 0") +
                                   "): the file is malformed");
    if (status == 1) {
        // The child's message less the source and field that InputError puts in front.
        const std::string prefix = source + (field.empty() ? "" : ": field '" + field + "'") + ": ";
        throw base::InputError(
            source, field,
            what.compare(0, prefix.size(), prefix) == 0 ? what.substr(prefix.size()) : what);
    }
    if (status == 2) throw std::runtime_error(what);
    return result;
}

}  // namespace sonotrace::tissue
