// Cases measured on frames of the embedded head (Colin27) through the skull: the
// transtemporal view's ventricles against the parenchyma, and the far side of the skull
// behind the acoustic window. Expectations come from the anatomy (the tissue labels of
// the frame's plane) and Snell's law on its acoustic map, never from the image.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "phantoms/validation/head_frames.h"
#include "phantoms/validation/validation.h"
#include "probe/aperture.h"
#include "tissue/tissue_table.h"

namespace sonotrace::validation {
namespace {

// The display of a frame for the report.
Figure frame_figure(const imaging::Frame& frame, const std::string& caption) {
    cv::Mat grey;
    frame.image.image.convertTo(grey, CV_8U, 255.0);
    return {caption, grey};
}

// Interior and parenchyma samples of several frames, their intensities and display
// levels in lists (a sample's `sample` indexes them), and their contrasts.
struct PooledSamples {
    imaging::ClearSamples all;
    std::vector<double> intensities, levels_db;
    void add(const TruthFrame& truth, const imaging::ClearSamples& samples,
             const imaging::ImagingSettings& display) {
        const imaging::LineData& envelope = truth.frame.envelope;
        const imaging::Compression compression(envelope.samples, envelope.fs_hz, display);
        for (const auto* list : {&samples.inside, &samples.outside})
            for (imaging::TruthSample t : *list) {
                const float e = envelope.at(t.line, t.sample);
                levels_db.push_back(compression(e, compression.offset(t.sample)) *
                                    display.dynamic_range_db);
                t.sample = int(intensities.size());
                intensities.push_back(double(e) * double(e));
                (list == &samples.inside ? all.inside : all.outside).push_back(t);
            }
    }
    // NaN (a failed check) with fewer than 500 interior samples.
    double contrast_db() const {  // imaging::band_contrast_db
        if (all.inside.size() < 500) return std::nan("");
        return imaging::band_contrast_db(
            all, [&](const imaging::TruthSample& t) { return intensities[std::size_t(t.sample)]; });
    }
    double level_difference_db() const {  // imaging::band_level_difference_db
        if (all.inside.size() < 500) return std::nan("");
        return imaging::band_level_difference_db(
            all, [&](const imaging::TruthSample& t) { return levels_db[std::size_t(t.sample)]; });
    }
};

// The temporal view's lateral ventricles against the parenchyma at the same depths, as
// the eye compares them: the mean grey level of the display (TGC, log compression) inside
// against outside (imaging::band_level_difference_db). CSF holds no scatterers
// (backscatter 0 in the tissue table), so linear acoustics images its interior only
// through the PSF's reach from the walls and what multiple reflections lay over it. Frames
// of four seeds pooled; the interior is the CSF 1 mm clear of other labels, 40 to 100 mm
// deep (the ventricles, not the sulci under the temple), each sample placed by walking its
// line through the map's speed of sound. Grey levels rather than mean intensities: beside
// the window the parenchyma's mean intensity is mostly a handful of echoes that bounced in
// the skull and scalp (80-87 % of it at 32 particles a line), so a mean of intensity
// measured which of those few a seed drew.
CaseResult temporal_ventricles(const CaseContext& ctx) {
    CaseResult r;
    imaging::SimulationSettings s;
    const auto head = head_view("temporal", &s);
    const int csf = tissue::tissue_label_of("csf"), brain = tissue::tissue_label_of("brain");
    PooledSamples pooled;
    for (uint64_t seed = ctx.seed; seed < ctx.seed + 4; ++seed) {
        const TruthFrame truth = truth_frame(*head, s, seed);
        pooled.add(truth, truth.samples(csf, brain, 1.0, 40.0, 100.0), s.imaging);
        if (ctx.pictures && seed == ctx.seed)
            r.figures.push_back(frame_figure(truth.frame, "the temporal view (first seed)"));
    }
    r.measurements.push_back(
        {"ventricles (CSF 1 mm clear, 40-100 mm) against parenchyma, mean grey levels, " +
             std::to_string(pooled.all.inside.size()) + " interior samples",
         pooled.level_difference_db(), -12.0, 0.0, "dB", Check::at_most});
    return r;
}

// The default frame's lateral ventricles, the interior taken as the samples the image can
// resolve from the walls. The 1 mm clearance lies inside the main lobe of the
// convex probe's two-way lateral response at the ventricles' depths (|H|^2 -13.4 dB at
// 1 mm, 63 mm deep): a plexus face 1 mm from a sample images on the sample's line in any
// linear-acoustics image at 3.5 MHz (-13 to -16 dB measured). By Rayleigh's criterion a
// point is resolved from a wall beyond the first minimum of the wall's response; from
// there the walls reach in only through side lobes (-37 dB and below), so whatever else
// lights the interior (the haze of multiply scattered energy, stray bounces, wrong
// receive weights) shows. The clearance at each depth is that first minimum for the
// central line (probe::LineFields, from the element positions, not the image pipeline),
// at least 1 mm; lines whose apertures the array's ends clip have wider lobes, so there
// the measure is stricter than the physics. Every physics on: the brain's refraction
// moves single rays 1-2 mm beyond the focus and the plexus's image with them, which
// spreads the result between seeds (-22 to -54 dB over seeds 1-32 in groups of four).
// The interior lies within 22 mm of the midline (the lateral ventricles' bodies, not the
// insular cisterns, whose fissure is echogenic on real scans).
CaseResult craniotomy_ventricles(const CaseContext& ctx) {
    CaseResult r;
    imaging::SimulationSettings s;
    const auto head = head_view("craniotomy", &s);
    const probe::Transducer& t = s.transducer;
    // The main lobe's half-width by whole millimetres of depth.
    const probe::LineFields fields(t, probe::line_array(t, t.lines / 2));
    std::vector<double> half_width(std::size_t(t.depth_mm) + 2, 1.0);
    for (std::size_t z = 1; z < half_width.size(); ++z) {
        const auto receive = fields.receive_aperture(double(z));  // focused at z, as two_way
        auto power_at = [&](double x) {
            const glm::dvec2 q(x, double(z));
            return std::norm(fields.transmit(q) * fields.receive(q, receive));
        };
        double previous = power_at(0.0);
        for (double x = 0.01; x <= 5.0; x += 0.01) {
            const double power = power_at(x);
            if (power > previous) {
                half_width[z] = std::max(1.0, x - 0.01);
                break;
            }
            previous = power;
        }
    }
    const imaging::Clearance beyond_main_lobe([&](double depth_mm) {
        const auto z =
            std::size_t(std::clamp(std::lround(depth_mm), 0L, long(half_width.size()) - 1));
        return half_width[z];
    });
    const int csf = tissue::tissue_label_of("csf"), brain = tissue::tissue_label_of("brain");
    PooledSamples pooled;
    for (uint64_t seed = ctx.seed; seed < ctx.seed + 4; ++seed) {
        const TruthFrame truth = truth_frame(*head, s, seed);
        imaging::ClearSamples samples = truth.samples(csf, brain, beyond_main_lobe, 40.0, 1e9);
        const imaging::MapToWorld to_world = imaging::map_to_world(head->start.pose, truth.grid);
        std::erase_if(samples.inside, [&](const imaging::TruthSample& sample) {
            return std::abs(to_world(sample.map).x) > 22.0;
        });
        pooled.add(truth, samples, s.imaging);
        if (ctx.pictures && seed == ctx.seed)
            r.figures.push_back(frame_figure(truth.frame, "the default frame (first seed)"));
    }
    char lobe[64];
    std::snprintf(lobe, sizeof lobe, " (main lobe %.2f mm at 63 mm), ", half_width[63]);
    r.measurements.push_back({"lateral ventricles beyond the main lobe against parenchyma" +
                                  std::string(lobe) + std::to_string(pooled.all.inside.size()) +
                                  " interior samples",
                              pooled.contrast_db(), -20.0, 0.0, "dB", Check::at_most});
    return r;
}

// The far side of the skull is a bright curve where the anatomy puts it, behind the
// acoustic window. Colin27 is 174 mm from temple to temple at this level, so the far
// skull's inner table lies 146-167 mm deep: the frame goes to 175 mm. Expected from the
// labels: on each line, the first cortical bone beyond 110 mm (true depth). Expected from
// Snell's law (near_skull): the window is the lines that meet the near skull 5 degrees or
// more inside its longitudinal critical angle (beyond it the wave turns to shear, which
// the bone absorbs, or reflects). Two seeds.
CaseResult far_skull(const CaseContext& ctx) {
    CaseResult r;
    imaging::SimulationSettings s;
    const auto head = head_view("temporal", &s, 175.0);
    const int bone = tissue::tissue_label_of("cortical_bone"),
              brain = tissue::tissue_label_of("brain");
    int window_lines = 0, shadow_lines = 0, hits = 0;  // over both seeds
    double curve = 0.0, front = 0.0, shadow = 0.0;
    int n_curve = 0, n_front = 0, n_shadow = 0;
    for (uint64_t seed = ctx.seed; seed < ctx.seed + 2; ++seed) {
        const TruthFrame truth = truth_frame(*head, s, seed);
        const imaging::Frame& frame = truth.frame;
        const imaging::ClearSamples samples = truth.samples(bone, brain, 0.0, 110.0, 175.0);
        const auto L = std::size_t(frame.envelope.lines);
        std::vector<double> skull(L, 1e9);
        for (const imaging::TruthSample& t : samples.inside)
            skull[std::size_t(t.line)] = std::min(skull[std::size_t(t.line)], t.depth_mm);
        std::vector<int> side(L, 0);  // 1 window, -1 shadow, 0 neither
        for (std::size_t l = 0; l < L; ++l) {
            const NearSkull n = near_skull(truth, int(l));
            if (!n.found || skull[l] > 170.0) continue;  // no far skull in the frame
            side[l] = n.incidence_deg < n.critical_deg - 5.0   ? 1
                      : n.incidence_deg > n.critical_deg + 5.0 ? -1
                                                               : 0;
        }
        // A line the trace leaves dark has no brightest sample.
        std::vector<double> brightest(L, 0.0), at_depth(L, -1.0);
        for (const auto* list : {&samples.inside, &samples.outside})
            for (const imaging::TruthSample& t : *list) {
                const auto l = std::size_t(t.line);
                const double e = frame.envelope.at(t.line, t.sample);
                if (e > brightest[l]) brightest[l] = e, at_depth[l] = t.depth_mm;
                const double to_skull = skull[l] - t.depth_mm;
                if (side[l] < 0) shadow += e * e, ++n_shadow;
                if (side[l] <= 0) continue;
                if (std::abs(to_skull) <= 1.5) curve += e * e, ++n_curve;
                if (list == &samples.outside && to_skull >= 10.0 && to_skull <= 20.0)
                    front += e * e, ++n_front;
            }
        for (std::size_t l = 0; l < L; ++l) {
            window_lines += side[l] > 0;
            shadow_lines += side[l] < 0;
            if (side[l] > 0 && at_depth[l] >= 0.0) hits += std::abs(at_depth[l] - skull[l]) <= 3.0;
        }
        if (ctx.pictures && seed == ctx.seed)
            r.figures.push_back(frame_figure(frame, "the temporal view to 175 mm (first seed)"));
    }
    const double curve_level = n_curve > 0 ? curve / n_curve : std::nan("");
    r.measurements.push_back({"window lines (both seeds; a third of the lines at least)",
                              double(window_lines), 60.0, 0.0, "", Check::at_least});
    r.measurements.push_back(
        {"window lines whose brightest deep sample lies within 3 mm of the far skull",
         window_lines > 0 ? double(hits) / window_lines : std::nan(""), 2.0 / 3.0, 0.0, "",
         Check::at_least});
    r.measurements.push_back({"the curve over the parenchyma 10-20 mm in front of it",
                              10.0 * std::log10(curve_level / (front / n_front)), 10.0, 0.0, "dB",
                              Check::at_least});
    r.measurements.push_back({"the shadow's deep region (" + std::to_string(shadow_lines) +
                                  " lines beyond the critical angle) against the curve",
                              10.0 * std::log10(shadow / n_shadow / curve_level), 0.0, 0.0, "dB",
                              Check::at_most});
    return r;
}

}  // namespace

void add_head_cases(std::vector<Case>& out) {
    out.push_back({"temporal_ventricles", "the temporal view's ventricles are dark",
                   "Colin27 through the right temple (phased 2.7 MHz): the lateral ventricles' "
                   "interior (CSF 1 mm clear of other labels, 40-100 mm) at least 12 dB below "
                   "the parenchyma at the same depths, on the envelope of four frames. CSF has "
                   "no scatterers: only the PSF's reach from the walls lights it.",
                   temporal_ventricles});
    out.push_back({"craniotomy_ventricles", "the default frame's ventricles are dark",
                   "The default frame (convex 3.5 MHz through the craniotomy): the lateral "
                   "ventricles' interior, farther from other labels than the main "
                   "lobe of the two-way lateral response at its depth (its first minimum, from "
                   "the aperture; at least 1 mm: Rayleigh's criterion), at least 20 dB below the "
                   "parenchyma at the "
                   "same depths, on the envelope of four frames.",
                   craniotomy_ventricles});
    out.push_back({"far_skull", "the far skull behind the acoustic window",
                   "The temporal view to 175 mm: on the lines that meet the near skull 5 degrees "
                   "or more inside its critical angle (Snell, from the map), the brightest deep "
                   "sample lies within 3 mm of the far skull's labels on two lines in three, "
                   "and the curve stands 10 dB above the parenchyma 10-20 mm in front; the "
                   "lines beyond the critical angle (the skull's shadow) are darker than it.",
                   far_skull});
}

}  // namespace sonotrace::validation
