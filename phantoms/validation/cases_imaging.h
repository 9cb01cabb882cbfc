#pragma once
// The imaging cases (phantoms/validation/cases_imaging.cpp lists them), one family per file.
#include "phantoms/validation/validation.h"

namespace sonotrace::validation {

// cases_placement.cpp
CaseResult wire_depth(const CaseContext& ctx);
CaseResult speed_displacement(const CaseContext& ctx);
CaseResult refraction_shift(const CaseContext& ctx);
CaseResult mirror_image(const CaseContext& ctx);
// cases_levels.cpp
CaseResult shadow_and_enhancement(const CaseContext& ctx);
CaseResult flat_reflector(const CaseContext& ctx);
CaseResult two_layers(const CaseContext& ctx);
// cases_resolution.cpp
CaseResult resolution(const CaseContext& ctx);
// cases_speckle.cpp
CaseResult speckle_and_cysts(const CaseContext& ctx);
CaseResult per_line_means(const CaseContext& ctx);
CaseResult speckle_depth(const CaseContext& ctx);
// cases_picmus.cpp
CaseResult picmus(const CaseContext& ctx);

}  // namespace sonotrace::validation
