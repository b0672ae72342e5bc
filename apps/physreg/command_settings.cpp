// SPDX-License-Identifier: GPL-3.0-or-later
// physreg settings MODE: a registration mode's settings specification — each key of a settings file
// (--settings F, Python's dict), its command-line option, kind, default, unit, range or choices and
// help — as a table, or as JSON (--json; the same as Python's physreg.settings_spec(MODE)).
#include "cli_support.hpp"

#include "physreg/core/error.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/images/image_registration.hpp"
#include "physreg/registration/surface/partial_surface_registration.hpp"

#include <iostream>

namespace physreg::cli {

namespace {

template <typename Settings>
void print_table(const SettingsSpec<Settings>& spec)
{
    const nlohmann::json d = spec.describe();
    std::cout << fmt::format("{} settings (a settings file holds key: value; an option on the command line wins over the file)\n\n", spec.mode());
    for (const auto& e : spec.entries()) {
        const nlohmann::json& x = d[e.key];
        std::string allowed = x.contains("range") ? x["range"].get<std::string>() : "";
        if (x.contains("choices")) {
            for (const auto& c : x["choices"]) allowed += (allowed.empty() ? "" : " | ") + c.get<std::string>();
        }
        std::cout << fmt::format("{:<24} {:<28} default {}{}{}\n    {}\n", e.key, x["option"].get<std::string>(), x["default"].dump(),
                                 e.unit.empty() ? "" : " " + e.unit, allowed.empty() ? "" : "; " + allowed, e.help);
    }
}

} // namespace

void add_subcommand_settings(CLI::App& app)
{
    auto mode = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    auto* sub = app.add_subcommand("settings", "A registration mode's settings: keys of a settings file (--settings F) and of Python's dicts, "
                                               "command-line options, defaults, units, ranges and help");
    sub->add_option("mode", *mode, "register-images, register-surface, register-compression, estimate, enrich-build or enrich-apply")->required();
    sub->add_flag("--json", *json, "Print the specification as JSON (physreg.settings_spec(MODE) in Python)");
    sub->callback([mode, json] {
        const auto show = [&](const auto& spec) {
            if (*json) std::cout << spec.describe().dump(2) << "\n";
            else print_table(spec);
        };
        if (*mode == "register-images") show(image_registration_spec());
        else if (*mode == "register-surface") show(partial_surface_spec());
        else if (*mode == "register-compression") show(compression_spec());
        else if (*mode == "estimate") show(estimation_spec());
        else if (*mode == "enrich-build") show(enrichment_build_spec());
        else if (*mode == "enrich-apply") show(enrichment_apply_spec());
        else
            fail("settings: mode '{}' has no settings specification (register-images, register-surface, register-compression, estimate, "
                 "enrich-build, enrich-apply)", *mode);
    });
}

} // namespace physreg::cli
