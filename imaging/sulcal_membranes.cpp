#include "imaging/sulcal_membranes.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <string>

#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"

namespace sonotrace::imaging {

namespace {

// Where samples lie between CSF (0) and brain (1): their speed, density and backscatter
// each as a fraction of the way from CSF's to brain's, averaged; another tissue (NaN)
// where the three disagree by more than 0.3 or lie beyond either end by more than a
// quarter. A transfer function blends CSF and brain across a T1's partial-volume
// boundary (a millimetre of the resampled map), so a boundary holds every fraction.
struct CsfToBrain {
    const float *c, *rho, *b;  // the maps' speed, density, backscatter
    float c0, rho0, b0, c_scale, rho_scale, b_scale;
    CsfToBrain(const tissue::PropertyMaps& maps, const tissue::TissueEntry& csf,
               const tissue::TissueEntry& brain) {
        using tissue::Property;
        auto from = [&](Property p, const float*& field, float& start, float& scale) {
            const auto f = std::size_t(p);
            field = maps.fields[f].voxels().data();
            start = csf.properties.values[f];
            scale = 1.0f / (brain.properties.values[f] - start);
        };
        from(Property::speed_of_sound, c, c0, c_scale);
        from(Property::density, rho, rho0, rho_scale);
        from(Property::backscatter, b, b0, b_scale);
    }
    float operator()(std::size_t v) const {
        const float fc = (c[v] - c0) * c_scale, fr = (rho[v] - rho0) * rho_scale,
                    fb = (b[v] - b0) * b_scale;
        const float mean = (fc + fr + fb) * (1.0f / 3.0f);
        const bool agree = std::abs(fc - mean) <= 0.3f && std::abs(fr - mean) <= 0.3f &&
                           std::abs(fb - mean) <= 0.3f;
        return agree && mean >= -0.25f && mean <= 1.25f ? mean : std::nanf("");
    }
};

// A square reaching r_mm from its centre along the map's axes (the header: why not a disc).
cv::Mat square(double r_mm, double dx, double dy) {
    const int rx = std::max(1, int(std::lround(r_mm / dx))),
              ry = std::max(1, int(std::lround(r_mm / dy)));
    return cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * rx + 1, 2 * ry + 1));
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
    const cv::Mat thick = square(kThickCsfMm, dx, dy), band = square(kMembraneMm, dx, dy);
    const CsfToBrain csf_to_brain(maps, csf, brain);
    std::size_t changed = 0;
    for (int k = 0; k < n.z; ++k) {
        // The fraction from CSF to brain (other tissues: 1, as brain), which samples are
        // more CSF than brain, and which are another tissue.
        cv::Mat fraction(n.y, n.x, CV_32F), is_csf(n.y, n.x, CV_8U, cv::Scalar(0)),
            other(n.y, n.x, CV_8U, cv::Scalar(0));
        bool any_csf = false, any_brain = false;
        for (int j = 0; j < n.y; ++j) {
            float* fraction_row = fraction.ptr<float>(j);
            uint8_t *csf_row = is_csf.ptr<uint8_t>(j), *other_row = other.ptr<uint8_t>(j);
            const std::size_t first = maps[tissue::Property::density].linear_index(0, j, k);
            for (int i = 0; i < n.x; ++i) {
                const float f = csf_to_brain(first + std::size_t(i));
                fraction_row[i] = std::isnan(f) ? 1.0f : std::clamp(f, 0.0f, 1.0f);
                other_row[i] = std::isnan(f);
                csf_row[i] = f < 0.5f;
                any_csf |= f < 0.5f;
                any_brain |= f >= 0.5f;
            }
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
                // Its scattering only: thinner than the beam, the membrane scatters but
                // does not reflect or refract (giving its samples the membrane's speed and
                // density made interfaces whose echoes stood 15-18 dB above the brain).
                for (const tissue::Property p :
                     {tissue::Property::backscatter, tissue::Property::scatterer_density})
                    maps[p].at(i, j, k) = pia.properties.values[std::size_t(p)];
                if (labels) labels->at(i, j, k) = pia_label;
                ++changed;
            }
    }
    return changed;
}

}  // namespace sonotrace::imaging
