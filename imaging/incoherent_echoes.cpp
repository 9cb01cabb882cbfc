#include "imaging/incoherent_echoes.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>

#include "tissue/base/hash.h"

namespace sonotrace::imaging {

namespace {

// Each echo's kernel sigma: half the distance to its k-th nearest echo, clamped. Echoes
// binned in a grid of `cell` mm; rings of cells are searched outwards until the ring
// cannot hold a nearer echo than the k-th found, or lies beyond the widest kernel.
std::vector<double> kernel_sigmas(const std::vector<glm::dvec2>& points,
                                  const std::vector<uint64_t>& paths,
                                  const IncoherentSpread& spread) {
    const std::size_t n = points.size();
    std::vector<double> sigma(n, spread.max_sigma_mm);
    if (n == 0) return sigma;
    const double cell = std::max(spread.min_sigma_mm, 0.25 * spread.max_sigma_mm);
    glm::dvec2 low(points[0]), high(points[0]);
    for (const glm::dvec2& p : points) low = glm::min(low, p), high = glm::max(high, p);
    const int nx = int((high.x - low.x) / cell) + 1, ny = int((high.y - low.y) / cell) + 1;
    auto cell_of = [&](const glm::dvec2& p) {
        return glm::ivec2(std::min(int((p.x - low.x) / cell), nx - 1),
                          std::min(int((p.y - low.y) / cell), ny - 1));
    };
    // Counting sort of the echoes by cell.
    std::vector<uint32_t> start(std::size_t(nx) * std::size_t(ny) + 1, 0), order(n);
    for (const glm::dvec2& p : points) {
        const glm::ivec2 c = cell_of(p);
        start[std::size_t(c.y) * std::size_t(nx) + std::size_t(c.x) + 1]++;
    }
    for (std::size_t c = 1; c < start.size(); ++c) start[c] += start[c - 1];
    {
        std::vector<uint32_t> next(start.begin(), start.end() - 1);
        for (std::size_t i = 0; i < n; ++i) {
            const glm::ivec2 c = cell_of(points[i]);
            order[next[std::size_t(c.y) * std::size_t(nx) + std::size_t(c.x)]++] = uint32_t(i);
        }
    }
    const std::size_t k = std::size_t(std::max(spread.neighbours, 1));
    const double reach = 2.0 * spread.max_sigma_mm;  // beyond it sigma is the widest
    tbb::parallel_for(std::size_t(0), n, [&](std::size_t i) {
        const glm::ivec2 home = cell_of(points[i]);
        std::vector<double> nearest;  // the k smallest distances so far, a max-heap
        for (int ring = 0;; ++ring) {
            // The nearest a point of this ring can be: (ring - 1) cells away.
            const double ring_distance = double(ring - 1) * cell;
            if (ring_distance > reach) break;
            if (nearest.size() == k && ring_distance > nearest.front()) break;
            for (int y = home.y - ring; y <= home.y + ring; ++y) {
                if (y < 0 || y >= ny) continue;
                const bool edge_row = y == home.y - ring || y == home.y + ring;
                for (int x = home.x - ring; x <= home.x + ring; x += edge_row ? 1 : 2 * ring) {
                    if (x >= 0 && x < nx) {
                        const std::size_t c = std::size_t(y) * std::size_t(nx) + std::size_t(x);
                        for (uint32_t s = start[c]; s < start[c + 1]; ++s) {
                            if (paths[order[s]] == paths[i]) continue;  // itself too
                            const double d = glm::length(points[order[s]] - points[i]);
                            if (nearest.size() < k) {
                                nearest.push_back(d);
                                std::push_heap(nearest.begin(), nearest.end());
                            } else if (d < nearest.front()) {
                                std::pop_heap(nearest.begin(), nearest.end());
                                nearest.back() = d;
                                std::push_heap(nearest.begin(), nearest.end());
                            }
                        }
                    }
                    if (ring == 0) break;
                }
            }
        }
        if (nearest.size() == k)
            sigma[i] = std::clamp(0.5 * nearest.front(), spread.min_sigma_mm, spread.max_sigma_mm);
    });
    return sigma;
}

// The echoes' points in the image plane (mm) and their paths (line, particle).
void echo_points(const std::vector<probe::ScanLine>& lines,
                 const std::vector<IncoherentEcho>& echoes, std::vector<glm::dvec2>* points,
                 std::vector<uint64_t>* paths) {
    for (const IncoherentEcho& e : echoes) {
        const probe::ScanLine& a = lines[std::size_t(e.line)];
        points->push_back(a.origin + a.direction * e.range_mm);
        paths->push_back(uint64_t(uint32_t(e.line)) << 32 | e.particle);
    }
}

std::vector<probe::ScanLine> scan_lines(const probe::ScanGeometry& geometry, int lines) {
    std::vector<probe::ScanLine> out;
    for (int l = 0; l < lines; ++l) out.push_back(geometry.line(l));
    return out;
}

}  // namespace

std::vector<uint8_t> sparse_echoes(const probe::ScanGeometry& geometry,
                                   const std::vector<IncoherentEcho>& echoes,
                                   const IncoherentSpread& spread) {
    int lines = 0;
    for (const IncoherentEcho& e : echoes) lines = std::max(lines, e.line + 1);
    std::vector<glm::dvec2> points;
    std::vector<uint64_t> paths;
    echo_points(scan_lines(geometry, lines), echoes, &points, &paths);
    const std::vector<double> sigma = kernel_sigmas(points, paths, spread);
    std::vector<uint8_t> sparse(echoes.size());
    for (std::size_t e = 0; e < echoes.size(); ++e) sparse[e] = sigma[e] > spread.min_sigma_mm;
    return sparse;
}

std::vector<float> incoherent_intensity(const probe::ScanGeometry& geometry, const LineData& layout,
                                        const std::vector<IncoherentEcho>& echoes,
                                        const IncoherentSpread& spread) {
    const int L = layout.lines, N = layout.samples;
    std::vector<float> mean(std::size_t(L) * std::size_t(N), 0.0f);
    if (echoes.empty() || L == 0 || N == 0) return mean;
    const double bin = spread.bin_mm;
    const double depth = layout.depth_mm(N - 1);
    const int bins = int(depth / bin) + 1;
    const std::vector<probe::ScanLine> lines = scan_lines(geometry, L);
    std::vector<glm::dvec2> points;
    std::vector<uint64_t> paths;
    echo_points(lines, echoes, &points, &paths);
    const std::vector<double> sigma = kernel_sigmas(points, paths, spread);

    // One echo's kernel on line l: calls add(bin, weight) for the bins within 3 sigma.
    auto kernel_on_line = [&](std::size_t e, int l, auto&& add) {
        const probe::ScanLine& a = lines[std::size_t(l)];
        const glm::dvec2 q = points[e] - a.origin;
        const double across = q.x * a.direction.y - q.y * a.direction.x;
        const double along = glm::dot(q, a.direction), s = sigma[e];
        if (std::abs(across) > 3.0 * s) return;
        const double lateral = std::exp(-0.5 * across * across / (s * s));
        const int first = std::max(0, int(std::ceil((along - 3.0 * s) / bin - 0.5)));
        const int last = std::min(bins - 1, int(std::floor((along + 3.0 * s) / bin - 0.5)));
        for (int j = first; j <= last; ++j) {
            const double d = (double(j) + 0.5) * bin - along;
            add(j, lateral * std::exp(-0.5 * d * d / (s * s)));
        }
    };
    // Each kernel's sum over the bins it reaches (in line order: the same sum on any
    // thread count); an echo whose kernel reaches no bin keeps its intensity on its own
    // line's nearest bin.
    std::vector<double> total(echoes.size(), 0.0);
    tbb::parallel_for(std::size_t(0), echoes.size(), [&](std::size_t e) {
        double sum = 0.0;
        for (int l = 0; l < L; ++l) kernel_on_line(e, l, [&](int, double w) { sum += w; });
        total[e] = sum;
    });
    // Per line, the echoes in their order; each bin's intensity shared by its samples.
    std::vector<int> bin_of(static_cast<std::size_t>(N)), samples_in(std::size_t(bins), 0);
    for (int i = 0; i < N; ++i) {
        bin_of[std::size_t(i)] = std::clamp(int(layout.depth_mm(i) / bin), 0, bins - 1);
        samples_in[std::size_t(bin_of[std::size_t(i)])]++;
    }
    tbb::parallel_for(0, L, [&](int l) {
        std::vector<double> gathered(std::size_t(bins), 0.0);
        for (std::size_t e = 0; e < echoes.size(); ++e) {
            const IncoherentEcho& echo = echoes[e];
            if (total[e] > 0.0) {
                const double scale = echo.intensity / total[e];
                kernel_on_line(e, l,
                               [&](int j, double w) { gathered[std::size_t(j)] += scale * w; });
            } else if (echo.line == l) {
                const int j = std::clamp(int(echo.range_mm / bin), 0, bins - 1);
                gathered[std::size_t(j)] += echo.intensity;
            }
        }
        float* row = mean.data() + std::size_t(l) * std::size_t(N);
        for (int i = 0; i < N; ++i) {
            const auto j = std::size_t(bin_of[std::size_t(i)]);
            row[i] = float(gathered[j] / samples_in[j]);
        }
    });
    return mean;
}

void add_incoherent_speckle(const std::vector<float>& mean, const LineData& layout,
                            const probe::Transducer& t, const probe::ScanGeometry& geometry,
                            uint64_t seed, float* in_phase, float* quadrature) {
    const int L = layout.lines, N = layout.samples;
    const uint64_t key = base::mix64(seed ^ 0x696e636f68ull);  // "incoh"
    // White circular Gaussian numbers of unit variance (1/2 per part), a function of
    // (seed, line, sample): Box-Muller from one hash.
    auto white = [key, N](int l, int i) {
        const uint64_t bits = base::mix64(key ^ (uint64_t(l) * uint64_t(N) + uint64_t(i)));
        const float u1 = (float(bits >> 40) + 0.5f) * 0x1.0p-24f;
        const float u2 = float(uint32_t(bits) >> 8) * 0x1.0p-24f;
        return std::polar(std::sqrt(-std::log(u1)), 2.0f * std::numbers::pi_v<float> * u2);
    };
    // Per sample, across lines: a Gaussian of the beam's sigma in lines, its weights scaled
    // so that their squares sum to 1 over the lines that exist (the variance stays 1 at the
    // array's ends too). The white numbers are made only near lines that need them.
    std::vector<uint8_t> row_lit(static_cast<std::size_t>(N), 0);  // read line by line
    for (int l = 0; l < L; ++l)
        for (int i = 0; i < N; ++i)
            row_lit[std::size_t(i)] |=
                mean[std::size_t(l) * std::size_t(N) + std::size_t(i)] > 0.0f;
    tbb::parallel_for(0, N, [&](int i) {
        if (!row_lit[std::size_t(i)]) return;
        auto mean_at = [&](int l) {
            return mean[std::size_t(l) * std::size_t(N) + std::size_t(i)];
        };
        const double sigma = receive_beam_sigma_lines(t, geometry, layout.depth_mm(i));
        const int reach = sigma < 0.3 ? 0 : int(std::ceil(3.0 * sigma));
        std::vector<double> weight(std::size_t(2 * reach + 1), 1.0);
        for (int k = -reach; k <= reach && reach > 0; ++k)
            weight[std::size_t(k + reach)] = std::exp(-0.5 * k * k / (sigma * sigma));
        std::vector<std::complex<float>> numbers(static_cast<std::size_t>(L));
        int made = 0;  // lines below `made` near a line that needs them have their numbers
        for (int l = 0; l < L; ++l) {
            const float m = mean_at(l);
            if (!(m > 0.0f)) continue;
            const int first = std::max(0, l - reach), last = std::min(L - 1, l + reach);
            for (made = std::max(made, first); made <= last; ++made)
                numbers[std::size_t(made)] = white(made, i);
            std::complex<double> sum = 0.0;
            double squares = 0.0;
            for (int k = first; k <= last; ++k) {
                const double w = weight[std::size_t(k - l + reach)];
                sum += w * std::complex<double>(numbers[std::size_t(k)]);
                squares += w * w;
            }
            const std::complex<double> z = sum * std::sqrt(double(m) / squares);
            const std::size_t at = std::size_t(l) * std::size_t(N) + std::size_t(i);
            in_phase[at] += float(z.real());
            quadrature[at] += float(z.imag());
        }
    });
}

}  // namespace sonotrace::imaging
