#include "imaging/scan_conversion.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <mutex>

#include "probe/array_geometry.h"
#include "simulator/interactions.h"
#include "tissue/base/fast_math.h"

namespace sonotrace::imaging {

namespace {

// Where each pixel of a scan conversion reads the line data. The arctangent per pixel of
// a fan costs as much as the rest of the conversion, so the table is kept for the next
// frames of the same geometry (a sweep, the GUI).
struct ScanTable {
    std::array<double, 9> key{};
    int rows = 0, cols = 0;
    glm::dvec2 origin{0.0};
    std::vector<int32_t> first;      // l0 * samples + s0, -1 outside the scanned region
    std::vector<int32_t> next_line;  // offset to line l0 + 1 (0 with one line)
    std::vector<int32_t> sample;     // s0
    std::vector<float> line_frac, sample_frac;
};

// The lines' layout a table is made for (of LineData or BasebandLines).
struct Layout {
    int lines = 0, samples = 0;
    double fs_hz = 0.0;
};

std::shared_ptr<const ScanTable> scan_table(const Layout& data, const probe::Transducer& t,
                                            double pixel_mm) {
    const probe::ScanGeometry geometry(t);
    // Not a structured binding: the lambdas below capture lo (clang 14, the fuzz build's
    // compiler, cannot capture bindings).
    const std::pair<glm::dvec2, glm::dvec2> bounds = geometry.bounds();
    const glm::dvec2 lo = bounds.first, hi = bounds.second;
    const std::array<double, 9> key{double(int(t.type)), double(data.lines), double(data.samples),
                                    data.fs_hz,          pixel_mm,           t.depth_mm,
                                    t.radius_mm,         t.fov_deg,          t.array_length_mm()};
    static std::mutex mutex;
    static std::vector<std::shared_ptr<const ScanTable>> cache;  // most recent last
    {
        const std::lock_guard<std::mutex> lock(mutex);
        for (const auto& table : cache)
            if (table->key == key) return table;
    }
    auto table = std::make_shared<ScanTable>();
    table->key = key;
    table->origin = lo;
    table->cols = int(std::floor((hi.x - lo.x) / pixel_mm)) + 1;
    table->rows = int(std::floor((hi.y - lo.y) / pixel_mm)) + 1;
    const std::size_t pixels = std::size_t(table->rows) * std::size_t(table->cols);
    table->first.assign(pixels, -1);
    table->next_line.assign(pixels, 0);
    table->sample.assign(pixels, 0);
    table->line_frac.assign(pixels, 0.0f);
    table->sample_frac.assign(pixels, 0.0f);
    const double samples_per_mm = 2.0 * 1e-3 / tissue::kReferenceSpeed * data.fs_hz;
    tbb::parallel_for(0, table->rows, [&](int r) {
        for (int c = 0; c < table->cols; ++c) {
            const glm::dvec2 p = lo + glm::dvec2(c, r) * pixel_mm;
            const glm::dvec2 ld = geometry.line_and_depth(p);
            if (!(ld.x >= -0.5 && ld.x <= data.lines - 0.5 && ld.y >= 0.0 && ld.y <= t.depth_mm))
                continue;
            const double sm = std::clamp(ld.y * samples_per_mm, 0.0, double(data.samples - 1));
            const int s0 = std::min(int(sm), data.samples - 2);
            const std::size_t at = std::size_t(r) * std::size_t(table->cols) + std::size_t(c);
            table->sample[at] = s0;
            if (geometry.closed() && data.lines > 1 && (ld.x < 0.0 || ld.x > data.lines - 1)) {
                // Between the last line and the first, which neighbour on a closed array.
                const double l = ld.x < 0.0 ? ld.x + data.lines : ld.x;
                const int last = data.lines - 1;
                table->first[at] = last * data.samples + s0;
                table->next_line[at] = -last * data.samples;
                table->line_frac[at] = float(l - last);
                table->sample_frac[at] = float(sm - s0);
                continue;
            }
            const double l = std::clamp(ld.x, 0.0, double(data.lines - 1));
            const int l0 = std::min(int(l), std::max(data.lines - 2, 0));
            table->first[at] = l0 * data.samples + s0;
            table->next_line[at] = std::min(l0 + 1, data.lines - 1) == l0 ? 0 : data.samples;
            table->line_frac[at] = float(l - l0);
            table->sample_frac[at] = float(sm - s0);
        }
    });
    const std::lock_guard<std::mutex> lock(mutex);
    cache.push_back(table);
    if (cache.size() > 4) cache.erase(cache.begin());
    return table;
}

}  // namespace

ScanConverted scan_convert(const LineData& data, const probe::Transducer& t, double pixel_mm,
                           float outside) {
    const auto table = scan_table({data.lines, data.samples, data.fs_hz}, t, pixel_mm);
    ScanConverted out;
    out.pixel_mm = pixel_mm;
    out.origin = table->origin;
    out.image = cv::Mat(table->rows, table->cols, CV_32F, cv::Scalar(outside));
    out.inside = cv::Mat(table->rows, table->cols, CV_8U, cv::Scalar(0));
    tbb::parallel_for(0, table->rows, [&](int r) {
        float* image = out.image.ptr<float>(r);
        uint8_t* inside = out.inside.ptr<uint8_t>(r);
        for (int c = 0; c < table->cols; ++c) {
            const std::size_t at = std::size_t(r) * std::size_t(table->cols) + std::size_t(c);
            if (table->first[at] < 0) continue;
            // Bilinear between the two samples of the two lines around the pixel.
            const float* a = data.values.data() + table->first[at];
            const float* b = a + table->next_line[at];
            const float fl = table->line_frac[at], fsm = table->sample_frac[at];
            const float va = a[0] * (1 - fsm) + a[1] * fsm, vb = b[0] * (1 - fsm) + b[1] * fsm;
            image[c] = va * (1 - fl) + vb * fl;
            inside[c] = 255;
        }
    });
    return out;
}

namespace {

// One line's sample and the local means at it (scan_convert_display), side by side.
struct Sample {
    float re, im, power, cross;  // the signal, <|a|^2>, Re <a b*> with the next line
};

// A row of pixels of the display (see the header), in two passes: what each pixel reads
// of its lines (gathers: scalar), then the restoration and compression over the row
// (contiguous: it vectorises; AVX2 in its clone, no FMA in either, so the same numbers).
// samples: the Samples as floats; offsets: Compression's by sample; scratch: 4 count.
[[gnu::target_clones("avx2", "default")]] void display_row(
    int count, const int32_t* __restrict first, const int32_t* __restrict next_line,
    const float* __restrict line_frac, const float* __restrict sample_frac,
    const int32_t* __restrict sample, const float* __restrict samples,
    const float* __restrict offsets, float half_scale, float* __restrict scratch,
    float* __restrict out) {
    float* __restrict z_power = scratch;
    float* __restrict linear = scratch + count;
    float* __restrict coherent = scratch + 2 * count;
    float* __restrict offset = scratch + 3 * count;
    for (int c = 0; c < count; ++c) {
        const int32_t from = first[c];
        if (from < 0) {  // outside the scanned region: nothing shown
            z_power[c] = 0.0f, linear[c] = 0.0f, coherent[c] = 1.0f, offset[c] = 0.0f;
            continue;
        }
        const float f = line_frac[c], g = sample_frac[c];
        // Linear between the two samples of a line (4 floats apart).
        const float* a = samples + 4 * std::ptrdiff_t(from);
        const float* b = samples + 4 * (std::ptrdiff_t(from) + next_line[c]);
        const float a_re = a[0] + g * (a[4] - a[0]), a_im = a[1] + g * (a[5] - a[1]);
        const float b_re = b[0] + g * (b[4] - b[0]), b_im = b[1] + g * (b[5] - b[1]);
        // The local means at the nearer sample (over 2 W + 1 samples, they change little
        // from one to the next).
        const int k = g < 0.5f ? 0 : 4;
        const float pa = a[2 + k], pb = b[2 + k], cross = a[3 + k];
        const float zr = (1.0f - f) * a_re + f * b_re, zi = (1.0f - f) * a_im + f * b_im;
        z_power[c] = zr * zr + zi * zi;
        linear[c] = (1.0f - f) * pa + f * pb;
        coherent[c] = (1.0f - f) * (1.0f - f) * pa + f * f * pb + 2.0f * f * (1.0f - f) * cross;
        const int32_t s = sample[c];
        offset[c] = offsets[s] + g * (offsets[s + 1] - offsets[s]);
    }
    for (int c = 0; c < count; ++c) {
        // Lines with nothing in the window (coherent 0) have linear 0 too: nothing shown.
        const float restored =
            std::min(linear[c] / std::max(coherent[c], 1e-37f), kMostRestoredPower);
        const float power = std::min(z_power[c] * restored, 3.4e38f);
        // Compression of the envelope sqrt(power): scale ln sqrt(P) + offset.
        const float level =
            std::min(std::max(half_scale * base::log_float(power) + offset[c], 0.0f), 1.0f);
        out[c] = power > 0.0f ? level : 0.0f;
    }
}

}  // namespace

ScanConverted scan_convert_display(const BasebandLines& lines, const probe::Transducer& t,
                                   const ImagingSettings& settings) {
    const auto table = scan_table({lines.lines, lines.samples, lines.fs_hz}, t, settings.pixel_mm);
    const int n = lines.samples;
    // Local means along each line (|a|^2) and each pair of neighbours (Re a b*, the pair
    // numbered by its first line and ending at the table's next_line: on a closed array
    // the last line's partner is the first), over +-W samples, fewer at the ends; kept
    // beside the signal, sample by sample.
    const int W = std::max(1, int(std::lround(kCoherenceSigmas * lines.sigma_samples)));
    std::vector<Sample> samples(lines.values.size());
    const bool closed = probe::ScanGeometry(t).closed();
    tbb::parallel_for(0, lines.lines, [&](int l) {
        const int partner = l + 1 < lines.lines ? l + 1 : (closed ? 0 : l);
        const std::complex<float>* a = lines.values.data() + std::size_t(l) * std::size_t(n);
        const std::complex<float>* b = lines.values.data() + std::size_t(partner) * std::size_t(n);
        // Running sums in double (a line's thousands of samples); the products written
        // out (std::complex's checks for infinities at every multiplication).
        thread_local std::vector<std::array<double, 2>> sums;
        sums.resize(std::size_t(n) + 1);
        sums[0] = {0.0, 0.0};
        for (int i = 0; i < n; ++i) {
            const double ar = a[i].real(), ai = a[i].imag(), br = b[i].real(), bi = b[i].imag();
            const auto& before = sums[std::size_t(i)];
            sums[std::size_t(i) + 1] = {before[0] + ar * ar + ai * ai,
                                        before[1] + ar * br + ai * bi};
        }
        Sample* line = samples.data() + std::size_t(l) * std::size_t(n);
        const double whole = 1.0 / double(2 * W + 1);  // but near the ends
        for (int i = 0; i < n; ++i) {
            const int lo = std::max(0, i - W), hi = std::min(n, i + W + 1);
            const double inverse = hi - lo == 2 * W + 1 ? whole : 1.0 / double(hi - lo);
            const auto &from = sums[std::size_t(lo)], &to = sums[std::size_t(hi)];
            line[i] = {a[i].real(), a[i].imag(), float((to[0] - from[0]) * inverse),
                       float((to[1] - from[1]) * inverse)};
        }
    });
    const Compression compression(n, lines.fs_hz, settings);
    ScanConverted out;
    out.pixel_mm = settings.pixel_mm;
    out.origin = table->origin;
    out.image = cv::Mat(table->rows, table->cols, CV_32F, cv::Scalar(0.0f));
    out.inside = cv::Mat(table->rows, table->cols, CV_8U, cv::Scalar(0));
    tbb::parallel_for(0, table->rows, [&](int r) {
        const std::size_t at = std::size_t(r) * std::size_t(table->cols);
        thread_local std::vector<float> scratch;
        scratch.resize(4 * std::size_t(table->cols));
        display_row(table->cols, table->first.data() + at, table->next_line.data() + at,
                    table->line_frac.data() + at, table->sample_frac.data() + at,
                    table->sample.data() + at, reinterpret_cast<const float*>(samples.data()),
                    compression.offsets(), 0.5f * compression.scale(), scratch.data(),
                    out.image.ptr<float>(r));
        uint8_t* inside = out.inside.ptr<uint8_t>(r);
        for (int c = 0; c < table->cols; ++c)
            inside[c] = table->first[at + std::size_t(c)] >= 0 ? 255 : 0;
    });
    return out;
}

}  // namespace sonotrace::imaging
