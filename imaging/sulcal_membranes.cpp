#include "imaging/sulcal_membranes.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <string>

#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace::imaging {

namespace {

// Where a sample lies between CSF (0) and brain (1): its speed, density and backscatter
// each as a fraction of the way from CSF's to brain's, averaged; NaN when they disagree
// by more than 0.3 or lie beyond either end by more than a quarter (another tissue). A
// transfer function blends the two across a T1's partial-volume boundary (a millimetre
// of the resampled map), so a boundary holds samples of every fraction.
float csf_to_brain(const tissue::PropertyMaps& maps, std::size_t v, const tissue::TissueEntry& csf,
                   const tissue::TissueEntry& brain) {
    using tissue::Property;
    float fractions[3], mean = 0.0f;
    const Property properties[3] = {Property::speed_of_sound, Property::density,
                                    Property::backscatter};
    for (int p = 0; p < 3; ++p) {
        const auto f = std::size_t(properties[p]);
        fractions[p] = (maps.fields[f].voxels()[v] - csf.properties.values[f]) /
                       (brain.properties.values[f] - csf.properties.values[f]);
        mean += fractions[p] / 3.0f;
    }
    for (const float f : fractions)
        if (!(std::abs(f - mean) <= 0.3f)) return std::nanf("");
    return mean >= -0.25f && mean <= 1.25f ? mean : std::nanf("");
}

// A disc (an ellipse in pixels where the spacings differ) of radius r_mm.
cv::Mat disc(double r_mm, double dx, double dy) {
    const int rx = std::max(1, int(std::lround(r_mm / dx))),
              ry = std::max(1, int(std::lround(r_mm / dy)));
    return cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * rx + 1, 2 * ry + 1));
}

}  // namespace

std::size_t add_sulcal_membranes(tissue::PropertyMaps& maps, tissue::Volume* labels) {
    const tissue::TissueEntry& brain = tissue::find_tissue("brain", "", "");
    const tissue::TissueEntry& csf = tissue::find_tissue("csf", "", "");
    const tissue::TissueEntry& pia = tissue::find_tissue("pia_arachnoid", "", "");
    const float pia_label = float(tissue::tissue_label_of("pia_arachnoid"));
    const tissue::VolumeGeometry& grid = maps.geometry();
    const glm::ivec3 n = grid.dims;
    const double dx = grid.spacing.x, dy = grid.spacing.y;
    const cv::Mat thick = disc(kThickCsfMm, dx, dy), band = disc(kMembraneMm, dx, dy);
    std::size_t changed = 0;
    for (int k = 0; k < n.z; ++k) {
        // The fraction from CSF to brain (other tissues: 1, as brain), which samples are
        // more CSF than brain, and which are another tissue.
        cv::Mat fraction(n.y, n.x, CV_32F), is_csf(n.y, n.x, CV_8U, cv::Scalar(0)),
            other(n.y, n.x, CV_8U, cv::Scalar(0));
        bool any_csf = false, any_brain = false;
        for (int j = 0; j < n.y; ++j)
            for (int i = 0; i < n.x; ++i) {
                const std::size_t v = maps[tissue::Property::density].linear_index(i, j, k);
                const float f = csf_to_brain(maps, v, csf, brain);
                fraction.at<float>(j, i) = std::isnan(f) ? 1.0f : std::clamp(f, 0.0f, 1.0f);
                if (std::isnan(f)) other.at<uint8_t>(j, i) = 1;
                if (f < 0.5f) is_csf.at<uint8_t>(j, i) = 1, any_csf = true;
                any_brain |= f >= 0.5f && f <= 1.25f;
            }
        if (!any_csf || !any_brain) continue;
        // Valleys narrower than the disc: the closing fills them (a black top-hat).
        cv::Mat closed, wide, is_brain, near_brain;
        cv::morphologyEx(fraction, closed, cv::MORPH_CLOSE, thick, cv::Point(-1, -1), 1,
                         cv::BORDER_REPLICATE);
        // Wide CSF and its walls: what the opening keeps, grown by the disc again.
        cv::morphologyEx(is_csf, wide, cv::MORPH_OPEN, thick, cv::Point(-1, -1), 1,
                         cv::BORDER_CONSTANT, cv::Scalar(0));
        cv::dilate(wide, wide, thick, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
        // Nor CSF beside other tissue (the plexus on a ventricle's floor, bone, dura): a
        // valley against it is not a sulcus.
        cv::dilate(other, other, thick, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
        wide |= other;
        cv::compare(fraction, 0.5, is_brain, cv::CMP_GE);
        cv::dilate(is_brain, near_brain, band, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
                   cv::Scalar(0));
        for (int j = 0; j < n.y; ++j)
            for (int i = 0; i < n.x; ++i) {
                const float f = fraction.at<float>(j, i);
                if (closed.at<float>(j, i) - f < kValleyDepth || wide.at<uint8_t>(j, i) ||
                    !near_brain.at<uint8_t>(j, i))
                    continue;
                for (std::size_t p = 0; p < tissue::kPropertyCount; ++p)
                    maps.fields[p].at(i, j, k) = pia.properties.values[p];
                if (labels) labels->at(i, j, k) = pia_label;
                ++changed;
            }
    }
    return changed;
}

}  // namespace sonotrace::imaging
