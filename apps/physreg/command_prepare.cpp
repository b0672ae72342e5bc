// SPDX-License-Identifier: GPL-3.0-or-later
// physreg prepare (issue 44 item 3): the body model built once and stored with its condensed
// contact's compliance and paper 001's liver model, so that `physreg serve MODEL` starts in
// seconds. From a phantom dataset (its rest labels, landmarks and tool paths) or from a label map
// with the tool's radius and the paths it will take (the contact candidates lie near them).
#include "cli_support.hpp"
#include "progress.hpp"
#include "settings_options.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/dataset.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/point_path.hpp"
#include "physreg/registration/prepared_model.hpp"

#include <chrono>
#include <iostream>

namespace physreg::cli {

void add_subcommand_prepare(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string dataset, labels, label_roles, landmarks, parameters, output;
        std::vector<std::string> tool_paths;
        double tool_radius = 0.0, surface_cell_size = 7.0;
        bool replace = false;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("prepare", "Build the body model once for physreg serve: the condensed contact's compliance near the session's "
                                              "tool paths, the organ surfaces and paper 001's liver model, stored in a folder that serve starts from in seconds");
    sub->add_option("--dataset", o->dataset, "Phantom dataset: the rest labels, landmarks, tool and the session's paths");
    sub->add_option("--labels", o->labels, "Instead of --dataset: the rest label volume (NIfTI/NRRD/MHA/DICOM)");
    sub->add_option("--label-roles", o->label_roles, "With --labels: which label is which organ (default \"body=1;liver=2;lesion=3;vessel=4;bone=5;kidney=6\")");
    sub->add_option("--landmarks", o->landmarks, "With --labels: the targets (CSV/FCSV/.mrk.json, LPS mm) served as POINT 'targets'");
    sub->add_option("--tool-radius", o->tool_radius, "With --labels: the spherical tool's radius, mm");
    sub->add_option("--tool-path", o->tool_paths, "With --labels: a path the tool may take, \"x,y,z;x,y,z;…\" (LPS mm, the sphere's centre); repeat "
                                                  "for several. Skin nodes within the tool's reach + 10 mm of a path are the contact candidates");
    sub->add_option("--parameters", o->parameters, "Parameter file from physreg estimate (else the model settings)");
    auto settings = std::make_shared<SettingsOptions<CompressionRegistrationSettings>>(sub, compression_spec());
    sub->add_option("--surface-cell-size", o->surface_cell_size, "Paper 001's tetrahedral liver model for clouds: largest circumradius, mm (0: none; default 7)");
    sub->add_option("-o,--output", o->output, "Output folder (the prepared model)")->required();
    sub->add_flag("--force", o->replace, "Replace an existing output folder (only once the new one is complete)");
    sub->add_flag("--json", o->json, "Print a JSON summary on stdout");
    sub->callback([o, settings] {
        const auto t0 = std::chrono::steady_clock::now();
        if (o->dataset.empty() == o->labels.empty()) fail("prepare: give --dataset DIR or --labels FILE, not both");
        if (!o->dataset.empty() && (!o->tool_paths.empty() || o->tool_radius != 0.0 || !o->landmarks.empty() || !o->label_roles.empty()))
            fail("prepare: --tool-path, --tool-radius, --landmarks and --label-roles go with --labels (a dataset has its own)");
        if (!(o->surface_cell_size >= 0.0) || !std::isfinite(o->surface_cell_size))
            fail("--surface-cell-size {} must be ≥ 0 mm (0: no liver model for clouds)", o->surface_cell_size);
        check_output_path(o->output, "--output");
        const CompressionRegistrationSettings s = settings->resolve();
        validate(s, SettingNaming::option);
        ProgressDisplay bar("prepare");
        CompressionSubject subject;
        std::vector<Indenter> tools;
        bar.update(0.02, "the body model");
        if (!o->dataset.empty()) {
            subject = read_dataset_compression_subject(o->dataset, s, o->parameters);
            tools = dataset_session_tools(o->dataset);
            subject.description = {{"dataset", fs::absolute(o->dataset).string()}};
        } else {
            if (o->tool_paths.empty()) fail("prepare: --labels needs at least one --tool-path (the contact candidates lie near the tool's paths)");
            if (!(o->tool_radius > 0.0) || !std::isfinite(o->tool_radius)) fail("--tool-radius {} must be > 0 mm", o->tool_radius);
            const LabelRoles roles = o->label_roles.empty() ? phantom_label_roles() : parse_label_roles(o->label_roles, "--label-roles");
            roles.validate("--label-roles");
            LandmarkSet targets = o->landmarks.empty() ? LandmarkSet{} : read_landmarks(o->landmarks);
            subject = make_compression_subject(read_label_volume(o->labels), roles, std::move(targets), s, o->parameters, "--labels '" + o->labels + "'");
            subject.description = {{"labels", fs::absolute(o->labels).string()}, {"landmarks", o->landmarks}};
            for (const auto& text : o->tool_paths) {
                Indenter t;
                t.name = "tool_" + std::to_string(tools.size() + 1);
                t.shape = IndenterShape::sphere;
                t.radius_mm = o->tool_radius;
                t.path = parse_point_path(text, "--tool-path");
                tools.push_back(std::move(t));
            }
        }
        const double model_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        PreparedModelOptions options;
        options.condensed.memory_limit_bytes = s.memory_limit_bytes();
        options.surface_cell_size_mm = o->surface_cell_size;
        bar.update(0.1, "condensed contact (factorisation and compliance)");
        auto prepared = prepare_body_model(std::move(subject), std::move(tools), options);
        prepared->description["timings_s"]["body_model"] = model_s;
        bar.update(0.9, "writing");
        const auto w0 = std::chrono::steady_clock::now();
        write_prepared_model(*prepared, o->output, o->replace);
        bar.finish();
        const auto& pre = prepared->condensed->precomputation();
        nlohmann::json summary{{"command", "prepare"},
                               {"output", fs::absolute(o->output).string()},
                               {"nodes", prepared->subject.model.mesh.node_count()},
                               {"candidate_nodes", pre.candidate_nodes},
                               {"query_nodes", pre.query_nodes},
                               {"compliance_bytes", pre.compliance_bytes},
                               {"timings_s", prepared->description["timings_s"]},
                               {"write_s", std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count()},
                               {"seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()}};
        summary["timings_s"]["factorisation"] = pre.factorisation_s;
        summary["timings_s"]["compliance"] = pre.compliance_s;
        std::cerr << fmt::format("prepare: {} nodes, {} candidate and {} query nodes ({:.0f} MB of compliance); factorisation {:.1f} s, compliance "
                                 "{:.1f} s; {} written in {:.1f} s in all\n",
                                 prepared->subject.model.mesh.node_count(), pre.candidate_nodes, pre.query_nodes, double(pre.compliance_bytes) / 1e6,
                                 pre.factorisation_s, pre.compliance_s, o->output, summary["seconds"].get<double>());
        if (o->json) std::cout << summary.dump(2) << std::endl;
    });
}

} // namespace physreg::cli
