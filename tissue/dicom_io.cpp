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
#include "tissue/dicom_header.h"

namespace fs = std::filesystem;

namespace sonotrace::tissue {

namespace {

using namespace dicom;

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
