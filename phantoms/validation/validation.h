#pragma once
// The validation suite of `sonotrace validate`: cases that simulate a phantom, measure a
// quantity from the images, echo events or energy maps, and compare it with the value
// physics or geometry predicts from the phantom's own parameters. Expected values never
// come from earlier simulator output; each case states and justifies its tolerance.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "tissue/acoustic_map.h"

namespace sonotrace::validation {

// m/s: the speed the scanner assumes when it turns echo times into depths.
inline constexpr double kC0 = tissue::kReferenceSpeed;

// How a measurement is judged against its expectation.
enum class Check {
    within,    // |measured - expected| <= tolerance
    at_most,   // measured <= expected (an upper bound; tolerance unused)
    at_least,  // measured >= expected
};

struct Measurement {
    std::string quantity;  // "transmitted angle at 30 deg incidence"
    double measured = 0.0, expected = 0.0, tolerance = 0.0;
    std::string unit;  // "deg", "mm", "dB", "" for ratios
    Check check = Check::within;
    bool pass() const;  // false for NaN
};

// A line plot for the report: measured points against the predicted curve.
struct Plot {
    struct Series {
        std::string name;
        std::vector<double> x, y;
        bool points = false;  // markers instead of a line
    };
    std::string title, x_label, y_label;
    std::vector<Series> series;
    std::vector<double> marker_x;  // dashed vertical lines (e.g. expected positions)
};

struct Figure {
    std::string caption;
    cv::Mat picture;  // 8-bit grey or BGR
};

struct CaseResult {
    std::vector<Measurement> measurements;
    std::vector<Figure> figures;
    std::vector<Plot> plots;
    double seconds = 0.0;
    bool pass() const;
};

// Where a case finds the catalogue (phantoms/*.json).
struct CaseContext {
    std::string phantom_dir;
    bool pictures = true;  // figures and plots for a report (skipped otherwise)
    uint64_t seed = 1;     // of the simulated frames (tracer and speckle)
};

struct Case {
    std::string name;     // "refraction_angle"
    std::string title;    // one line for people
    std::string physics;  // what is predicted and why the tolerance (the report's text)
    std::function<CaseResult(const CaseContext&)> run;
};

// All cases, in report order.
const std::vector<Case>& cases();

// Machine-readable records {case, quantity, measured, expected, tolerance, unit, check, pass}.
nlohmann::json to_json(const std::vector<const Case*>& run, const std::vector<CaseResult>& results);

// Writes `dir`/index.html with the figures as PNG and the plots as inline SVG (through
// the caller's transaction: `stage` maps a final path to the path to write).
void write_report(const std::string& dir, const std::vector<const Case*>& run,
                  const std::vector<CaseResult>& results,
                  const std::function<std::string(const std::string&)>& stage,
                  const std::string& header_note);

// Registration of the case groups (one per source file).
void add_tracer_cases(std::vector<Case>& out);
void add_imaging_cases(std::vector<Case>& out);
void add_head_cases(std::vector<Case>& out);

}  // namespace sonotrace::validation
