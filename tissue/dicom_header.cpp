#include "tissue/dicom_header.h"

#include <gdcmAttribute.h>
#include <gdcmReader.h>
#include <gdcmTrace.h>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include "tissue/base/error.h"
#include "tissue/base/file_status.h"
#include "tissue/base/memory.h"

namespace fs = std::filesystem;

namespace sonotrace::tissue::dicom {

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

}  // namespace sonotrace::tissue::dicom
