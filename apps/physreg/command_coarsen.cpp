// SPDX-License-Identifier: GPL-3.0-or-later
// physreg coarsen: a grid mesh re-gridded by the majority rule, with every fine node embedded in a
// coarse element (paper 000's coarse-to-fine model).
#include "cli_support.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/hex_meshing.hpp"

#include <fstream>

namespace physreg::cli {

void add_subcommand_coarsen(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string input, grid, output, embedding, components = "all";
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("coarsen", "Coarsen a grid hexahedral mesh (majority rule) and embed its nodes");
    sub->add_option("mesh", o->input, "Fine grid mesh written by 'physreg mesh' (.vtu)")->required();
    sub->add_option("--grid", o->grid, "Coarse cells per axis, e.g. 24x18x18")->required();
    sub->add_option("-o,--output", o->output, "Coarse mesh (.vtu or .msh)")->required();
    sub->add_option("--embedding", o->embedding,
                    "CSV: for every fine node the coarse cell holding it and its natural coordinates");
    sub->add_option("--components", o->components, "all, largest or refuse (see 'physreg mesh')")
        ->check(CLI::IsMember({"all", "largest", "refuse"}));
    sub->add_flag("--json", o->json, "Print a JSON summary on stdout");
    sub->callback([o] {
        check_output_path(o->output, "--output");
        if (!o->embedding.empty()) check_output_path(o->embedding, "--embedding");
        check_distinct_paths({{"--output", o->output}, {"--embedding", o->embedding}}, {{"MESH", o->input}});
        const Index3 dims = parse_grid_dims(o->grid, "--grid");
        const VolumeMesh fine = read_volume_mesh(o->input);
        const auto result = coarsen(fine, dims, parse_component_policy(o->components));
        std::size_t outside = 0;
        double worst = 0.0;
        for (const auto& e : result.fine_nodes) {
            outside += !e.inside;
            worst = std::max(worst, e.distance_mm);
        }
        OutputFiles outputs; // both or neither
        outputs.write(o->output, [&](const auto& path) { write_volume_mesh(path, result.mesh); });
        if (!o->embedding.empty())
            outputs.write(o->embedding, [&](const auto& path) { write_atomically(path, [&](const std::filesystem::path& tmp) {
                std::ofstream out(tmp);
                out.precision(17);
                out << "fine_node,coarse_cell,xi,eta,zeta,inside,distance_mm\n";
                for (std::size_t n = 0; n < result.fine_nodes.size(); ++n) {
                    const auto& e = result.fine_nodes[n];
                    out << n << ',' << e.cell << ',' << e.natural[0] << ',' << e.natural[1] << ',' << e.natural[2]
                        << ',' << (e.inside ? 1 : 0) << ',' << e.distance_mm << "\n";
                }
                out.close();
                if (!out) fail("--embedding '{}': write failed", o->embedding);
            }); });
        outputs.commit();
        if (outside)
            logger()->warn("{} of {} fine nodes lie outside the coarse mesh (up to {:.3f} mm); they are embedded "
                           "in the nearest coarse cell with extrapolated natural coordinates",
                           outside, result.fine_nodes.size(), worst);
        nlohmann::json summary = mesh_summary(result.mesh);
        summary["fine"] = {{"file", o->input}, {"nodes", fine.node_count()}, {"cells", fine.cell_count()}};
        summary["fine_nodes_outside_coarse"] = outside;
        summary["max_outside_distance_mm"] = worst;
        summary["components"] = to_json(result.components);
        logger()->info("coarsened {} → {} hexahedra ({} nodes) → '{}'", fine.cell_count(), result.mesh.cell_count(),
                       result.mesh.node_count(), o->output);
        report(*o, summary);
    });
}

} // namespace physreg::cli
