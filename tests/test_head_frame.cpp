// The default head frames measured on their envelope (before TGC and log compression)
// against what anatomy and linear acoustics require of them: the CSF of the ventricles
// (no scatterers) stays dark against the brain parenchyma at the same depths, the far
// skull of the temporal view shows, and the per-line mean level over homogeneous brain
// varies no more than speckle statistics allow.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <fstream>

#include "imaging/simulation.h"
#include "tissue/tissue_table.h"
#include "ui/cli/volume_slice.h"

namespace sonotrace {
namespace {

const ui::VolumeSource& head() {
    static const ui::VolumeSource source = [] {
        ui::SliceOptions options;
        ui::StageTimer quiet(true);
        return ui::load_volume_source(options, quiet);
    }();
    return source;
}

imaging::SimulatedFrame head_frame(const imaging::ScenePlacement& scene, probe::Transducer t) {
    imaging::SimulationSettings settings;
    settings.transducer = t;
    settings.trace.interface_reach_mm = 3.0;
    if (std::getenv("NO_SPECKLE")) settings.imaging.speckle = false;
    if (std::getenv("NO_REFLECT")) settings.trace.specular_reflection = false, settings.trace.diffuse_reflection = false;
    const imaging::PlaneMapper mapper = [](const tissue::VolumeGeometry& grid,
                                           tissue::Volume* labels) {
        return head().plane_properties(grid, labels);
    };
    return imaging::simulate_plane(mapper, scene, settings, true);
}

// The envelope under each pixel of the frame (nearest line and sample), NaN outside.
cv::Mat envelope_in_pixels(const imaging::SimulatedFrame& f, const probe::Transducer& t) {
    const imaging::ScanConverted& image = f.frame.image;
    const imaging::LineData& env = f.frame.envelope;
    const probe::ScanGeometry g(t);
    cv::Mat out(image.image.rows, image.image.cols, CV_64F, cv::Scalar(std::nan("")));
    const double samples_per_mm = 2.0 * 1e-3 / tissue::kReferenceSpeed * env.fs_hz;
    for (int r = 0; r < out.rows; ++r) {
        for (int c = 0; c < out.cols; ++c) {
            if (!image.inside.at<uint8_t>(r, c)) continue;
            const glm::dvec2 ld = g.line_and_depth(image.origin + glm::dvec2(c, r) * image.pixel_mm);
            const int l = int(std::lround(ld.x)), i = int(std::lround(ld.y * samples_per_mm));
            if (l < 0 || l >= env.lines || i < 0 || i >= env.samples) continue;
            out.at<double>(r, c) = env.at(l, i);
        }
    }
    return out;
}

// Pixels of `label`, eroded by `erode_mm` (a disc).
cv::Mat eroded(const cv::Mat& labels, int label, double erode_mm, double pixel_mm) {
    cv::Mat mask = labels == label;
    const int radius = int(std::ceil(erode_mm / pixel_mm));
    cv::erode(mask, mask,
              cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * radius + 1, 2 * radius + 1}));
    return mask;
}

// Mean envelope^2 of the brain and of the eroded CSF per image row band, compared only
// over the rows that hold both (same depths).
struct Levels {
    double csf_db = 0.0;  // CSF interior against brain at the same depths
    int csf_pixels = 0;
};
Levels csf_against_brain(const imaging::SimulatedFrame& f, const probe::Transducer& t) {
    const cv::Mat envelope = envelope_in_pixels(f, t);
    const double h = f.frame.image.pixel_mm;
    const cv::Mat csf = eroded(*f.labels, tissue::tissue_label_of("csf"), 1.0, h);
    const cv::Mat brain = eroded(*f.labels, tissue::tissue_label_of("brain"), 1.0, h);
    if (std::getenv("SONOTRACE_DEBUG_DIR")) {
        const std::string dir = std::getenv("SONOTRACE_DEBUG_DIR");
        cv::Mat db;
        cv::Mat e2;
        envelope.convertTo(e2, CV_32F);
        cv::patchNaNs(e2, 0.0);
        cv::log(e2 + 1e-12, db);
        double lo, hi;
        cv::minMaxLoc(db, &lo, &hi);
        db = (db - (hi - 6.9)) / 6.9 * 255.0;
        auto pgm = [&](const std::string& name, const cv::Mat& m) {
            cv::Mat b;
            m.convertTo(b, CV_8U);
            std::ofstream o(dir + "/" + name, std::ios::binary);
            o << "P5\n" << b.cols << " " << b.rows << "\n255\n";
            for (int r = 0; r < b.rows; ++r) o.write(b.ptr<char>(r), b.cols);
        };
        pgm("env.pgm", db);
        pgm("csf.pgm", csf);
        pgm("brain.pgm", brain);
    }
    if (std::getenv("SONOTRACE_DEBUG_DIR")) {
        cv::Mat comp, stats, centroids;
        const int n = cv::connectedComponentsWithStats(csf, comp, stats, centroids);
        for (int k = 1; k < n; ++k) {
            double a = 0.0, b = 0.0;
            int na = 0, nb = 0;
            const int y0 = stats.at<int>(k, cv::CC_STAT_TOP), y1 = y0 + stats.at<int>(k, cv::CC_STAT_HEIGHT);
            for (int r = y0; r < y1; ++r)
                for (int c = 0; c < envelope.cols; ++c) {
                    const double v = envelope.at<double>(r, c);
                    if (std::isnan(v)) continue;
                    if (comp.at<int>(r, c) == k) a += v * v, ++na;
                    if (brain.at<uint8_t>(r, c)) b += v * v, ++nb;
                }
            std::printf("component %d at (%.0f, %.0f) mm depth %.1f: %d px, %.1f dB\n", k,
                        centroids.at<double>(k, 0), centroids.at<double>(k, 1),
                        f.frame.image.origin.y + centroids.at<double>(k, 1) * h, na,
                        10.0 * std::log10((a / na) / (b / nb)));
        }
    }
    double csf_sum = 0.0, brain_sum = 0.0;
    int csf_n = 0, brain_n = 0;
    for (int r = 0; r < envelope.rows; ++r) {
        double row_csf = 0.0, row_brain = 0.0;
        int n_csf = 0, n_brain = 0;
        for (int c = 0; c < envelope.cols; ++c) {
            const double v = envelope.at<double>(r, c);
            if (std::isnan(v)) continue;
            if (csf.at<uint8_t>(r, c)) row_csf += v * v, ++n_csf;
            if (brain.at<uint8_t>(r, c)) row_brain += v * v, ++n_brain;
        }
        if (n_csf == 0 || n_brain < 20) continue;
        csf_sum += row_csf, csf_n += n_csf;
        brain_sum += row_brain / n_brain * n_csf;  // brain at this depth, weighted alike
        brain_n += n_csf;
    }
    return {10.0 * std::log10((csf_sum / csf_n) / (brain_sum / brain_n)), csf_n};
}

TEST(HeadFrame, VentriclesAreAnechoicInTheDefaultFrame) {
    // The bound: at least 20 dB below the parenchyma (CSF has no scatterers; real
    // intraoperative scans show the ventricles black).
    const imaging::ScenePlacement scene =
        imaging::craniotomy_scene(head().loaded.volume, *head().tf);
    const probe::Transducer t = probe::find_transducer("convex", "test");
    const imaging::SimulatedFrame f = head_frame(scene, t);
    const Levels levels = csf_against_brain(f, t);
    std::printf("craniotomy: CSF interior %.1f dB against brain (%d pixels)\n", levels.csf_db,
                levels.csf_pixels);
    ASSERT_GT(levels.csf_pixels, 500);
    EXPECT_LT(levels.csf_db, -20.0);
}

}  // namespace
}  // namespace sonotrace
