#include "phantoms/scene/sweep.h"

#include <cmath>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "probe/pose.h"
#include "tissue/base/error.h"
#include "tissue/base/file_read.h"

namespace sonotrace::scene {

namespace {
// A file of poses: a million lines of them.
constexpr std::size_t kMaxSweepFileBytes = std::size_t(256) << 20;
}  // namespace

std::vector<SweepPlacement> sweep_placements(const std::string& sweep,
                                             const imaging::ScenePlacement& base) {
    std::vector<SweepPlacement> out;
    if (sweep.empty()) return {{base, 0.0}};
    if (std::filesystem::exists(sweep)) {
        // Read as a regular file only: a FIFO named here blocked the run for ever.
        std::istringstream in(base::read_regular_file(sweep, kMaxSweepFileBytes, "--sweep"));
        int line_number = 0;
        for (std::string line; std::getline(in, line);) {
            ++line_number;
            if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#') continue;
            SweepPlacement p{base, double(out.size())};
            p.scene.pose = probe::parse_pose(line, sweep + ":" + std::to_string(line_number));
            p.scene.description = base.description + " (pose from " + sweep + ")";
            out.push_back(p);
        }
        if (out.empty()) throw base::InputError(sweep, "", "lists no poses");
        return out;
    }
    std::vector<std::string> parts;
    {
        std::istringstream list(sweep);
        for (std::string part; std::getline(list, part, ':');) parts.push_back(part);
    }
    if (parts.size() != 3)
        throw base::InputError("--sweep", sweep,
                               "expected AXIS:LENGTH:STEP (mm) or a file of poses");
    glm::dvec3 axis;
    if (parts[0] == "elevation")
        axis = base.pose.elevation();
    else if (parts[0] == "lateral")
        axis = base.pose.lateral();
    else if (parts[0] == "axial")
        axis = base.pose.axial();
    else {
        std::istringstream xyz(parts[0]);
        char c1 = 0, c2 = 0;
        if (!(xyz >> axis.x >> c1 >> axis.y >> c2 >> axis.z) || c1 != ',' || c2 != ',' ||
            !(glm::length(axis) > 0.0) || !std::isfinite(glm::length(axis)))
            throw base::InputError("--sweep", parts[0],
                                   "axis must be elevation, lateral, axial or X,Y,Z");
        axis = glm::normalize(axis);
    }
    double length = 0.0, step = 0.0;
    try {
        length = std::stod(parts[1]);
        step = std::stod(parts[2]);
    } catch (const std::exception&) {
        throw base::InputError("--sweep", sweep, "LENGTH and STEP must be numbers (mm)");
    }
    base::require_in_range("--sweep", "length", length, 0.0, 1000.0, "mm");
    base::require_in_range("--sweep", "step", step, 1e-3, 1000.0, "mm");
    const int frames = int(std::floor(length / step + 1e-9)) + 1;
    if (frames > 10000)
        throw base::InputError("--sweep", sweep, "would make more than 10000 frames");
    for (int f = 0; f < frames; ++f) {
        SweepPlacement p{base, -0.5 * length + f * step};
        p.scene.pose.position += p.offset_mm * axis;
        out.push_back(p);
    }
    return out;
}

}  // namespace sonotrace::scene
