#include "imaging/coherent_surfaces.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <opencv2/core.hpp>

namespace sonotrace::imaging {
namespace {

// Chains of neighbouring echoes on one surface (header), as indices into `echoes`.
std::vector<std::vector<std::size_t>> surface_chains(const std::vector<SurfaceEcho>& echoes,
                                                     const SurfaceSmoothing& settings) {
    std::vector<std::vector<std::size_t>> chains;
    std::vector<std::size_t> open;  // chains that may still grow
    for (std::size_t i = 0; i < echoes.size(); ++i) {
        const SurfaceEcho& e = echoes[i];
        std::erase_if(open, [&](std::size_t c) {
            return echoes[chains[c].back()].particle + settings.max_gap < e.particle;
        });
        std::size_t best = chains.size();
        double nearest = settings.link_mm;
        for (std::size_t c : open) {
            const SurfaceEcho& last = echoes[chains[c].back()];
            if (last.particle == e.particle || last.bounces != e.bounces) continue;
            const double d = glm::length(e.position - last.position);
            if (d < nearest) nearest = d, best = c;
        }
        if (best == chains.size()) {
            chains.push_back({});
            open.push_back(best);
        }
        chains[best].push_back(i);
    }
    return chains;
}

// v = c0 + c1 u + c2 u^2 through points (u, v) by least squares (OpenCV's QR); false
// when they do not determine it.
bool fit_quadratic(const std::vector<glm::dvec2>& points, std::array<double, 3>& coef) {
    cv::Mat a(int(points.size()), 3, CV_64F), b(int(points.size()), 1, CV_64F), x;
    for (int i = 0; i < a.rows; ++i) {
        const glm::dvec2& q = points[std::size_t(i)];
        a.at<double>(i, 0) = 1.0, a.at<double>(i, 1) = q.x, a.at<double>(i, 2) = q.x * q.x;
        b.at<double>(i, 0) = q.y;
    }
    if (!cv::solve(a, b, x, cv::DECOMP_QR) || !cv::checkRange(x)) return false;
    for (int k = 0; k < 3; ++k) coef[std::size_t(k)] = x.at<double>(k, 0);
    return true;
}

constexpr std::size_t kFewest = 5;

// One pass of surface_patches: each echo's move onto its fit and the fit's tangent there
// (width 1 where fitted, else 0).
std::vector<SurfacePatch> moves_onto_fits(const std::vector<SurfaceEcho>& echoes,
                                          const SurfaceSmoothing& settings) {
    std::vector<SurfacePatch> moves(echoes.size());
    for (const std::vector<std::size_t>& chain : surface_chains(echoes, settings)) {
        if (chain.size() < kFewest) continue;
        std::vector<double> arc(chain.size(), 0.0);
        for (std::size_t k = 1; k < chain.size(); ++k)
            arc[k] =
                arc[k - 1] + glm::length(echoes[chain[k]].position - echoes[chain[k - 1]].position);
        std::size_t first = 0, last = 0;  // the window [first, last)
        for (std::size_t k = 0; k < chain.size(); ++k) {
            while (arc[k] - arc[first] > 0.5 * settings.window_mm) ++first;
            while (last < chain.size() && arc[last] - arc[k] <= 0.5 * settings.window_mm) ++last;
            if (last - first < kFewest) continue;
            // Principal axes of the window's echoes.
            glm::dvec2 centre(0.0);
            for (std::size_t j = first; j < last; ++j) centre += echoes[chain[j]].position;
            centre /= double(last - first);
            double sxx = 0.0, sxy = 0.0, syy = 0.0;
            for (std::size_t j = first; j < last; ++j) {
                const glm::dvec2 r = echoes[chain[j]].position - centre;
                sxx += r.x * r.x, sxy += r.x * r.y, syy += r.y * r.y;
            }
            const double angle = 0.5 * std::atan2(2.0 * sxy, sxx - syy);
            const glm::dvec2 along(std::cos(angle), std::sin(angle)), across(-along.y, along.x);
            // v = a + b u + c u^2 by least squares, then again without the echoes more than
            // three median deviations off it (a staircase's corners).
            std::vector<glm::dvec2> local;
            for (std::size_t j = first; j < last; ++j) {
                const glm::dvec2 p = echoes[chain[j]].position - centre;
                local.push_back({glm::dot(p, along), glm::dot(p, across)});
            }
            std::array<double, 3> coef{};
            if (!fit_quadratic(local, coef)) continue;
            std::vector<double> off;
            for (const glm::dvec2& q : local)
                off.push_back(std::abs(q.y - (coef[0] + coef[1] * q.x + coef[2] * q.x * q.x)));
            std::vector<double> sorted = off;
            std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(sorted.size() / 2),
                             sorted.end());
            const double limit = 3.0 * sorted[sorted.size() / 2];
            std::vector<glm::dvec2> kept;
            for (std::size_t j = 0; j < local.size(); ++j)
                if (off[j] <= limit) kept.push_back(local[j]);
            if (kept.size() < local.size() && kept.size() >= kFewest && !fit_quadratic(kept, coef))
                continue;
            // Along the ray onto the fit (Newton from s = 0).
            const SurfaceEcho& e = echoes[chain[k]];
            const glm::dvec2 p = e.position - centre;
            const double u0 = glm::dot(p, along), v0 = glm::dot(p, across);
            const double du = glm::dot(e.direction, along), dv = glm::dot(e.direction, across);
            double s = 0.0;
            bool meets = true;
            for (int iteration = 0; iteration < 3 && meets; ++iteration) {
                const double u = u0 + s * du;
                const double slope = coef[1] + 2.0 * coef[2] * u;
                const double f = v0 + s * dv - (coef[0] + slope * u - coef[2] * u * u);
                const double df = dv - slope * du;
                meets = std::abs(df) > 0.2 * std::sqrt(1.0 + slope * slope);
                if (meets) s -= f / df;
            }
            if (meets && std::abs(s) < settings.link_mm) {
                const double u = u0 + s * du;
                SurfacePatch& patch = moves[chain[k]];
                patch.move_mm = s;
                patch.width_mm = 1.0;
                patch.tangent = glm::normalize(along + (coef[1] + 2.0 * coef[2] * u) * across);
            }
        }
    }
    return moves;
}

}  // namespace

std::vector<SurfacePatch> surface_patches(std::vector<SurfaceEcho> echoes,
                                          const SurfaceSmoothing& settings) {
    std::vector<SurfacePatch> patches(echoes.size());
    for (int pass = 0; pass < settings.passes; ++pass) {
        const std::vector<SurfacePatch> fits = moves_onto_fits(echoes, settings);
        for (std::size_t k = 0; k < echoes.size(); ++k) {
            patches[k].move_mm += fits[k].move_mm;
            patches[k].width_mm = fits[k].width_mm;
            patches[k].tangent = fits[k].tangent;
            echoes[k].position += fits[k].move_mm * echoes[k].direction;
        }
    }
    // Each fitted echo stands for the surface halfway to its chain's neighbours.
    for (const std::vector<std::size_t>& chain : surface_chains(echoes, settings)) {
        for (std::size_t k = 0; k < chain.size(); ++k) {
            SurfacePatch& patch = patches[chain[k]];
            if (chain.size() < kFewest || !(patch.width_mm > 0.0)) {
                patch.width_mm = 0.0;
                continue;
            }
            // Per launched particle: a gap's particles are filled in (SurfacePatch::next).
            const SurfaceEcho& e = echoes[chain[k]];
            auto spacing = [&](const SurfaceEcho& other) {
                return glm::length(other.position - e.position) /
                       std::max(1.0, std::abs(double(other.particle) - double(e.particle)));
            };
            const double before = k > 0 ? spacing(echoes[chain[k - 1]]) : 0.0;
            const double after = k + 1 < chain.size() ? spacing(echoes[chain[k + 1]]) : 0.0;
            patch.width_mm = k == 0                  ? after
                             : k + 1 == chain.size() ? before
                                                     : 0.5 * (before + after);
            if (k + 1 < chain.size()) patch.next = int(chain[k + 1]);
        }
    }
    return patches;
}

}  // namespace sonotrace::imaging
