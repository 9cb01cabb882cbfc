#include "tissue/image_io.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <string_view>

#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/file_status.h"
#include "tissue/base/memory.h"

namespace sonotrace::tissue {

namespace {

namespace fs = std::filesystem;
using OIIO::TypeDesc;

std::string lower_extension(const std::string& path) {
    std::string ext = fs::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    return ext;
}

template <typename T>
void reduce_channels(const std::vector<unsigned char>& raw, int channels, float* out,
                     std::size_t pixels) {
    const T* in = reinterpret_cast<const T*>(raw.data());
    for (std::size_t p = 0; p < pixels; ++p) {
        const T* px = in + p * std::size_t(channels);
        out[p] =
            channels >= 3
                ? float(0.2126 * double(px[0]) + 0.7152 * double(px[1]) + 0.0722 * double(px[2]))
                : float(px[0]);
    }
}

struct ImageSlice {
    int width = 0, height = 0, channels = 0;
};

// Reads `path` into `out` (width*height floats). Returns the size it found.
// The format a file's first bytes declare, of those image volumes are read from (the
// documentation's, volume_io.h), or "" for any other.
std::string image_format_of(const std::string& path) {
    unsigned char head[8] = {};
    if (std::FILE* f = std::fopen(path.c_str(), "rb")) {
        const std::size_t n = std::fread(head, 1, sizeof head, f);
        std::fclose(f);
        if (n < 4) return "";
    } else {
        return "";
    }
    auto starts = [&](std::initializer_list<int> magic) {
        int k = 0;
        for (const int byte : magic)
            if (head[k++] != byte) return false;
        return true;
    };
    if (starts({0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A})) return "png";
    if (starts({'I', 'I', 42, 0}) || starts({'M', 'M', 0, 42}) || starts({'I', 'I', 43, 0}) ||
        starts({'M', 'M', 0, 43}))
        return "tiff";
    if (starts({0xFF, 0xD8, 0xFF})) return "jpeg";
    if (starts({0x76, 0x2F, 0x31, 0x01})) return "openexr";
    return "";
}

ImageSlice read_into(const std::string& path, Voxels* out, const ImageSlice* expect) {
    if (!fs::exists(base::file_status(path, path, "")))
        throw base::InputError(path, "", "file not found");
    // The formats the documentation promises, whatever the file's name, told by their
    // first bytes and opened by their own reader alone. OpenImageIO's open() tries every
    // reader it has on a file its named one refuses: the others (WebP, RLA, ...) declare
    // sizes a few bytes can claim (a 21-byte WebP of 16384 x 16384 pixels took 2.2 GB),
    // RLA's aborts the process on a malformed header, and none is what scans come in.
    const std::string file_format = image_format_of(path);
    if (file_format.empty())
        throw base::InputError(path, "format",
                               "is not a PNG, TIFF, JPEG or EXR file (by its first bytes); image "
                               "volumes are read from those");
    // Stored colour values, not premultiplied by alpha (which we ignore).
    OIIO::ImageSpec config;
    config.attribute("oiio:UnassociatedAlpha", 1);
    auto in = OIIO::ImageInput::create(file_format, false, &config);
    OIIO::ImageSpec opened;
    if (!in || !in->open(path, opened, config))
        throw base::InputError(path, "",
                               "cannot read image: " + (in ? in->geterror() : OIIO::geterror()));
    const OIIO::ImageSpec& spec = in->spec();
    ImageSlice slice{spec.width, spec.height, spec.nchannels};
    if (spec.depth > 1)
        throw base::InputError(path, "depth", "volumetric images are not supported");
    if (expect && (slice.width != expect->width || slice.height != expect->height)) {
        throw base::InputError(path, "size",
                               std::to_string(slice.width) + "x" + std::to_string(slice.height) +
                                   " differs from the first slice's " +
                                   std::to_string(expect->width) + "x" +
                                   std::to_string(expect->height));
    }
    const std::size_t pixels = std::size_t(slice.width) * slice.height;
    // A PNG's rows are deflate-compressed, at most 1032:1 (plus a filter byte per row): a
    // header declaring more than that is truncated, corrupt or a decompression bomb, and
    // is refused before anything is allocated or decoded.
    if (file_format == "png") {
        const double declared = double(pixels) * slice.channels * spec.format.size();
        const double bytes = double(fs::file_size(path));
        if (declared > 1100.0 * bytes + 65536.0) {
            std::ostringstream s;
            s.precision(3);
            s << "declares " << slice.width << " x " << slice.height << " pixels ("
              << declared / 1048576.0 << " MiB) in " << bytes
              << " bytes; deflate compresses at most 1032:1, so the file is truncated or corrupt";
            throw base::InputError(path, "size", s.str());
        }
    }
    base::check_allocation(double(pixels) * slice.channels * 8.0, path, "size");

    // Integers are read raw (no OIIO normalisation to 0..1); floats of any width as float.
    TypeDesc format = spec.format;
    const bool integer =
        spec.channelformats.empty() &&
        (format == TypeDesc::UINT8 || format == TypeDesc::INT8 || format == TypeDesc::UINT16 ||
         format == TypeDesc::INT16 || format == TypeDesc::UINT32 || format == TypeDesc::INT32);
    if (!integer) format = TypeDesc::FLOAT;
    std::vector<unsigned char> raw(pixels * slice.channels * format.size());
    if (!in->read_image(0, 0, 0, slice.channels, format, raw.data())) {
        throw base::InputError(path, "data", "cannot decode image: " + in->geterror());
    }
    const std::size_t offset = out->size();
    out->resize(offset + pixels);
    float* dst = out->data() + offset;
    if (format == TypeDesc::UINT8)
        reduce_channels<uint8_t>(raw, slice.channels, dst, pixels);
    else if (format == TypeDesc::INT8)
        reduce_channels<int8_t>(raw, slice.channels, dst, pixels);
    else if (format == TypeDesc::UINT16)
        reduce_channels<uint16_t>(raw, slice.channels, dst, pixels);
    else if (format == TypeDesc::INT16)
        reduce_channels<int16_t>(raw, slice.channels, dst, pixels);
    else if (format == TypeDesc::UINT32)
        reduce_channels<uint32_t>(raw, slice.channels, dst, pixels);
    else if (format == TypeDesc::INT32)
        reduce_channels<int32_t>(raw, slice.channels, dst, pixels);
    else
        reduce_channels<float>(raw, slice.channels, dst, pixels);
    return slice;
}

VolumeGeometry image_geometry(int width, int height, int slices, const glm::dvec3& spacing,
                              const std::string& source) {
    VolumeGeometry g;
    g.dims = glm::ivec3(width, height, slices);
    g.spacing = spacing;
    g.validate(source);
    return g;
}

// Natural order: compare the last run of digits numerically, then the whole name.
long trailing_number(const std::string& name) {
    const std::string stem = fs::path(name).stem().string();
    std::size_t end = stem.size();
    while (end > 0 && !std::isdigit(static_cast<unsigned char>(stem[end - 1]))) --end;
    std::size_t begin = end;
    while (begin > 0 && std::isdigit(static_cast<unsigned char>(stem[begin - 1]))) --begin;
    return begin == end ? -1
                        : std::stol(stem.substr(begin, std::min<std::size_t>(end - begin, 18)));
}

}  // namespace

bool has_image_extension(const std::string& path) {
    static const char* known[] = {".png", ".tif", ".tiff", ".jpg", ".jpeg", ".exr",
                                  ".bmp", ".pgm", ".ppm",  ".hdr", ".dpx",  ".tga"};
    const std::string ext = lower_extension(path);
    return std::any_of(std::begin(known), std::end(known), [&](const char* k) { return ext == k; });
}

std::vector<std::string> list_image_stack(const std::string& spec) {
    std::vector<std::string> files;
    if (fs::is_directory(base::file_status(spec, spec, ""))) {
        for (const auto& entry : fs::directory_iterator(spec)) {
            if (entry.is_regular_file() && has_image_extension(entry.path().string())) {
                files.push_back(entry.path().string());
            }
        }
        std::sort(files.begin(), files.end(), [](const std::string& a, const std::string& b) {
            const long na = trailing_number(a), nb = trailing_number(b);
            return na != nb ? na < nb : a < b;
        });
        if (files.empty()) throw base::InputError(spec, "", "directory holds no image files");
        return files;
    }
    const ImagePattern pattern = parse_image_pattern(spec);
    int first = kPatternIndexLimit;
    const fs::path prefix(pattern.prefix);
    if (pattern.suffix.find('/') == std::string::npos && !pattern.prefix.empty() &&
        pattern.prefix.back() != '/') {
        // The first index from one listing of the directory, not 10,000 probes (a pattern
        // matching nothing took seconds, and minutes on a network file system).
        const fs::path dir = prefix.has_parent_path() ? prefix.parent_path() : fs::path(".");
        const std::string stem = prefix.filename().string();
        std::error_code ec;
        for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
            const std::string name = it->path().filename().string();
            if (name.size() <= stem.size() + pattern.suffix.size() || name.rfind(stem, 0) != 0 ||
                !name.ends_with(pattern.suffix))
                continue;
            const std::string middle =
                name.substr(stem.size(), name.size() - stem.size() - pattern.suffix.size());
            // Padding (' ' or '0'), then at most four digits: indices below 10,000.
            const std::size_t digits = std::min(middle.find_first_not_of(" 0"), middle.size());
            if (middle.size() - digits > 4 ||
                middle.find_first_not_of("0123456789", digits) != std::string::npos)
                continue;
            const int index = digits == middle.size() ? 0 : std::stoi(middle.substr(digits));
            const std::string path = prefix.has_parent_path() ? (dir / name).string() : name;
            if (index < first && pattern.name(index) == path) first = index;
        }
    } else {
        first = 0;
        while (first < kPatternIndexLimit && !fs::exists(pattern.name(first))) ++first;
    }
    if (first == kPatternIndexLimit)
        throw base::InputError(spec, "", "no file matches the pattern (indices 0..9999)");
    for (int index = first; fs::exists(pattern.name(index)); ++index)
        files.push_back(pattern.name(index));
    return files;
}

std::string ImagePattern::name(int index) const {
    std::string digits = std::to_string(index);
    if (int(digits.size()) < width) digits.insert(0, std::size_t(width) - digits.size(), pad);
    return prefix + digits + suffix;
}

ImagePattern parse_image_pattern(const std::string& spec) {
    // Parsed here, never handed to printf: the text is the user's, and a format of theirs
    // could read or write memory (%s, %n) or run for minutes (%99999999d).
    const std::string accepted = "takes one index as %d, %Nd or %0Nd (N at most " +
                                 std::to_string(kPatternMaxWidth) + ") and %% for a percent sign";
    ImagePattern pattern;
    bool found = false;
    std::string* out = &pattern.prefix;
    for (std::size_t n = 0; n < spec.size(); ++n) {
        if (spec[n] != '%') {
            *out += spec[n];
            continue;
        }
        if (n + 1 < spec.size() && spec[n + 1] == '%') {
            *out += '%';
            ++n;
            continue;
        }
        std::size_t end = n + 1;
        if (end < spec.size() && spec[end] == '0') {
            pattern.pad = '0';
            ++end;
        }
        const std::size_t digits_begin = end;
        while (end < spec.size() && std::isdigit(static_cast<unsigned char>(spec[end]))) ++end;
        const std::size_t digit_count = end - digits_begin;
        if (found || end >= spec.size() || spec[end] != 'd' || digit_count > 1 ||
            (digit_count == 1 && spec[digits_begin] - '0' > kPatternMaxWidth)) {
            throw base::InputError(spec, "", "an image-stack pattern " + accepted);
        }
        pattern.width = digit_count ? spec[digits_begin] - '0' : 0;
        found = true;
        out = &pattern.suffix;
        n = end;
    }
    if (!found)
        throw base::InputError(
            spec, "",
            "not a directory or an image-stack pattern such as img_%03d.png (" + accepted + ")");
    return pattern;
}

Volume read_image(const std::string& path, const glm::dvec3& spacing) {
    return read_image_stack({path}, spacing, path);
}

Volume read_image_stack(const std::vector<std::string>& files, const glm::dvec3& spacing,
                        const std::string& source) {
    if (files.empty()) throw base::InputError(source, "", "no image files");
    Voxels voxels;
    ImageSlice first;
    for (std::size_t n = 0; n < files.size(); ++n) {
        const ImageSlice slice = read_into(files[n], &voxels, n == 0 ? nullptr : &first);
        if (n == 0) {
            first = slice;
            base::check_allocation(
                double(slice.width) * slice.height * files.size() * sizeof(float), source, "size");
            voxels.reserve(std::size_t(slice.width) * slice.height * files.size());
        }
    }
    Volume volume(image_geometry(first.width, first.height, int(files.size()), spacing, source),
                  std::move(voxels));
    volume.require_finite(source);
    return volume;
}

void write_gray_image(const std::string& path, int width, int height,
                      const std::vector<float>& pixels, int bits) {
    const TypeDesc format = bits == 8    ? TypeDesc::UINT8
                            : bits == 16 ? TypeDesc::UINT16
                                         : TypeDesc::FLOAT;
    OIIO::ImageSpec spec(width, height, 1, format);
    // OIIO converts float -> integer by normalising 0..1; pass raw values as float for
    // float files, otherwise scale so stored integers equal the given values.
    std::vector<float> scaled(pixels);
    if (bits != 32) {
        const float range = bits == 8 ? 255.0f : 65535.0f;
        for (float& v : scaled) v /= range;
    }
    if (base::output_name(path) != path) {  // already staged by the caller's transaction
        write_image_file(path, spec, TypeDesc::FLOAT, scaled.data());
        return;
    }
    base::OutputTransaction transaction;
    write_image_file(transaction.stage(path), spec, TypeDesc::FLOAT, scaled.data());
    transaction.commit();
}

void write_image_file(const std::string& path, const OIIO::ImageSpec& spec, OIIO::TypeDesc given,
                      const void* pixels, OIIO::stride_t row_bytes) {
    const std::string shown = base::output_name(path);
    auto out = OIIO::ImageOutput::create(path);
    if (!out)
        throw base::InputError(shown, "",
                               "no image writer for this extension: " + OIIO::geterror());
    OIIO::ImageSpec stamped = spec;
    stamped.attribute("DateTime", "");  // no write time: same inputs, same bytes
    std::vector<unsigned char> encoded;
    OIIO::Filesystem::IOVecOutput memory(encoded);
    if (!out->supports("ioproxy") || !out->set_ioproxy(&memory))
        throw base::InputError(shown, "", "the image writer cannot encode to memory");
    if (!out->open(path, stamped) ||
        !out->write_image(given, pixels, OIIO::AutoStride, row_bytes) || !out->close()) {
        throw base::InputError(shown, "", "cannot encode the image: " + out->geterror());
    }
    base::write_file(path, encoded.data(), encoded.size());
}

}  // namespace sonotrace::tissue
