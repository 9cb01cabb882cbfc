#pragma once
// The probe face's geometry, as the tracer's capture receive model meets it: whether a
// step crosses the face within its aperture, and the face's normal there (flat, or a
// convex arc about the elevation axis). Private to simulator/tracer.cpp.
#include <cmath>

#include <glm/glm.hpp>

#include "simulator/interactions.h"
#include "simulator/trace_settings.h"

namespace sonotrace::simulator::detail {
// Internal linkage, as when this lived in tracer.cpp: the one file that includes it
// inlines what it calls once.
namespace {

// The axis a convex face curves about: through the centre of its arc, along the
// elevation in 3D (a 2D face's arc lies in the plane).
template <int Dim>
Vec<Dim> arc_centre(const ProbeFace<Dim>& face) {
    return face.centre - face.normal * face.radius_mm;
}
// The part of an offset from the arc's axis that lies across it (all of it in 2D).
template <int Dim>
Vec<Dim> across_axis(const ProbeFace<Dim>& face, const Vec<Dim>& rel) {
    if constexpr (Dim == 2) {
        (void)face;
        return rel;
    } else {
        return rel - face.elevation * glm::dot(rel, face.elevation);
    }
}
template <int Dim>
float elevation_offset(const ProbeFace<Dim>& face, const Vec<Dim>& offset) {
    if constexpr (Dim == 2) {
        (void)face, (void)offset;
        return 0.0f;
    } else {
        return glm::dot(offset, face.elevation);
    }
}

// Within the face's rectangle (flat faces): across the array and in elevation.
template <int Dim>
bool within_aperture(const ProbeFace<Dim>& face, const Vec<Dim>& x) {
    const Vec<Dim> offset = x - face.centre;
    if constexpr (Dim == 2) {
        const Vec<Dim> across(-face.normal.y, face.normal.x);
        return std::abs(glm::dot(offset, across)) <= face.half_width_mm;
    } else {
        const Vec<Dim> lateral = glm::cross(face.normal, face.elevation);
        return std::abs(glm::dot(offset, lateral)) <= face.half_width_mm &&
               std::abs(glm::dot(offset, face.elevation)) <= face.half_height_mm;
    }
}

// True if the step from -> to enters the face from the tissue side within its aperture.
template <int Dim>
bool crosses_face(const ProbeFace<Dim>& face, const Vec<Dim>& from, const Vec<Dim>& to) {
    if (face.radius_mm > 0.0f) {  // convex: from outside its cylinder (2D: circle) to inside
        const Vec<Dim> centre = arc_centre(face);
        const float r2 = face.radius_mm * face.radius_mm;
        const Vec<Dim> rel = across_axis(face, to - centre),
                       before = across_axis(face, from - centre);
        if (!(glm::dot(before, before) >= r2 && glm::dot(rel, rel) < r2)) return false;
        // Arc length from the face's centre: the angle between rel and the normal.
        float aside;
        if constexpr (Dim == 2)
            aside = std::abs(face.normal.x * rel.y - face.normal.y * rel.x);
        else
            aside = glm::length(glm::cross(face.normal, rel));
        const float angle = std::atan2(aside, glm::dot(face.normal, rel));
        return angle * face.radius_mm <= face.half_width_mm &&
               std::abs(elevation_offset(face, to - face.centre)) <= face.half_height_mm;
    }
    const float before = glm::dot(from - face.centre, face.normal);
    const float after = glm::dot(to - face.centre, face.normal);
    return before >= 0.0f && after < 0.0f && within_aperture(face, to);
}

template <int Dim>
Vec<Dim> face_normal_at(const ProbeFace<Dim>& face, const Vec<Dim>& x) {
    if (face.radius_mm > 0.0f) return glm::normalize(across_axis(face, x - arc_centre(face)));
    return face.normal;
}

}  // namespace
}  // namespace sonotrace::simulator::detail
