// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A mode's settings on the command line: one option per entry of its SettingsSpec (help, default
// and range from the specification), plus --settings FILE (JSON/YAML). The values resolve as
// defaults ← file ← options given on the command line.
#include "physreg/core/settings_spec.hpp"
#include "physreg/io/settings_file.hpp"

#include <CLI/CLI.hpp>

#include <map>
#include <memory>
#include <string>

namespace physreg::cli {

template <typename Settings>
class SettingsOptions {
public:
    SettingsOptions(CLI::App* command, const SettingsSpec<Settings>& spec) : m_spec(spec)
    {
        const Settings defaults{};
        for (const auto& e : spec.entries()) {
            const nlohmann::json d = e.get(defaults);
            Value& v = m_values[e.key];
            const std::string& help = e.help;
            switch (e.kind) {
            case SettingKind::real:
                v.real = d.get<double>();
                v.option = command->add_option(e.option, v.real, help)->capture_default_str();
                break;
            case SettingKind::integer:
                v.integer = d.get<long long>();
                v.option = command->add_option(e.option, v.integer, help)->capture_default_str();
                break;
            case SettingKind::flag:
                v.flag = d.get<bool>();
                v.option = command->add_flag(e.option, v.flag, help);
                break;
            case SettingKind::choice:
            case SettingKind::text:
                v.text = d.get<std::string>();
                v.option = command->add_option(e.option, v.text, help)->capture_default_str();
                break;
            case SettingKind::labels:
                v.option = command->add_option(e.option, v.text, help);
                break;
            }
        }
        command->add_option("--settings", m_file, "a settings file (JSON or YAML: key: value, the keys of `physreg settings " + spec.mode() +
                                                      "`); options given on the command line win");
    }

    /// Defaults, then the settings file, then every option the command line gave; not validated.
    Settings resolve() const
    {
        Settings s{};
        if (!m_file.empty()) m_spec.apply(s, read_settings_file(m_file), m_file);
        for (const auto& e : m_spec.entries()) {
            const Value& v = m_values.at(e.key);
            if (v.option->count() == 0) continue;
            const std::string what = SettingsSpec<Settings>::primary_option(e);
            switch (e.kind) {
            case SettingKind::real: e.set(s, v.real, what); break;
            case SettingKind::integer: e.set(s, v.integer, what); break;
            case SettingKind::flag: e.set(s, v.flag, what); break;
            case SettingKind::choice:
            case SettingKind::text:
            case SettingKind::labels: e.set(s, v.text, what); break;
            }
        }
        return s;
    }
    const std::string& file() const { return m_file; }

private:
    struct Value {
        double real = 0.0;
        long long integer = 0;
        bool flag = false;
        std::string text;
        CLI::Option* option = nullptr;
    };
    const SettingsSpec<Settings>& m_spec;
    std::map<std::string, Value> m_values;
    std::string m_file;
};

} // namespace physreg::cli
