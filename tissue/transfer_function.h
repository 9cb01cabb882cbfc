#pragma once
// Transfer functions turn voxel values into acoustic properties.
//
// Two kinds share one small interface:
//  - piecewise-linear: control points (intensity -> properties), linear in between and
//    clamped outside; intensities are "raw" voxel values or "normalized" (0..1 spans the
//    volume's intensity window between two quantiles, so one preset fits scans with
//    different scaling);
//  - labels: a table from integer labels to tissues (label maps, phantoms). Label maps
//    are sampled nearest-neighbour because interpolating labels would invent tissues.
// Every control point or label names a tissue from tissue_table.h and/or gives property
// values explicitly (explicit values override the tissue's).
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tissue/acoustic_properties.h"
#include "tissue/volume.h"

namespace sonotrace::tissue {

class TransferFunction {
  public:
    virtual ~TransferFunction() = default;
    // Adapts to the volume before use (intensity window, label check). Throws base::InputError
    // naming the transfer function's file if the volume does not fit it.
    virtual void bind(const Volume& volume) = 0;
    virtual AcousticProperties evaluate(float value) const = 0;
    virtual bool uses_nearest_sampling() const = 0;
    // The tissue a value stands for, as 1 + its index in tissue_table() (0: a point or
    // label without a named tissue). Piecewise-linear: the nearer control point's tissue.
    virtual int tissue_label(float value) const = 0;
    // Name, source and parameters, for sidecars.
    virtual nlohmann::json describe() const = 0;
};

struct ControlPoint {
    double intensity = 0.0;
    std::string tissue;  // may be empty when every property is explicit
    AcousticProperties properties;
};

class PiecewiseLinearTransferFunction final : public TransferFunction {
  public:
    enum class Domain { raw, normalized };
    PiecewiseLinearTransferFunction(std::string name, std::string source, Domain domain,
                                    double low_quantile, double high_quantile,
                                    std::vector<ControlPoint> points);

    void bind(const Volume& volume) override;
    AcousticProperties evaluate(float value) const override;
    bool uses_nearest_sampling() const override { return false; }
    int tissue_label(float value) const override;
    nlohmann::json describe() const override;

    const std::vector<ControlPoint>& points() const { return points_; }
    // Raw intensities that normalized 0 and 1 map to (identity for the raw domain).
    double window_low() const { return window_low_; }
    double window_high() const { return window_high_; }

  private:
    std::string name_, source_;
    Domain domain_;
    double low_quantile_, high_quantile_;
    double window_low_ = 0.0, window_high_ = 1.0;
    std::vector<ControlPoint> points_;
    std::vector<int> tissue_labels_;  // per point
};

class LabelTransferFunction final : public TransferFunction {
  public:
    struct Entry {
        int label = 0;
        std::string tissue;
        AcousticProperties properties;
    };
    LabelTransferFunction(std::string name, std::string source, std::vector<Entry> entries);

    void bind(const Volume& volume) override;  // every voxel must be a listed integer label
    AcousticProperties evaluate(float value) const override;
    bool uses_nearest_sampling() const override { return true; }
    int tissue_label(float value) const override;
    nlohmann::json describe() const override;

  private:
    const Entry& entry(float value) const;
    std::string name_, source_;
    std::vector<Entry> entries_;      // sorted by label
    std::vector<int> tissue_labels_;  // per entry
};

// Reads a tissue reference ("tissue": "liver") and/or explicit property values (keys of
// kPropertyInfo) from a JSON object at path `where` of `source`. Without a tissue, every
// property must be given. `tissue_name` receives the tissue's key ("" without one).
AcousticProperties read_properties(const nlohmann::json& object, const std::string& source,
                                   const std::string& where, std::string* tissue_name);

// 1 + the index of a named tissue in tissue_table(); 0 for an empty or unknown name.
int tissue_label_of(const std::string& tissue);
// The tissue_table() key of a label from tissue_label(), "custom" for 0.
std::string tissue_label_name(int label);
// The legend of a label map, as every sidecar and manifest writes it: "0" outside the
// scanned region, then each label's tissue_table() key.
nlohmann::json label_legend();

// Names of the presets compiled into the binary (from tissue/presets/*.json).
std::vector<std::string> transfer_function_presets();
// `spec` is a preset name or a JSON file path. Throws base::InputError naming the file/field.
std::unique_ptr<TransferFunction> load_transfer_function(const std::string& spec);
// Parses JSON text; `source` names it in messages.
std::unique_ptr<TransferFunction> parse_transfer_function(const std::string& text,
                                                          const std::string& source);
std::unique_ptr<TransferFunction> transfer_function_from_json(const nlohmann::json& j,
                                                              const std::string& source);

}  // namespace sonotrace::tissue
