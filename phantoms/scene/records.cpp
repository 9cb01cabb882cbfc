#include "phantoms/scene/records.h"

#include <variant>

namespace sonotrace::scene {

using nlohmann::json;

json pose_json(const probe::Pose& pose) {
    return {{"text", pose.to_string()},
            {"position_mm", {pose.position.x, pose.position.y, pose.position.z}},
            {"lateral", {pose.lateral().x, pose.lateral().y, pose.lateral().z}},
            {"axial", {pose.axial().x, pose.axial().y, pose.axial().z}},
            {"elevation", {pose.elevation().x, pose.elevation().y, pose.elevation().z}}};
}

json geometry_json(const tissue::VolumeGeometry& g) {
    json direction = json::array();
    for (int c = 0; c < 3; ++c)
        direction.push_back({g.direction[c].x, g.direction[c].y, g.direction[c].z});
    return {{"dims", {g.dims.x, g.dims.y, g.dims.z}},
            {"spacing_mm", {g.spacing.x, g.spacing.y, g.spacing.z}},
            {"origin_mm", {g.origin.x, g.origin.y, g.origin.z}},
            {"direction", direction}};
}

json volume_source_json(const VolumeSource& source, const VolumeOptions& options) {
    return {{"volume",
             {{"spec", options.volume},
              {"path", source.loaded.path},
              {"format", source.loaded.format},
              {"geometry", geometry_json(source.loaded.volume.geometry())},
              {"value_range", {source.value_min, source.value_max}},
              {"outside_value", source.outside}}},
            {"transfer_function", source.tf->describe()},
            {"warnings", source.loaded.warnings}};
}

json transducer_json(const probe::Transducer& t) {
    json out = {{"name", t.name}, {"description", t.description}};
    for (const auto& doc : probe::transducer_parameter_docs())
        std::visit([&](const auto& value) { out[doc.record_key] = value; }, doc.get(t));
    return out;
}

}  // namespace sonotrace::scene
