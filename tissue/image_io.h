#pragma once
// 2D images and numbered image stacks (PNG, TIFF, JPEG, EXR, and whatever else
// OpenImageIO reads) as volumes. Images carry no physical size, so the caller gives the
// pixel spacing (and the slice spacing for stacks).
//
// Index i runs along image columns, j along rows (downwards, as stored), k along the
// stack; the direction is the identity and the origin zero. Integer pixels keep their
// stored values (0..255 for 8-bit, 0..65535 for 16-bit), so label images stay labels;
// colour images are reduced to Rec. 709 luminance and alpha is ignored.
#include <string>
#include <vector>

#include <OpenImageIO/imageio.h>

#include "tissue/volume.h"

namespace sonotrace::tissue {

// True if `path` names a file OpenImageIO can probably read (by extension).
bool has_image_extension(const std::string& path);

// Lists the files of a stack: a directory (its image files in natural numeric order)
// or a pattern such as "slices/img_%03d.png" (consecutive indices from the first
// one found among 0..9999). Throws base::InputError if nothing matches.
std::vector<std::string> list_image_stack(const std::string& spec);

// A numbered-file pattern in printf's spelling, read by our own parser: one %d, %Nd or
// %0Nd (N <= kPatternMaxWidth), and %% for a literal percent sign. Anything else throws
// base::InputError naming the pattern.
inline constexpr int kPatternMaxWidth = 9;
inline constexpr int kPatternIndexLimit = 10000;
struct ImagePattern {
    std::string prefix, suffix;
    int width = 0;   // minimum number of digits
    char pad = ' ';  // '0' for %0Nd
    std::string name(int index) const;
};
ImagePattern parse_image_pattern(const std::string& spec);

// Reads one image (one slice) or a stack into a volume with the given spacing (mm).
Volume read_image(const std::string& path, const glm::dvec3& spacing);
Volume read_image_stack(const std::vector<std::string>& files, const glm::dvec3& spacing,
                        const std::string& source);

// Encodes an image of `spec` (the file format by `path`'s extension) from `pixels` of type
// `given` in memory, then writes it with base::write_file(): a full disk is an error naming the
// output, never a truncated image reported as written. `row_bytes`: AutoStride when
// packed.
void write_image_file(const std::string& path, const OIIO::ImageSpec& spec, OIIO::TypeDesc given,
                      const void* pixels, OIIO::stride_t row_bytes = OIIO::AutoStride);

// Writes a single-channel image (used by tests and tools); 8- or 16-bit by `bits`,
// or 32-bit float when bits == 32. Atomic (staged and renamed, unless `path` is already a
// staged temporary of the caller's base::OutputTransaction).
void write_gray_image(const std::string& path, int width, int height,
                      const std::vector<float>& pixels, int bits);

}  // namespace sonotrace::tissue
