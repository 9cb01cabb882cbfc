// The suite's registry, its JSON records and the HTML report (figures as PNG, plots as
// inline SVG so that the report is one directory with no scripts or downloads).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "imaging/picture.h"
#include "phantoms/validation/validation.h"
#include "sonotrace_version.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"

namespace sonotrace::validation {

bool Measurement::pass() const {
    if (!std::isfinite(measured)) return false;
    switch (check) {
        case Check::within:
            return std::abs(measured - expected) <= tolerance;
        case Check::at_most:
            return measured <= expected;
        case Check::at_least:
            return measured >= expected;
    }
    return false;
}

bool CaseResult::pass() const {
    return !measurements.empty() && std::all_of(measurements.begin(), measurements.end(),
                                                [](const Measurement& m) { return m.pass(); });
}

const std::vector<Case>& cases() {
    static const std::vector<Case> all = [] {
        std::vector<Case> out;
        add_tracer_cases(out);
        add_imaging_cases(out);
        add_head_cases(out);
        return out;
    }();
    return all;
}

namespace {

const char* check_name(Check c) {
    switch (c) {
        case Check::within:
            return "within";
        case Check::at_most:
            return "at_most";
        case Check::at_least:
            return "at_least";
    }
    return "?";
}

std::string html_escape(const std::string& s) {
    std::string out;
    for (char c : s) {
        if (c == '<')
            out += "&lt;";
        else if (c == '>')
            out += "&gt;";
        else if (c == '&')
            out += "&amp;";
        else
            out += c;
    }
    return out;
}

std::string number(double v, int digits = 4) {
    if (!std::isfinite(v)) return "nan";
    char buffer[64];
    std::snprintf(buffer, sizeof buffer, "%.*g", digits, v);
    return buffer;
}

std::string expectation(const Measurement& m) {
    switch (m.check) {
        case Check::within:
            return number(m.expected) + " &plusmn; " + number(m.tolerance, 3);
        case Check::at_most:
            return "&le; " + number(m.expected);
        case Check::at_least:
            return "&ge; " + number(m.expected);
    }
    return "";
}

// "Nice" tick step for a range: 1, 2 or 5 times a power of ten, about 5 ticks.
double tick_step(double span) {
    const double raw = span / 5.0;
    const double p = std::pow(10.0, std::floor(std::log10(raw)));
    for (double m : {1.0, 2.0, 5.0})
        if (raw <= m * p) return m * p;
    return 10.0 * p;
}

std::string svg_plot(const Plot& plot) {
    constexpr double W = 520, H = 320, left = 62, right = 16, top = 28, bottom = 46;
    double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
    for (const auto& s : plot.series) {
        for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
            if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
            x0 = std::min(x0, s.x[i]), x1 = std::max(x1, s.x[i]);
            y0 = std::min(y0, s.y[i]), y1 = std::max(y1, s.y[i]);
        }
    }
    for (double m : plot.marker_x) x0 = std::min(x0, m), x1 = std::max(x1, m);
    if (!(x1 > x0)) x0 -= 1, x1 += 1;
    if (!(y1 > y0)) y0 -= 1, y1 += 1;
    const double pad = 0.05 * (y1 - y0);
    y0 -= pad, y1 += pad;
    auto px = [&](double x) { return left + (x - x0) / (x1 - x0) * (W - left - right); };
    auto py = [&](double y) { return H - bottom - (y - y0) / (y1 - y0) * (H - top - bottom); };
    std::ostringstream o;
    o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H
      << "' font-family='sans-serif' font-size='11'>\n";
    o << "<rect width='100%' height='100%' fill='white'/>\n";
    o << "<text x='" << W / 2 << "' y='16' text-anchor='middle' font-size='13'>"
      << html_escape(plot.title) << "</text>\n";
    // Axes and ticks.
    o << "<rect x='" << left << "' y='" << top << "' width='" << W - left - right << "' height='"
      << H - top - bottom << "' fill='none' stroke='#444'/>\n";
    const double xs = tick_step(x1 - x0), ys = tick_step(y1 - y0);
    for (double t = std::ceil(x0 / xs) * xs; t <= x1 + 1e-9 * xs; t += xs) {
        o << "<line x1='" << px(t) << "' y1='" << H - bottom << "' x2='" << px(t) << "' y2='"
          << H - bottom + 4 << "' stroke='#444'/><text x='" << px(t) << "' y='" << H - bottom + 16
          << "' text-anchor='middle'>" << number(std::abs(t) < 1e-12 ? 0.0 : t) << "</text>\n";
    }
    for (double t = std::ceil(y0 / ys) * ys; t <= y1 + 1e-9 * ys; t += ys) {
        o << "<line x1='" << left - 4 << "' y1='" << py(t) << "' x2='" << W - right << "' y2='"
          << py(t) << "' stroke='#ddd'/><text x='" << left - 6 << "' y='" << py(t) + 4
          << "' text-anchor='end'>" << number(std::abs(t) < 1e-12 ? 0.0 : t) << "</text>\n";
    }
    o << "<text x='" << (left + W - right) / 2 << "' y='" << H - 8 << "' text-anchor='middle'>"
      << html_escape(plot.x_label) << "</text>\n";
    o << "<text transform='translate(14," << (top + H - bottom) / 2
      << ") rotate(-90)' text-anchor='middle'>" << html_escape(plot.y_label) << "</text>\n";
    for (double m : plot.marker_x) {
        o << "<line x1='" << px(m) << "' y1='" << top << "' x2='" << px(m) << "' y2='" << H - bottom
          << "' stroke='#888' stroke-dasharray='4 3'/>\n";
    }
    static const char* colours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e"};
    for (std::size_t k = 0; k < plot.series.size(); ++k) {
        const Plot::Series& s = plot.series[k];
        const char* colour = colours[k % 5];
        if (s.points) {
            for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
                if (!std::isfinite(s.y[i])) continue;
                o << "<circle cx='" << px(s.x[i]) << "' cy='" << py(s.y[i]) << "' r='3' fill='"
                  << colour << "'/>";
            }
        } else {
            o << "<polyline fill='none' stroke='" << colour << "' stroke-width='1.5' points='";
            for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
                if (std::isfinite(s.y[i])) o << px(s.x[i]) << ',' << py(s.y[i]) << ' ';
            o << "'/>";
        }
        o << "\n<text x='" << W - right - 6 << "' y='" << top + 14 + 14 * double(k)
          << "' text-anchor='end' fill='" << colour << "'>" << html_escape(s.name) << "</text>\n";
    }
    o << "</svg>\n";
    return o.str();
}

}  // namespace

nlohmann::json to_json(const std::vector<const Case*>& run,
                       const std::vector<CaseResult>& results) {
    nlohmann::json records = nlohmann::json::array();
    for (std::size_t c = 0; c < run.size() && c < results.size(); ++c) {
        for (const Measurement& m : results[c].measurements) {
            records.push_back({{"case", run[c]->name},
                               {"quantity", m.quantity},
                               {"measured", std::isfinite(m.measured) ? nlohmann::json(m.measured)
                                                                      : nlohmann::json(nullptr)},
                               {"expected", m.expected},
                               {"tolerance", m.tolerance},
                               {"unit", m.unit},
                               {"check", check_name(m.check)},
                               {"pass", m.pass()}});
        }
    }
    return records;
}

void write_report(const std::string& dir, const std::vector<const Case*>& run,
                  const std::vector<CaseResult>& results,
                  const std::function<std::string(const std::string&)>& stage,
                  const std::string& header_note) {
    std::size_t passed = 0;
    for (const CaseResult& r : results) passed += r.pass() ? 1 : 0;
    std::ostringstream h;
    h << "<!DOCTYPE html>\n<html><head><meta charset='utf-8'><title>sonotrace validation</title>\n"
         "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
         "table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:3px "
         "8px;text-align:right}td:first-child,th:first-child{text-align:left}"
         "table.summary td:nth-child(2){text-align:left}"
         ".pass{color:#080;font-weight:bold}.fail{color:#c00;font-weight:bold}"
         "figure{display:inline-block;margin:.5em;vertical-align:top}figcaption{font-size:90%;"
         "max-width:520px}img{max-width:640px;border:1px solid #ccc}h2{margin-top:2em;"
         "border-bottom:1px solid #ccc}</style></head><body>\n";
    h << "<h1>sonotrace " SONOTRACE_VERSION " validation</h1>\n<p>" << passed << " of "
      << results.size() << " cases pass. " << html_escape(header_note) << "</p>\n";
    h << "<table "
         "class='summary'><tr><th>case</th><th>what</th><th>result</th><th>seconds</th></tr>\n";
    for (std::size_t c = 0; c < run.size(); ++c) {
        h << "<tr><td><a href='#" << run[c]->name << "'>" << run[c]->name << "</a></td><td>"
          << html_escape(run[c]->title) << "</td><td class='"
          << (results[c].pass() ? "pass'>PASS" : "fail'>FAIL") << "</td><td>"
          << number(results[c].seconds, 3) << "</td></tr>\n";
    }
    h << "</table>\n";
    for (std::size_t c = 0; c < run.size(); ++c) {
        const Case& k = *run[c];
        const CaseResult& r = results[c];
        h << "<h2 id='" << k.name << "'>" << k.name << ": " << html_escape(k.title)
          << " <span class='" << (r.pass() ? "pass'>PASS" : "fail'>FAIL") << "</span></h2>\n<p>"
          << html_escape(k.physics) << "</p>\n";
        h << "<table><tr><th>quantity</th><th>measured</th><th>expected</th><th>unit</th>"
             "<th></th></tr>\n";
        for (const Measurement& m : r.measurements) {
            h << "<tr><td>" << html_escape(m.quantity) << "</td><td>" << number(m.measured)
              << "</td><td>" << expectation(m) << "</td><td>" << html_escape(m.unit)
              << "</td><td class='" << (m.pass() ? "pass'>PASS" : "fail'>FAIL") << "</td></tr>\n";
        }
        h << "</table>\n";
        for (std::size_t f = 0; f < r.figures.size(); ++f) {
            const std::string file = k.name + "_" + std::to_string(f) + ".png";
            imaging::write_png(r.figures[f].picture, stage(dir + "/" + file));
            h << "<figure><img src='" << file << "'><figcaption>"
              << html_escape(r.figures[f].caption) << "</figcaption></figure>\n";
        }
        for (const Plot& p : r.plots) h << "<figure>" << svg_plot(p) << "</figure>\n";
    }
    h << "</body></html>\n";
    const std::string text = h.str();
    base::write_file(stage(dir + "/index.html"), text.data(), text.size());
}

}  // namespace sonotrace::validation
