#pragma once
// Frames of a dataset: frame i of a spec made from its draw (spec.h), every frame on the
// same W x H pixel grid so that a shard stacks them.
#include <memory>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "ui/dataset/spec.h"

namespace sonotrace::dataset {

struct DatasetFrame {
    FrameDraw draw;
    probe::Transducer transducer;  // as simulated
    probe::Pose pose;
    double gain_db = 0.0;  // as simulated (the draw's, or the scene's)
    // The scan-converted frame fills the top-left valid_width x valid_height pixels of the
    // W x H grid (the rest is 0, label 0); pixel (0, 0)'s centre lies at origin_mm in the
    // probe plane (x lateral, y depth), pixels are pixel_mm square.
    double pixel_mm = 0.0;
    glm::dvec2 origin_mm{0.0};
    int valid_width = 0, valid_height = 0;
    cv::Mat bmode;        // CV_8U, H x W (display grey levels, as simulate's png8)
    cv::Mat labels;       // CV_8U, H x W: tissue index (1-based, the tissue table), 0 outside
    cv::Mat echo_labels;  // the same where the echoes show them (imaging::truth_at_echo)
    // Written on request only (empty otherwise):
    cv::Mat true_depth, echogenicity;  // CV_32F, H x W: of what each pixel shows (the same)
    cv::Mat instances;                 // CV_16U, H x W: a phantom's shape index, 0 background
    imaging::LineData envelope, rf;
    std::optional<imaging::ChannelData> channels;  // spec "transmit" and write "channels"
    tissue::Volume energy;                         // absorbed energy on the map grid
};

// Loads every source of a spec once, then makes frames from their draws, one at a time,
// each on every core (as `sonotrace simulate`).
class FrameMaker {
  public:
    explicit FrameMaker(const Spec& spec);
    DatasetFrame make(uint64_t index) const;
    const Spec& spec() const { return spec_; }

  private:
    Spec spec_;
    std::vector<std::shared_ptr<const scene::Scene>> scenes_;
};

}  // namespace sonotrace::dataset
