#include "ui/cli/tissue_command.h"

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <limits>
#include <sstream>

#include <tbb/parallel_for.h>

#include "imaging/picture.h"
#include "probe/pose.h"
#include "sonotrace_version.h"
#include "tissue/acoustic_map.h"
#include "tissue/base/atomic_output.h"
#include "tissue/base/error.h"
#include "tissue/base/memory.h"
#include "tissue/nifti_io.h"
#include "tissue/property_maps.h"
#include "tissue/resample.h"
#include "tissue/tissue_table.h"
#include "tissue/transfer_function.h"
#include "tissue/volume_io.h"

namespace sonotrace::ui {

namespace {

using nlohmann::json;
using tissue::Property;

constexpr ParameterDoc kOutDoc = {"--out", "", "output directory"};

struct FieldOutput {
    std::string key;
    imaging::FieldStyle style;
    tissue::Volume field;
};

tissue::Volume central_plane(const tissue::Volume& v) {
    if (v.is_2d()) return v;
    tissue::VolumeGeometry g = v.geometry();
    const int k = g.dims.z / 2;
    g.origin = g.index_to_world({0.0, 0.0, double(k)});
    g.dims.z = 1;
    tissue::Volume plane(g);
    for (int j = 0; j < g.dims.y; ++j) {
        for (int i = 0; i < g.dims.x; ++i) plane.at(i, j) = v.at(i, j, k);
    }
    return plane;
}

}  // namespace

std::string tissue_tables_markdown() {
    std::ostringstream out;
    out << "| property | unit | range | meaning |\n|---|---|---|---|\n";
    for (const auto& p : tissue::kPropertyInfo) {
        out << "| `" << p.key << "` | " << p.unit << " | " << p.min << " .. " << p.max << " | "
            << p.description << " |\n";
    }
    out << "\n| tissue |";
    for (const auto& p : tissue::kPropertyInfo) out << " " << p.key << " |";
    out << " Z [MRayl] | source |\n|---|";
    for (std::size_t n = 0; n <= tissue::kPropertyCount; ++n) out << "---|";
    out << "---|\n";
    for (const auto& t : tissue::tissue_table()) {
        out << "| `" << t.key << "` |";
        for (float v : t.properties.values) out << " " << v << " |";
        out << " " << std::setprecision(3) << t.properties.impedance_mrayl() << std::setprecision(6)
            << " | " << t.source << " |\n";
    }
    return out.str();
}

CLI::App* add_tissue_command(CLI::App& app, TissueOptions& options) {
    CLI::App* cmd = app.add_subcommand(
        "tissue",
        "Show what the simulator will see: slice a volume under the probe pose, apply the "
        "transfer function and write the slice and every acoustic field as colour-mapped PNGs "
        "with a JSON sidecar (tissue.json).");
    add_slice_options(*cmd, options.slice, true);
    add_parameter(*cmd, kOutDoc, options.out_dir);
    add_run_options(*cmd, options.json_path, options.threads, options.quiet);
    cmd->add_flag("--nifti", options.write_nifti,
                  "also write every field as float NIfTI (.nii.gz) with the grid's geometry");
    cmd->add_flag("--list-tissues", options.list_tissues,
                  "print the acoustic properties (units, ranges) and the tissue table (literature "
                  "values) as Markdown and exit");
    return cmd;
}

int run_tissue_command(const TissueOptions& options) {
    if (options.list_tissues) {
        std::cout << tissue_tables_markdown();
        return 0;
    }

    StageTimer timer(options.quiet);
    const auto thread_limit = limit_threads(options.threads);
    const Slice slice = make_slice(options.slice, timer);
    const tissue::VolumeGeometry& grid = slice.grid;
    const tissue::PropertyMaps& maps = slice.maps;
    const tissue::Volume& values = slice.values;
    const tissue::GridExtent& extent = slice.extent;
    const float vmin = slice.source.value_min, vmax = slice.source.value_max;
    timer.begin("acoustic map and gradients");
    tissue::Volume grad_n(grid), grad_z(grid);
    auto store_gradients = [&](const auto& map) {
        for (int k = 0; k < grid.dims.z; ++k) {
            for (int j = 0; j < grid.dims.y; ++j) {
                for (int i = 0; i < grid.dims.x; ++i) {
                    const auto& t =
                        map.texel(typename std::decay_t<decltype(map)>::IVec(glm::ivec3(i, j, k)));
                    double gn = 0.0, gz = 0.0;
                    for (int a = 0; a < int(std::size(t.grad_impedance)); ++a) {
                        gn += double(t.grad_refractive_index[a]) * t.grad_refractive_index[a];
                        gz += double(t.grad_impedance[a]) * t.grad_impedance[a];
                    }
                    grad_n.at(i, j, k) = float(std::sqrt(gn));
                    grad_z.at(i, j, k) = float(std::sqrt(gz));
                }
            }
        }
    };
    if (grid.dims.z == 1)
        store_gradients(tissue::AcousticMap<2>::build(maps));
    else
        store_gradients(tissue::AcousticMap<3>::build(maps));
    timer.end();

    // ---- pictures ----
    timer.begin("writing pictures");
    std::vector<FieldOutput> fields;
    const double px = extent.pixel_mm;
    fields.push_back({"slice",
                      {"intensity", "volume units", imaging::Colormap::gray,
                       std::pair<double, double>(vmin, vmax), false, px},
                      values});
    const imaging::Colormap maps_cmap[] = {imaging::Colormap::turbo,   imaging::Colormap::viridis,
                                           imaging::Colormap::inferno, imaging::Colormap::bone,
                                           imaging::Colormap::magma,   imaging::Colormap::cividis};
    for (std::size_t n = 0; n < tissue::kPropertyCount; ++n) {
        const auto& info = tissue::kPropertyInfo[n];
        fields.push_back({std::string(info.key),
                          {std::string(info.label), std::string(info.unit), maps_cmap[n],
                           std::nullopt, false, px},
                          maps.fields[n]});
        if (n == 1) {
            fields.push_back({"impedance",
                              {"impedance Z", std::string(tissue::kImpedanceUnit),
                               imaging::Colormap::viridis, std::nullopt, false, px},
                              maps.impedance()});
        }
    }
    fields.push_back({"impedance_gradient",
                      {"|grad Z|", "MRayl/mm", imaging::Colormap::inferno, std::nullopt, true, px},
                      grad_z});
    fields.push_back({"refractive_index_gradient",
                      {"|grad n|", "1/mm", imaging::Colormap::inferno, std::nullopt, true, px},
                      grad_n});

    // Stage every path first (the transaction is not thread-safe), then render and encode
    // the pictures in parallel; each task writes only its own files.
    base::OutputTransaction transaction;
    json outputs = json::array();
    std::vector<std::string> png_staged(fields.size()), nii_staged(fields.size());
    for (std::size_t n = 0; n < fields.size(); ++n) {
        const FieldOutput& f = fields[n];
        const std::filesystem::path stem = std::filesystem::path(options.out_dir) / f.key;
        const auto [lo, hi] = f.field.value_range();
        json entry = {{"field", f.key},
                      {"unit", f.style.unit},
                      {"png", stem.string() + ".png"},
                      {"min", lo},
                      {"max", hi}};
        png_staged[n] = transaction.stage(stem.string() + ".png");
        if (options.write_nifti) {
            nii_staged[n] = transaction.stage(stem.string() + ".nii.gz");
            entry["nifti"] = stem.string() + ".nii.gz";
        }
        outputs.push_back(entry);
    }
    std::vector<cv::Mat> panels(fields.size());
    tbb::parallel_for(std::size_t(0), fields.size(), [&](std::size_t n) {
        panels[n] = imaging::render_field(central_plane(fields[n].field), fields[n].style);
        imaging::write_png(panels[n], png_staged[n]);
        if (options.write_nifti) tissue::write_nifti(fields[n].field, nii_staged[n]);
    });
    const std::string overview = (std::filesystem::path(options.out_dir) / "overview.png").string();
    imaging::write_png(imaging::montage(panels, 4), transaction.stage(overview));
    timer.end();

    // ---- sidecar ----
    json record = slice_json(slice, options.slice);
    record.update({
        {"command", "tissue"},
        {"software", {{"name", "sonotrace"}, {"version", SONOTRACE_VERSION}}},
        {"outputs", outputs},
        {"overview", overview},
        {"timings_s", timer.timings()},
    });
    const std::string sidecar = (std::filesystem::path(options.out_dir) / "tissue.json").string();
    write_json(record, transaction.stage(sidecar));
    if (!options.json_path.empty() && options.json_path != "-") {
        write_json(record, transaction.stage(options.json_path));
    }
    transaction.commit();
    if (options.json_path == "-") write_json(record, "-");
    if (!options.quiet) {
        std::cerr << "sonotrace: wrote " << outputs.size() + 1 << " pictures and tissue.json to "
                  << options.out_dir << " (overview: " << overview << ")\n";
    }
    return 0;
}

}  // namespace sonotrace::ui
