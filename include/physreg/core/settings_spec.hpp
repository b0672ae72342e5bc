// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// One specification per mode's settings (issue 43): each setting's key, command-line option, kind,
// default, range and help are written once, and read by the command line (one option per entry),
// Python (a dict checked here), settings files (JSON/YAML: SettingsSpec::apply) and summary.json
// (SettingsSpec::to_json writes the values actually used). After polyfem's JSON specification with
// defaults: a key the specification lacks is an error naming the nearest key, never ignored.
#include "physreg/core/config_keys.hpp"
#include "physreg/core/error.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

namespace physreg {

enum class SettingKind { real, integer, flag, choice, labels, text };
std::string to_string(SettingKind kind);

/// How an error names a setting: as its command-line option (--cell-size) or its key (cell_size).
enum class SettingNaming { option, key };

/// "2,3,4" → labels 1 … 65535, sorted and unique; Error naming `name` otherwise.
std::vector<std::int32_t> parse_label_list(const std::string& text, const std::string& name);

template <typename Settings>
class SettingsSpec {
public:
    struct Entry {
        std::string key;     ///< JSON and Python name, e.g. cell_size
        std::string option;  ///< command line, e.g. --cell-size; a flag may add its negation: "--x,!--no-x", or be one: "!--no-x"
        SettingKind kind = SettingKind::real;
        std::string unit;    ///< "mm", "N/mm", "" for none
        std::string help;
        double lo = -std::numeric_limits<double>::infinity(), hi = std::numeric_limits<double>::infinity();
        bool lo_open = false, hi_open = false; ///< (lo, …) instead of [lo, …
        std::vector<std::string> choices;
        std::function<nlohmann::json(const Settings&)> get;
        std::function<void(Settings&, const nlohmann::json&, const std::string&)> set; ///< the last argument names the value in errors
    };

    explicit SettingsSpec(std::string mode) : m_mode(std::move(mode)) {}
    const std::string& mode() const { return m_mode; }
    const std::vector<Entry>& entries() const { return m_entries; }
    const Entry* find(std::string_view key) const
    {
        for (const auto& e : m_entries)
            if (e.key == key) return &e;
        return nullptr;
    }
    /// The name an error uses for `key`.
    std::string name(std::string_view key, SettingNaming naming) const
    {
        const Entry* e = find(key);
        if (!e) fail("{} settings: no setting '{}'", m_mode, key);
        return naming == SettingNaming::key ? e->key : primary_option(*e);
    }

    /// A real number, mm or other `unit`, in [lo, hi] (or open ends).
    SettingsSpec& real(std::string key, std::string option, double Settings::*member, std::string unit, std::string help, double lo = -inf(),
                       double hi = inf(), bool lo_open = false, bool hi_open = false)
    {
        Entry e{std::move(key), std::move(option), SettingKind::real, std::move(unit), std::move(help), lo, hi, lo_open, hi_open, {}, {}, {}};
        e.get = [member](const Settings& s) { return nlohmann::json(s.*member); };
        e.set = [member](Settings& s, const nlohmann::json& v, const std::string& what) {
            if (!v.is_number()) fail("{}: expected a number, got {}", what, v.dump());
            s.*member = v.get<double>();
        };
        m_entries.push_back(std::move(e));
        return *this;
    }
    SettingsSpec& integer(std::string key, std::string option, int Settings::*member, std::string help, double lo = -inf(), double hi = inf())
    {
        Entry e{std::move(key), std::move(option), SettingKind::integer, "", std::move(help), lo, hi, false, false, {}, {}, {}};
        e.get = [member](const Settings& s) { return nlohmann::json(s.*member); };
        e.set = [member](Settings& s, const nlohmann::json& v, const std::string& what) {
            if (!v.is_number()) fail("{}: expected a whole number, got {}", what, v.dump());
            s.*member = to_integer<int>(v.get<double>(), what, "the value");
        };
        m_entries.push_back(std::move(e));
        return *this;
    }
    SettingsSpec& flag(std::string key, std::string option, bool Settings::*member, std::string help)
    {
        Entry e{std::move(key), std::move(option), SettingKind::flag, "", std::move(help), -inf(), inf(), false, false, {}, {}, {}};
        e.get = [member](const Settings& s) { return nlohmann::json(s.*member); };
        e.set = [member](Settings& s, const nlohmann::json& v, const std::string& what) {
            if (!v.is_boolean()) fail("{}: expected true or false, got {}", what, v.dump());
            s.*member = v.get<bool>();
        };
        m_entries.push_back(std::move(e));
        return *this;
    }
    SettingsSpec& choice(std::string key, std::string option, std::string Settings::*member, std::vector<std::string> choices, std::string help)
    {
        Entry e{std::move(key), std::move(option), SettingKind::choice, "", std::move(help), -inf(), inf(), false, false, std::move(choices), {}, {}};
        e.get = [member](const Settings& s) { return nlohmann::json(s.*member); };
        e.set = [member](Settings& s, const nlohmann::json& v, const std::string& what) {
            if (!v.is_string()) fail("{}: expected a word, got {}", what, v.dump());
            s.*member = v.get<std::string>();
        };
        m_entries.push_back(std::move(e));
        return *this;
    }
    /// Free text whose form the mode's validate() checks (a grid "54x40x26", a size "8G", a list "A,B").
    SettingsSpec& text(std::string key, std::string option, std::string Settings::*member, std::string help)
    {
        Entry e{std::move(key), std::move(option), SettingKind::text, "", std::move(help), -inf(), inf(), false, false, {}, {}, {}};
        e.get = [member](const Settings& s) { return nlohmann::json(s.*member); };
        e.set = [member](Settings& s, const nlohmann::json& v, const std::string& what) {
            if (!v.is_string()) fail("{}: expected text, got {}", what, v.dump());
            s.*member = v.get<std::string>();
        };
        m_entries.push_back(std::move(e));
        return *this;
    }
    /// Labels (1 … 65535): a JSON array of whole numbers, or the command line's "2,3,4".
    SettingsSpec& labels(std::string key, std::string option, std::vector<std::int32_t> Settings::*member, std::string help)
    {
        Entry e{std::move(key), std::move(option), SettingKind::labels, "", std::move(help), 1, 65535, false, false, {}, {}, {}};
        e.get = [member](const Settings& s) { return nlohmann::json(s.*member); };
        e.set = [member](Settings& s, const nlohmann::json& v, const std::string& what) {
            if (v.is_string()) {
                s.*member = v.get<std::string>().empty() ? std::vector<std::int32_t>{} : parse_label_list(v.get<std::string>(), what);
                return;
            }
            if (!v.is_array()) fail("{}: expected a list of labels, got {}", what, v.dump());
            std::string text;
            for (const auto& item : v) {
                if (!item.is_number()) fail("{}: '{}' is not a label (1 … 65535)", what, item.dump());
                if (!text.empty()) text += ',';
                text += item.dump();
            }
            s.*member = text.empty() ? std::vector<std::int32_t>{} : parse_label_list(text, what);
        };
        m_entries.push_back(std::move(e));
        return *this;
    }

    /// Every setting's value, by key (what summary.json writes).
    nlohmann::json to_json(const Settings& settings) const
    {
        nlohmann::json out = nlohmann::json::object();
        for (const auto& e : m_entries) out[e.key] = e.get(settings);
        return out;
    }
    /// Overrides `settings` by the entries of `values` (a JSON object by key). Throws Error naming
    /// `what` (a file, "settings") and the key for an unknown key (with the nearest one) or a value
    /// of the wrong type; ranges are checked by validate().
    void apply(Settings& settings, const nlohmann::json& values, const std::string& what) const
    {
        if (!values.is_object()) fail("{}: expected an object of {} settings (key: value), got {}", what, m_mode, values.type_name());
        std::vector<std::string> keys;
        for (const auto& [key, value] : values.items()) keys.push_back(key);
        std::vector<std::string_view> accepted;
        for (const auto& e : m_entries) accepted.push_back(e.key);
        require_known_keys(keys, accepted, what, m_mode + " settings");
        for (const auto& [key, value] : values.items()) find(key)->set(settings, value, fmt::format("{}: {}", what, key));
    }
    /// Ranges and choices of every entry; Error naming the setting as `naming` says, its value and
    /// what is accepted.
    void validate(const Settings& settings, SettingNaming naming) const
    {
        for (const auto& e : m_entries) {
            const nlohmann::json v = e.get(settings);
            const std::string n = naming == SettingNaming::key ? e.key : primary_option(e);
            if (e.kind == SettingKind::real || e.kind == SettingKind::integer) {
                const double x = v.get<double>();
                const bool below = e.lo_open ? !(x > e.lo) : !(x >= e.lo);
                const bool above = e.hi_open ? !(x < e.hi) : !(x <= e.hi);
                if (!std::isfinite(x) || below || above)
                    fail("{} {}{} must be {}", n, format_number(x), e.unit.empty() ? "" : " " + e.unit, range_text(e));
            } else if (e.kind == SettingKind::choice) {
                const std::string s = v.get<std::string>();
                bool known = false;
                for (const auto& c : e.choices) known = known || c == s;
                if (!known) fail("{} '{}': use {}", n, s, join(e.choices, ", ", " or "));
            }
        }
    }
    /// The specification itself (physreg settings MODE --json; Python physreg.settings_spec):
    /// per key, its option, kind, default (from Settings{}), unit, range or choices, and help.
    nlohmann::json describe() const
    {
        const Settings defaults{};
        nlohmann::json out = nlohmann::json::object();
        for (const auto& e : m_entries) {
            nlohmann::json d = {{"option", primary_option(e)}, {"kind", to_string(e.kind)}, {"default", e.get(defaults)}, {"help", e.help}};
            if (!e.unit.empty()) d["unit"] = e.unit;
            if (e.kind == SettingKind::real || e.kind == SettingKind::integer) d["range"] = range_text(e);
            if (e.kind == SettingKind::choice) d["choices"] = e.choices;
            out[e.key] = d;
        }
        return out;
    }
    /// The option's first positive spelling ("--rest-offsets" of "--rest-offsets,!--no-rest-offsets";
    /// "--no-moduli" of "!--no-moduli").
    static std::string primary_option(const Entry& e)
    {
        std::string first = e.option.substr(0, e.option.find(','));
        return first.rfind('!', 0) == 0 ? first.substr(1) : first;
    }

private:
    static constexpr double inf() { return std::numeric_limits<double>::infinity(); }
    static std::string format_number(double x) { return fmt::format("{}", x); }
    static std::string join(const std::vector<std::string>& items, const char* separator, const char* last)
    {
        std::string out;
        for (std::size_t i = 0; i < items.size(); ++i) out += (i == 0 ? "" : i + 1 == items.size() ? last : separator) + items[i];
        return out;
    }
    static std::string range_text(const Entry& e)
    {
        const bool low = std::isfinite(e.lo), high = std::isfinite(e.hi);
        if (low && high) return fmt::format("in {}{}, {}{}", e.lo_open ? "(" : "[", e.lo, e.hi, e.hi_open ? ")" : "]");
        if (low) return fmt::format("{} {}", e.lo_open ? ">" : "≥", e.lo);
        if (high) return fmt::format("{} {}", e.hi_open ? "<" : "≤", e.hi);
        return "a finite number";
    }
    std::string m_mode;
    std::vector<Entry> m_entries;
};

} // namespace physreg
