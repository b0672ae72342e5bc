// SPDX-License-Identifier: GPL-3.0-or-later
// physreg register-images: paper 002 — a moving image registered to a fixed (reference) image by a
// linear-elastic simulation whose boundary load and Young's moduli are estimated from the two
// segmentations, with ITK's rigid, Demons and B-spline registrations (on intensities and on
// labels) in the same report. The pipeline is the library's register_images
// (registration/images/image_registration.hpp); this command reads the inputs, resolves the
// settings (image_registration_spec: options, --settings FILE) and writes the files.
#include "cli_support.hpp"
#include "progress.hpp"
#include "settings_options.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/phantom/registration_cases.hpp"
#include "physreg/registration/images/image_registration.hpp"

#include <chrono>
#include <fstream>
#include <iostream>

namespace physreg::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct Sources : CommonOptions {
    std::string dataset, state = "insufflation", fixed, fixed_labels, moving, moving_labels, landmarks_fixed, landmarks_moving, tissues, output;
    bool replace = false;
};

/// The pair from --dataset (its conventions: ImagePair's defaults for a dataset) or from files.
ImagePair load_pair(const Sources& o)
{
    const bool files = !o.fixed.empty() || !o.fixed_labels.empty() || !o.moving.empty() || !o.moving_labels.empty();
    if (o.dataset.empty() == !files || (files && (o.fixed_labels.empty() || o.moving_labels.empty() || o.fixed.empty() != o.moving.empty())))
        fail("register-images: give --dataset DIR, or --fixed-labels and --moving-labels (a label-to-label pair), with --fixed and --moving for their images");
    ImagePair pair;
    if (!o.dataset.empty()) {
        if (!o.landmarks_fixed.empty() || !o.landmarks_moving.empty()) fail("register-images: --dataset provides the landmarks; leave out --landmarks-fixed/--landmarks-moving");
        pair = read_dataset_image_pair(o.dataset, o.state);
    } else {
        pair.fixed_labels = read_label_volume(o.fixed_labels);
        pair.moving_labels = read_label_volume(o.moving_labels);
        pair.intensities = !o.fixed.empty();
        const auto as_image = [](const LabelVolume& l) {
            ScalarImage image{l.geometry, std::vector<float>(l.labels.begin(), l.labels.end())};
            return image;
        };
        pair.fixed = pair.intensities ? read_scalar_image(o.fixed) : as_image(pair.fixed_labels);
        pair.moving = pair.intensities ? read_scalar_image(o.moving) : as_image(pair.moving_labels);
        if (o.landmarks_fixed.empty() != o.landmarks_moving.empty()) fail("register-images: give both --landmarks-fixed and --landmarks-moving, or neither");
        if (!o.landmarks_fixed.empty()) {
            pair.landmarks_fixed = read_landmarks(o.landmarks_fixed);
            pair.landmarks_moving = read_landmarks(o.landmarks_moving);
        }
        pair.description = {{"fixed", o.fixed}, {"fixed_labels", o.fixed_labels}, {"moving", o.moving}, {"moving_labels", o.moving_labels}};
    }
    if (!o.tissues.empty()) {
        pair.tissues = read_tissue_table(o.tissues);
        pair.tissues_source = o.tissues;
    }
    return pair;
}

void write_outputs(const fs::path& folder, const ImageRegistrationResult& r)
{
    const ImageMethodOutcome& chosen = r.chosen_method();
    write_label_volume(folder / "warped_labels.nii.gz", chosen.warped_labels);
    if (!r.warped_moving.values.empty()) write_scalar_image(folder / "warped_moving.nii.gz", r.warped_moving);
    write_displacement_field(folder / "displacement.nii.gz", chosen.field);
    if (chosen.landmarks) write_landmarks(folder / "landmarks.csv", *chosen.landmarks);
    const auto& b = r.biomechanical;
    MeshData data;
    data.point_data.push_back({"displacement", 3, std::vector<double>(b.displacement_mm.data(), b.displacement_mm.data() + b.displacement_mm.size())});
    data.point_data.push_back({"force", 3, std::vector<double>(b.force_n.data(), b.force_n.data() + b.force_n.size())});
    data.point_data.push_back({"held", 1, std::vector<double>(r.held.begin(), r.held.end())});
    write_vtu(folder / "mesh.vtu", r.mesh, data);
    write_atomically(folder / "parameters.json", [&](const fs::path& tmp) { std::ofstream(tmp) << r.parameters.dump(2) << "\n"; });
}

/// One line per method on stderr: TRE (all, internal), mean Dice, seconds.
void print_methods(const ImageRegistrationResult& r, const json& methods)
{
    for (const auto& m : r.methods) {
        const json& e = methods[m.name];
        std::string line = fmt::format("{:<20}", m.name);
        if (e.contains("tre")) {
            // A group without landmarks has null statistics (issue 28 item 6).
            const auto mm = [](const json& v) { return v.is_number() ? fmt::format("{:.2f}", v.get<double>()) : std::string("–"); };
            line += fmt::format(" TRE {} mm (internal {})", mm(e["tre"]["all"]["mean_mm"]), mm(e["tre"]["internal"]["mean_mm"]));
        }
        double dice = 0.0;
        for (const auto& [k, v] : e["dice"].items()) dice += v.get<double>();
        line += fmt::format(", mean Dice {:.3f}, {:.1f} s", dice / std::max<std::size_t>(1, e["dice"].size()), m.seconds);
        std::cerr << line << "\n";
    }
    for (const auto& [name, reason] : r.failed_baselines) std::cerr << fmt::format("{:<20} failed: {}\n", name, reason);
}

} // namespace

void add_subcommand_register_images(CLI::App& app)
{
    auto o = std::make_shared<Sources>();
    auto* cmd = app.add_subcommand("register-images",
                                   "Paper 002: register a moving image to a fixed one with a linear-elastic simulation whose boundary load and "
                                   "per-structure Young's moduli are estimated from the segmentations; rigid, Demons and B-spline baselines");
    cmd->add_option("--dataset", o->dataset, "a phantom dataset: its rest → state segmentation pair, images and landmarks");
    cmd->add_option("--state", o->state, "the dataset's deformed state (the fixed image)")->capture_default_str();
    cmd->add_option("--fixed", o->fixed, "the fixed (reference, e.g. intra-operative) image");
    cmd->add_option("--fixed-labels", o->fixed_labels, "its segmentation");
    cmd->add_option("--moving", o->moving, "the moving (pre-operative) image");
    cmd->add_option("--moving-labels", o->moving_labels, "its segmentation (meshed)");
    cmd->add_option("--landmarks-fixed", o->landmarks_fixed, "landmarks in the fixed image (CSV/FCSV/.mrk.json; TRE)");
    cmd->add_option("--landmarks-moving", o->landmarks_moving, "the same landmarks in the moving image");
    cmd->add_option("--tissues", o->tissues, "tissue table (YAML/JSON): initial E (Pa) and ν per label (default: 3 kPa, ν 0.45)");
    auto settings = std::make_shared<SettingsOptions<ImageRegistrationSettings>>(cmd, image_registration_spec());
    cmd->add_option("-o,--output", o->output, "output folder (staged: appears only when complete)")->required();
    cmd->add_flag("--force,--replace", o->replace, "replace an existing output folder (only once the new one is complete; --replace: the older name)");
    cmd->add_flag("--json", o->json, "print the summary as JSON on stdout");
    cmd->callback([o, settings] {
        const auto start = std::chrono::steady_clock::now();
        const ImageRegistrationSettings s = settings->resolve();
        validate(s, SettingNaming::option);
        check_output_path(o->output, "--output");
        StagedDirectory staging(o->output, o->replace);
        ProgressDisplay bar("register-images");
        bar.update(0.0, "inputs");
        const ImagePair pair = load_pair(*o);
        ImageRegistrationResult r = register_images(pair, s, [&](double f, const std::string& m) { bar.update(f, m); });
        bar.update(0.95, "outputs");
        write_outputs(staging.path(), r);
        if (!settings->file().empty()) r.summary["settings_file"] = settings->file();
        r.summary["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        write_atomically(staging.path() / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << r.summary.dump(2) << "\n"; });
        bar.update(0.99, "report.html");
        write_html_report(staging.path(), o->output);
        staging.commit();
        bar.finish();
        if (o->json)
            std::cout << r.summary.dump(2) << "\n";
        else
            print_methods(r, r.summary["methods"]);
    });
}

} // namespace physreg::cli
