#include "tissue/nifti_io.h"

#include <nifti1_io.h>
#include <zlib.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <sstream>

#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/file_status.h"
#include "tissue/base/memory.h"

namespace sonotrace::tissue {

namespace {

namespace fs = std::filesystem;

struct NiftiImageDeleter {
    void operator()(nifti_image* nim) const { nifti_image_free(nim); }
};
using NiftiImagePtr = std::unique_ptr<nifti_image, NiftiImageDeleter>;

std::string number(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

// Reads the first 348 bytes (through zlib, so .nii.gz works) to say precisely why a
// file is not a NIfTI-1 file before niftilib gives up with a generic failure.
void check_header_bytes(const std::string& path) {
    gzFile file = gzopen(path.c_str(), "rb");
    if (!file) throw base::InputError(path, "", "cannot open file");
    unsigned char header[348];
    const int got = gzread(file, header, sizeof header);
    gzclose(file);
    if (got < 0) throw base::InputError(path, "", "corrupt compressed data in the header");
    if (got < int(sizeof header)) {
        throw base::InputError(
            path, "sizeof_hdr",
            "truncated header: " + std::to_string(got) + " of 348 bytes present");
    }
    int32_t sizeof_hdr = 0;
    std::memcpy(&sizeof_hdr, header, 4);
    const int32_t swapped = int32_t(__builtin_bswap32(uint32_t(sizeof_hdr)));
    if (sizeof_hdr == 540 || swapped == 540) {
        throw base::InputError(path, "sizeof_hdr",
                               "NIfTI-2 files are not supported; convert to NIfTI-1");
    }
    if (sizeof_hdr != 348 && swapped != 348) {
        throw base::InputError(
            path, "sizeof_hdr",
            "not a NIfTI-1 file (sizeof_hdr is " + std::to_string(sizeof_hdr) + ", expected 348)");
    }
}

bool is_supported_datatype(int datatype) {
    switch (datatype) {
        case DT_UINT8:
        case DT_INT8:
        case DT_UINT16:
        case DT_INT16:
        case DT_UINT32:
        case DT_INT32:
        case DT_UINT64:
        case DT_INT64:
        case DT_FLOAT32:
        case DT_FLOAT64:
            return true;
        default:
            return false;
    }
}

template <typename T>
void convert(const void* data, std::size_t count, double slope, double inter, float* out) {
    const T* in = static_cast<const T*>(data);
    for (std::size_t n = 0; n < count; ++n) out[n] = float(double(in[n]) * slope + inter);
}

void convert_voxels(int datatype, const void* data, std::size_t count, double slope, double inter,
                    float* out) {
    switch (datatype) {
        case DT_UINT8:
            convert<uint8_t>(data, count, slope, inter, out);
            break;
        case DT_INT8:
            convert<int8_t>(data, count, slope, inter, out);
            break;
        case DT_UINT16:
            convert<uint16_t>(data, count, slope, inter, out);
            break;
        case DT_INT16:
            convert<int16_t>(data, count, slope, inter, out);
            break;
        case DT_UINT32:
            convert<uint32_t>(data, count, slope, inter, out);
            break;
        case DT_INT32:
            convert<int32_t>(data, count, slope, inter, out);
            break;
        case DT_UINT64:
            convert<uint64_t>(data, count, slope, inter, out);
            break;
        case DT_INT64:
            convert<int64_t>(data, count, slope, inter, out);
            break;
        case DT_FLOAT32:
            convert<float>(data, count, slope, inter, out);
            break;
        case DT_FLOAT64:
            convert<double>(data, count, slope, inter, out);
            break;
        default:
            break;  // refused earlier by is_supported_datatype
    }
}

// mm per NIfTI spatial unit (unknown units are taken as mm, as most tools do).
double unit_to_mm(int xyz_units) {
    switch (xyz_units) {
        case NIFTI_UNITS_METER:
            return 1000.0;
        case NIFTI_UNITS_MICRON:
            return 0.001;
        default:
            return 1.0;
    }
}

// Reads the voxel bytes from the data file (the .nii itself or the .img of a pair,
// compressed or not) and refuses short files.
void read_voxel_bytes(const nifti_image& nim, const std::string& path,
                      std::vector<unsigned char>* bytes) {
    const std::string data_file = nim.iname ? nim.iname : path;
    gzFile file = gzopen(data_file.c_str(), "rb");
    if (!file) throw base::InputError(data_file, "", "cannot open the voxel data file");
    std::size_t got = 0;
    if (gzseek(file, nim.iname_offset, SEEK_SET) == nim.iname_offset) {
        while (got < bytes->size()) {
            const unsigned chunk = unsigned(std::min<std::size_t>(bytes->size() - got, 1u << 30));
            const int n = gzread(file, bytes->data() + got, chunk);
            if (n <= 0) break;
            got += std::size_t(n);
        }
    }
    gzclose(file);
    if (got < bytes->size()) {
        throw base::InputError(data_file, "data",
                               "file is truncated or corrupt: " + std::to_string(got) + " of " +
                                   std::to_string(bytes->size()) + " voxel bytes could be read");
    }
}

glm::dmat4 to_glm(const mat44& m) {
    glm::dmat4 g(1.0);
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) g[c][r] = m.m[r][c];
    }
    return g;
}

}  // namespace

NiftiReadResult read_nifti(const std::string& path) {
    NiftiReadResult result;
    const fs::file_status status = base::file_status(path, path, "");
    if (!fs::exists(status)) throw base::InputError(path, "", "file not found");
    if (fs::is_directory(status))
        throw base::InputError(path, "", "is a directory, not a NIfTI file");
    nifti_set_debug_level(0);  // we report errors ourselves, naming the field
    check_header_bytes(path);

    // Validate the header fields before niftilib allocates anything.
    int swapped = 0;
    std::unique_ptr<nifti_1_header, decltype(&std::free)> hdr(
        nifti_read_header(path.c_str(), &swapped, 1), &std::free);
    if (!hdr)
        throw base::InputError(path, "header", "header is inconsistent (niftilib rejected it)");
    const int ndim = hdr->dim[0];
    if (ndim < 1 || ndim > 7) {
        throw base::InputError(path, "dim[0]", "must be 1..7, got " + std::to_string(ndim));
    }
    double voxel_total = 1.0;
    for (int d = 1; d <= ndim; ++d) {
        if (hdr->dim[d] < 1) {
            throw base::InputError(path, "dim[" + std::to_string(d) + "]",
                                   "must be at least 1, got " + std::to_string(hdr->dim[d]));
        }
        voxel_total *= hdr->dim[d];
    }
    if (!is_supported_datatype(hdr->datatype)) {
        throw base::InputError(path, "datatype",
                               std::string("unsupported datatype ") +
                                   nifti_datatype_string(hdr->datatype) + " (" +
                                   std::to_string(hdr->datatype) +
                                   "); sonotrace reads real scalar integer and float voxels");
    }
    for (int d = 1; d <= std::min(ndim, 3); ++d) {
        const double pd = hdr->pixdim[d];
        const std::string field = "pixdim[" + std::to_string(d) + "]";
        if (!std::isfinite(pd) || pd < 0.0 || (pd == 0.0 && hdr->dim[d] > 1)) {
            throw base::InputError(path, field,
                                   "voxel spacing must be positive and finite, got " + number(pd));
        }
    }
    if (!std::isfinite(hdr->scl_slope) || !std::isfinite(hdr->scl_inter)) {
        throw base::InputError(path, "scl_slope/scl_inter", "scaling is not finite");
    }
    base::check_allocation(voxel_total * (hdr->bitpix / 8.0 + sizeof(float)), path, "dim");

    NiftiImagePtr nim(nifti_image_read(path.c_str(), 0));  // header only
    if (!nim) throw base::InputError(path, "header", "niftilib could not interpret the header");

    VolumeGeometry g;
    g.dims = glm::ivec3(nim->nx, std::max(1, nim->ny), std::max(1, nim->nz));
    if (ndim < 3) g.dims.z = 1;
    if (ndim < 2) g.dims.y = 1;
    if (nim->nt > 1 || nim->nu > 1 || nim->nv > 1 || nim->nw > 1) {
        result.warnings.push_back(path + ": " + std::to_string(ndim) +
                                  "D file; only the first 3D volume is used");
    }

    // Index -> world: sform, else qform, else pixdim scaling (NIfTI "method 1").
    const double to_mm = unit_to_mm(XYZT_TO_SPACE(hdr->xyzt_units));
    glm::dmat4 affine(1.0);
    result.anatomical = nim->sform_code > 0 || nim->qform_code > 0;
    if (nim->sform_code > 0) {
        affine = to_glm(nim->sto_xyz);
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 4; ++c) {
                if (!std::isfinite(affine[c][r])) {
                    throw base::InputError(path, "srow_" + std::string(1, "xyz"[r]),
                                           "is not finite");
                }
            }
        }
    } else if (nim->qform_code > 0) {
        affine = to_glm(nim->qto_xyz);
    } else {
        affine[0][0] = nim->dx > 0 ? nim->dx : 1.0;
        affine[1][1] = nim->dy > 0 ? nim->dy : 1.0;
        affine[2][2] = nim->dz > 0 ? nim->dz : 1.0;
        result.warnings.push_back(path + ": no qform or sform; using pixdim with origin 0");
    }
    for (int c = 0; c < 3; ++c) {
        glm::dvec3 column = glm::dvec3(affine[c]) * to_mm;
        double length = glm::length(column);
        if (length == 0.0 && g.dims[c] == 1) {
            // A single-slice axis without spacing: give it 1 mm so the frame stays valid.
            column = glm::dvec3(0.0);
            column[c] = 1.0;
            length = 1.0;
        }
        if (!(length > 0.0) || !std::isfinite(length)) {
            throw base::InputError(path, nim->sform_code > 0 ? "srow" : "pixdim",
                                   "axis " + std::to_string(c) + " has zero or invalid spacing");
        }
        g.spacing[c] = length;
        g.direction[c] = column / length;
    }
    g.origin = glm::dvec3(affine[3]) * to_mm;
    g.validate(path);

    // Voxels of the first 3D volume. Read here rather than by nifti_image_load, which
    // zero-fills a truncated file with only a warning.
    const std::size_t count = g.voxel_count();
    {  // the declared voxels must fit in the data file: refused before allocating them
        const std::string data_file = nim->iname ? nim->iname : path;
        std::error_code error;
        const double file_bytes = double(fs::file_size(data_file, error));
        if (error) throw base::InputError(data_file, "", "cannot read the voxel data file's size");
        const bool compressed = data_file.size() > 3 && data_file.ends_with(".gz");
        // vox_offset is a float in the header that niftilib converts to an int: out of
        // range it wraps, and a negative offset would make the file seem to hold anything.
        if (nim->iname_offset < 0 || (!compressed && double(nim->iname_offset) > file_bytes))
            throw base::InputError(
                data_file, "vox_offset",
                "the voxel data's offset (" + base::number_text(double(nim->iname_offset)) +
                    ") lies outside the " + base::number_text(file_bytes) + "-byte file");
        // gzip's deflate compresses at most 1032:1
        const double can_hold =
            compressed ? 1100.0 * file_bytes + 65536.0 : file_bytes - double(nim->iname_offset);
        const double declared = double(count) * double(nim->nbyper);
        if (declared > can_hold) {
            throw base::InputError(
                data_file, "data",
                "dim declares " + base::number_text(declared) + " voxel bytes, more than the " +
                    base::number_text(file_bytes) + "-byte file can hold: truncated or corrupt");
        }
    }
    std::vector<unsigned char> bytes(count * std::size_t(nim->nbyper));
    read_voxel_bytes(*nim, path, &bytes);
    if (nim->nbyper > 1 && nim->byteorder != nifti_short_order()) {
        nifti_swap_Nbytes(count, nim->nbyper, bytes.data());
    }
    // Scaled to float; NaN/Inf refused (the tracer's gradients would spread them).
    Voxels voxels(count);
    const bool scaled = nim->scl_slope != 0.0f;
    convert_voxels(nim->datatype, bytes.data(), count, scaled ? nim->scl_slope : 1.0,
                   scaled ? nim->scl_inter : 0.0, voxels.data());
    result.volume = Volume(g, std::move(voxels));
    result.volume.require_finite(path);
    return result;
}

void write_nifti(const Volume& volume, const std::string& path) {
    const VolumeGeometry& g = volume.geometry();
    base::OutputTransaction transaction;
    const std::string temporary = transaction.stage(path);

    int dims[8] = {3, g.dims.x, g.dims.y, g.dims.z, 1, 1, 1, 1};
    NiftiImagePtr nim(nifti_make_new_nim(dims, DT_FLOAT32, 1));
    if (!nim) throw base::InputError(path, "", "niftilib could not create the image");
    nim->nifti_type = NIFTI_FTYPE_NIFTI1_1;  // single .nii(.gz) file
    std::memcpy(nim->data, volume.voxels().data(), volume.size() * sizeof(float));

    const glm::dmat4 affine = g.index_to_world_matrix();
    mat44 m;
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) m.m[r][c] = float(affine[c][r]);
    }
    nim->sform_code = NIFTI_XFORM_SCANNER_ANAT;
    nim->sto_xyz = m;
    nim->sto_ijk = nifti_mat44_inverse(m);
    // The qform can only hold a rotation (+ flip); for sheared directions the sform is exact.
    float qb, qc, qd, qx, qy, qz, dx, dy, dz, qfac;
    nifti_mat44_to_quatern(m, &qb, &qc, &qd, &qx, &qy, &qz, &dx, &dy, &dz, &qfac);
    nim->qform_code = NIFTI_XFORM_SCANNER_ANAT;
    nim->quatern_b = qb, nim->quatern_c = qc, nim->quatern_d = qd;
    nim->qoffset_x = qx, nim->qoffset_y = qy, nim->qoffset_z = qz;
    nim->qfac = qfac;
    nim->dx = nim->pixdim[1] = float(g.spacing.x);
    nim->dy = nim->pixdim[2] = float(g.spacing.y);
    nim->dz = nim->pixdim[3] = float(g.spacing.z);
    nim->qto_xyz = nifti_quatern_to_mat44(qb, qc, qd, qx, qy, qz, nim->dx, nim->dy, nim->dz, qfac);
    nim->qto_ijk = nifti_mat44_inverse(nim->qto_xyz);
    nim->xyz_units = NIFTI_UNITS_MM;
    std::strncpy(nim->descrip, "sonotrace", sizeof nim->descrip - 1);

    if (nifti_set_filenames(nim.get(), temporary.c_str(), 0, 1) != 0) {
        throw base::InputError(path, "", "niftilib rejected the file name (use .nii or .nii.gz)");
    }
    // gzip level 1 ("wb1"): zlib's default (6) spent most of `sonotrace tissue --nifti`'s
    // time compressing float maps, for files 2 % smaller (ten maps of a 10 mm slab).
    nifti_image_write_hdr_img(nim.get(), 1, "wb1");
    std::error_code ec;
    if (!fs::exists(temporary, ec) || fs::file_size(temporary, ec) == 0) {
        throw base::InputError(path, "", "writing the NIfTI file failed");
    }
    transaction.commit();
}

}  // namespace sonotrace::tissue
