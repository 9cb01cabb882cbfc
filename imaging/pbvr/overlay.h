#pragma once
// The ultrasound context in the 3D view: the probe as a small model, the sector of its
// scan plane outlined, and the B-mode frame textured on it. They are rasterized once per
// camera as opaque surfaces into entries of the renderer's Z-buffer
// (PbvrRenderer::set_overlay), so in every repetition particles in front of the plane
// hide it and the plane hides particles behind it.
#include <string>
#include <vector>

#include <glm/glm.hpp>
#include <opencv2/core.hpp>

#include "imaging/pbvr/camera.h"
#include "imaging/pbvr/tetra.h"
#include "probe/transducer.h"
#include "tissue/volume.h"

namespace sonotrace::imaging::pbvr {

struct FrameOverlay {
    cv::Mat frame;              // 8-bit grey B-mode, scan-converted; empty: none
    glm::dvec2 origin_mm{0.0};  // in-plane position of pixel (0, 0): lateral, depth
    glm::dvec2 pixel_mm{1.0};   // pixel spacing: lateral, depth
    glm::dvec3 position{0.0};   // the probe pose in world mm (ScanGeometry's origin)
    glm::dvec3 axial{0.0, 0.0, 1.0}, lateral{1.0, 0.0, 0.0}, elevation{0.0, 1.0, 0.0};
    probe::Transducer transducer;  // its sector
    bool draw_frame = true;        // false: the sector's outline only (a sector mesh shows it)
};

// From the JSON sidecar `sonotrace simulate` writes next to a frame (the PNG of the same
// stem). Throws base::InputError naming the file and field.
FrameOverlay load_frame_overlay(const std::string& sidecar_path);

// Z-buffer entries (zbuffer_entry) of the overlay for every sub-pixel of the camera.
std::vector<uint64_t> overlay_layer(const FrameOverlay& overlay, const OrbitCamera& camera,
                                    int subpixel_level);

// The frame's sector as an irregular volume: a grid over scan lines (every
// `line_step`-th), depth (`depth_step_mm`) and elevation (the slice thickness), split
// into tetrahedra, carrying the frame's grey values (0..255) at the points.
TetMesh sector_mesh(const FrameOverlay& overlay, int line_step = 2, double depth_step_mm = 1.0);

// The half-space on the camera's side of the scan plane, in a volume's local frame (for
// RenderSettings::clip_plane): removing it shows what lies around the plane.
glm::vec4 camera_side_of_plane(const FrameOverlay& overlay, const tissue::VolumeGeometry& volume,
                               const OrbitCamera& camera);

}  // namespace sonotrace::imaging::pbvr
