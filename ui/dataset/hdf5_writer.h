#pragma once
// Writing an HDF5 file in memory (HDF5's core driver, no backing store), whose bytes the
// caller stores with a checked writer (base::write_file): HDF5 never writes to disk, so a
// full disk cannot leave its library with a file it fails to close. The dataset shards
// and the channel-data files are written with it.
#include <hdf5.h>

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "tissue/base/error.h"

namespace sonotrace::dataset::hdf5 {

// The name of a file HDF5 holds in memory. Its core driver opens the name first and
// refuses an image if that succeeds: this is a name no file can have.
inline constexpr const char* kImageName = "/dev/null/hdf5-image";

// An HDF5 identifier closed by its own close function.
class Handle {
  public:
    Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
    ~Handle() {
        if (id_ >= 0) close_(id_);
    }
    Handle(const Handle&) = delete;
    Handle& operator=(const Handle&) = delete;
    operator hid_t() const { return id_; }
    bool ok() const { return id_ >= 0; }

  private:
    hid_t id_;
    herr_t (*close_)(hid_t);
};

class ImageWriter {
  public:
    // The file is built in memory (HDF5's core driver, no backing store): HDF5 never
    // writes to disk, so a full disk cannot leave its library with a file it fails to
    // close (its exit handler crashed retrying). Our checked writer stores the bytes.
    // `userblock_bytes` (0 or a power of two >= 512) are left for a header of our own.
    ImageWriter(std::string name, std::size_t userblock_bytes) : name_(std::move(name)) {
        H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors become our messages
        Handle fcpl(H5Pcreate(H5P_FILE_CREATE), H5Pclose);
        H5Pset_obj_track_times(fcpl, false);
        if (userblock_bytes > 0)
            H5Pset_userblock(fcpl, userblock_bytes);  // our header, which HDF5 skips
        Handle fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
        H5Pset_fapl_core(fapl, std::size_t(1) << 20, false);
        file_ = H5Fcreate(kImageName, H5F_ACC_TRUNC, fcpl, fapl);
        check(file_, "create");
    }
    ~ImageWriter() {
        if (file_ >= 0) H5Fclose(file_);
    }
    // The finished file's bytes; the shard is closed.
    std::string image() {
        check(H5Fflush(file_, H5F_SCOPE_GLOBAL), "finish");
        const ssize_t size = H5Fget_file_image(file_, nullptr, 0);
        check(hid_t(size), "finish");
        std::string bytes(std::size_t(size), '\0');
        check(hid_t(H5Fget_file_image(file_, bytes.data(), bytes.size())), "finish");
        const herr_t status = H5Fclose(file_);
        file_ = -1;
        check(status, "finish");
        return bytes;
    }

    void check(hid_t status, const char* what) const {
        if (status < 0)
            throw base::InputError(
                name_, "", std::string("HDF5 could not ") + what + " the file (out of memory?)");
    }

    void attribute(const char* name, const std::string& text) {
        Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
        H5Tset_size(type, std::max<std::size_t>(1, text.size()));
        Handle space(H5Screate(H5S_SCALAR), H5Sclose);
        Handle a(H5Acreate2(file_, name, type, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
        check(a, "write an attribute of");
        check(H5Awrite(a, type, text.empty() ? "" : text.data()), "write an attribute of");
    }
    // On the file, or on the object `where` (a dataset, a group).
    void attribute(const char* name, double value, hid_t where = -1) {
        Handle space(H5Screate(H5S_SCALAR), H5Sclose);
        Handle a(H5Acreate2(where < 0 ? file_ : where, name, H5T_IEEE_F64LE, space, H5P_DEFAULT,
                            H5P_DEFAULT),
                 H5Aclose);
        check(a, "write an attribute of");
        check(H5Awrite(a, H5T_NATIVE_DOUBLE, &value), "write an attribute of");
    }
    void attribute(const char* name, uint64_t value) {
        Handle space(H5Screate(H5S_SCALAR), H5Sclose);
        Handle a(H5Acreate2(file_, name, H5T_STD_U64LE, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
        check(a, "write an attribute of");
        check(H5Awrite(a, H5T_NATIVE_UINT64, &value), "write an attribute of");
    }

    // A dataset of `dims`, chunked as `chunk` (empty: contiguous), deflated when chunked
    // and `deflate`; `attributes` (name, value) on it.
    void dataset(hid_t where, const char* name, hid_t file_type, hid_t memory_type,
                 const std::vector<hsize_t>& dims, const std::vector<hsize_t>& chunk,
                 const void* data, bool deflate = true,
                 const std::vector<std::pair<const char*, double>>& attributes = {}) {
        Handle space(H5Screate_simple(int(dims.size()), dims.data(), nullptr), H5Sclose);
        Handle dcpl(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
        H5Pset_obj_track_times(dcpl, false);
        if (!chunk.empty()) {
            H5Pset_chunk(dcpl, int(chunk.size()), chunk.data());
            if (deflate) H5Pset_deflate(dcpl, 4);
        }
        Handle d(H5Dcreate2(where, name, file_type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT),
                 H5Dclose);
        check(d, "create a dataset in");
        check(H5Dwrite(d, memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), "write");
        for (const auto& [key, value] : attributes) attribute(key, value, d);
    }

    hid_t group(const char* name) {
        Handle gcpl(H5Pcreate(H5P_GROUP_CREATE), H5Pclose);
        H5Pset_obj_track_times(gcpl, false);
        const hid_t g = H5Gcreate2(file_, name, H5P_DEFAULT, gcpl, H5P_DEFAULT);
        check(g, "create a group in");
        return g;
    }

    hid_t file() const { return file_; }

  private:
    std::string name_;
    hid_t file_ = -1;
};

}  // namespace sonotrace::dataset::hdf5
