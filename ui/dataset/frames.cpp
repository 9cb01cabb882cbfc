#include "ui/dataset/frames.h"

#include <algorithm>
#include <cmath>

#include "imaging/picture.h"
#include "phantoms/scene/request.h"
#include "tissue/base/error.h"
#include "tissue/base/number_list.h"

namespace sonotrace::dataset {

namespace {

// The transducer of a frame: the preset with the spec's drawn parameters (the
// frame's, or a corner of their ranges).
probe::Transducer transducer_of(const std::string& preset, const Spec& spec,
                                const std::vector<double>& values) {
    probe::Transducer t = probe::find_transducer(preset, spec.path);
    for (std::size_t n = 0; n < spec.transducer.size(); ++n)
        for (const auto& doc : probe::transducer_parameter_docs())
            if (spec.transducer[n].key == doc.key)
                doc.set(t, base::exact_number_text(values[n]),
                        spec.path + ": transducer." + doc.key);
    return t;
}

}  // namespace

FrameMaker::FrameMaker(const Spec& spec) : spec_(spec) {
    for (std::size_t n = 0; n < spec_.sources.size(); ++n) {
        try {
            scenes_.push_back(scene::load_scene(spec_.sources[n].scene));
        } catch (const base::InputError& e) {
            throw base::InputError(spec_.path, "sources[" + std::to_string(n) + "]", e.what());
        }
    }
    // Every probe of every source at the corners of the transducer's ranges, before any
    // frame: a focus beyond a depth the spec allows is found now, not at frame 90,000.
    const std::size_t ranges = spec_.transducer.size();
    if (ranges > 16)
        throw base::InputError(spec_.path, "transducer",
                               "draws at most 16 parameters (their 2^n corners are checked)");
    for (std::size_t n = 0; n < scenes_.size(); ++n) {
        const std::vector<std::string> presets =
            spec_.probes.empty() ? std::vector<std::string>{scenes_[n]->probe_preset}
                                 : spec_.probes;
        for (const std::string& preset : presets)
            for (uint32_t corner = 0; corner < (1u << ranges); ++corner) {
                std::vector<double> values;
                std::string where = "sources[" + std::to_string(n) + "] with probe " + preset;
                for (std::size_t k = 0; k < ranges; ++k) {
                    const Range& r = spec_.transducer[k].range;
                    values.push_back(corner >> k & 1u ? r.high : r.low);
                    where +=
                        ", " + spec_.transducer[k].key + " " + base::number_text(values.back());
                }
                transducer_of(preset, spec_, values).validate(spec_.path + " (" + where + ")");
            }
    }
}

DatasetFrame FrameMaker::make(uint64_t index) const {
    DatasetFrame out;
    out.draw = draw_frame(spec_, index);
    const FrameDraw& d = out.draw;
    const scene::Scene& scene = *scenes_[std::size_t(d.source)];
    const std::string where = "frame " + std::to_string(index);
    // -- the probe: the drawn preset and parameters, checked as every transducer is
    const probe::Transducer t =
        transducer_of(d.probe.empty() ? scene.probe_preset : d.probe, spec_, d.transducer);
    t.validate(spec_.path + " (" + where + ")");
    out.transducer = t;
    // -- the pose: moved and turned about the source's start, laid back on the surface
    probe::Pose pose = scene.start.pose;
    pose.position += d.lateral_mm * pose.lateral() + d.elevation_mm * pose.elevation();
    pose = scene.settle(pose.rotated(d.rotation_deg).tilted(d.tilt_deg));
    scene.require_inside(pose, spec_.path + " (" + where + ", pose)");
    out.pose = pose;
    imaging::ScenePlacement placement = scene.start;
    placement.pose = pose;
    // -- the frame's request, as `sonotrace simulate` would be asked for it
    scene::FrameRequest request;
    request.probe = t.name;
    for (std::size_t n = 0; n < spec_.transducer.size(); ++n)  // the drawn values, to the bit
        request.transducer[spec_.transducer[n].key] = base::exact_number_text(d.transducer[n]);
    request.quality = imaging::to_string(spec_.quality);
    request.trace = spec_.trace_dimensions == 3 ? "3d" : "2d";
    request.transmit = spec_.transmit;
    request.seed = d.seed;
    request.disable = spec_.disable;
    request.energy = spec_.write_energy;
    const bool truth = spec_.write_labels || spec_.write_echo_labels || spec_.write_depth ||
                       spec_.write_echogenicity;
    request.labels = truth;
    request.gain_db = d.gain_db;
    request.dynamic_range_db = d.dynamic_range_db;
    request.tgc = tgc_curve(d, t);
    request.noise_snr_db = d.noise_snr_db;
    // Pixels that fit the scanned region into W x H.
    const auto [lo, hi] = probe::ScanGeometry(t).bounds();
    request.pixel_mm =
        std::max((hi.x - lo.x) / (spec_.width - 1), (hi.y - lo.y) / (spec_.height - 1)) *
        (1.0 + 1e-9);
    const imaging::SimulationSettings s =
        scene::make_settings(request, scene, spec_.path + " (" + where + ")");
    out.gain_db = s.imaging.gain_db;
    // The drawn tissue properties: every texel of a drawn tissue scaled (its label says
    // which), in the plane and in a 3D trace's slab alike.
    imaging::PlaneMapper mapper = scene.mapper;
    if (!d.tissue_scales.empty())
        mapper = [&scene, &d](const tissue::VolumeGeometry& grid, tissue::Volume* labels) {
            tissue::Volume own;
            tissue::Volume& l = labels ? *labels : own;
            tissue::PropertyMaps maps = scene.mapper(grid, &l);
            tissue::scale_by_label(maps, l, d.tissue_scales);
            return maps;
        };
    imaging::SimulatedFrame simulated = imaging::simulate_plane(mapper, placement, s, truth);
    imaging::Frame& frame = simulated.frame;
    // -- onto the W x H grid
    const imaging::ScanConverted& image = frame.image;
    out.pixel_mm = image.pixel_mm;
    out.origin_mm = image.origin;
    out.valid_width = std::min(image.image.cols, spec_.width);
    out.valid_height = std::min(image.image.rows, spec_.height);
    const cv::Rect valid(0, 0, out.valid_width, out.valid_height);
    out.bmode = cv::Mat(spec_.height, spec_.width, CV_8U, cv::Scalar(0));
    imaging::grey_levels(image.image)(valid).copyTo(out.bmode(valid));
    out.labels = cv::Mat(spec_.height, spec_.width, CV_8U, cv::Scalar(0));
    if (simulated.labels) (*simulated.labels)(valid).copyTo(out.labels(valid));
    auto on_the_grid = [&](const std::optional<cv::Mat>& map, int type) {
        cv::Mat grid(spec_.height, spec_.width, type, cv::Scalar(0));
        if (map) (*map)(valid).copyTo(grid(valid));
        return grid;
    };
    out.echo_labels = on_the_grid(simulated.echo_labels, CV_8U);
    if (spec_.write_depth) out.true_depth = on_the_grid(simulated.true_depth, CV_32F);
    if (spec_.write_echogenicity) out.echogenicity = on_the_grid(simulated.echogenicity, CV_32F);
    if (spec_.write_instances)
        out.instances = on_the_grid(scene::instance_map(scene, simulated), CV_16U);
    out.envelope = std::move(frame.envelope);
    out.rf = std::move(frame.rf);
    if (spec_.write_channels) out.channels = std::move(frame.channels);
    out.energy = std::move(frame.absorbed);
    return out;
}

}  // namespace sonotrace::dataset
