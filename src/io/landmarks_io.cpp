// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/landmarks_io.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"

#include <cerrno>
#include <cstring>
#include <algorithm>
#include <charconv>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>

namespace physreg {
namespace fs = std::filesystem;

std::string to_string(LandmarkType type)
{
    switch (type) {
    case LandmarkType::surface: return "surface";
    case LandmarkType::tumour: return "tumour";
    case LandmarkType::vessel: return "vessel";
    default: return "";
    }
}

std::optional<LandmarkType> parse_landmark_type(const std::string& text)
{
    if (text.empty()) return LandmarkType::unspecified;
    if (text == "surface") return LandmarkType::surface;
    if (text == "tumour" || text == "tumor") return LandmarkType::tumour;
    if (text == "vessel") return LandmarkType::vessel;
    return std::nullopt;
}

namespace {

std::string trim(std::string s)
{
    const auto b = s.find_first_not_of(" \t\r\n");
    const auto e = s.find_last_not_of(" \t\r\n");
    return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

std::string lower(std::string s)
{
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
    return s;
}

std::vector<std::string> split_csv(const std::string& line)
{
    std::vector<std::string> fields;
    std::string field;
    bool quoted = false;
    for (char c : line) {
        if (c == '"') quoted = !quoted;
        else if (c == ',' && !quoted) {
            fields.push_back(trim(field));
            field.clear();
        } else field += c;
    }
    fields.push_back(trim(field));
    return fields;
}

double parse_number(const std::string& text, const std::string& where)
{
    double v = 0;
    const auto [p, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (ec != std::errc() || p != text.data() + text.size() || !std::isfinite(v))
        fail("{}: '{}' is not a finite number", where, text);
    return v;
}

// "# Key = value" comment lines of CSV/fcsv headers: the lower-case key and the value, or nothing.
std::optional<std::pair<std::string, std::string>> header_setting(const std::string& line)
{
    const auto eq = line.find('=');
    if (line.empty() || line[0] != '#' || eq == std::string::npos) return std::nullopt;
    return std::pair{lower(trim(line.substr(1, eq - 1))), trim(line.substr(eq + 1))};
}

// CoordinateSystem values: RAS or 0 → true, LPS or 1 → false.
bool is_ras(const std::string& value, const std::string& what)
{
    if (value == "RAS" || value == "0") return true;
    if (value == "LPS" || value == "1") return false;
    fail("{}: unknown coordinate system '{}'", what, value);
}

Vec3 to_lps(const Vec3& p, bool ras) { return ras ? Vec3(-p[0], -p[1], p[2]) : p; }

std::string csv_quote(const std::string& s)
{
    return s.find_first_of(",\"") == std::string::npos ? s : "\"" + s + "\"";
}

LandmarkSet read_csv(std::istream& in, const std::string& what)
{
    LandmarkSet out;
    bool ras = false;
    std::vector<std::string> header;
    std::string line;
    std::size_t line_number = 0;
    int col_name = -1, col_x = -1, col_y = -1, col_z = -1, col_type = -1;
    while (std::getline(in, line)) {
        ++line_number;
        line = trim(line);
        if (line.empty()) continue;
        if (line[0] == '#') {
            const auto setting = header_setting(line);
            if (!setting) continue;
            const auto& [key, value] = *setting;
            if (key == "coordinate_system" || key == "coordinatesystem") {
                ras = is_ras(value, what);
            } else if (key == "units" && lower(value) != "mm") {
                fail("{}: units '{}' are not supported (landmarks are in mm)", what, value);
            }
            continue;
        }
        const auto fields = split_csv(line);
        if (header.empty()) {
            // Headerless rows of three numbers (x,y,z, as many tools write them): the points are
            // named 1…N in file order.
            const bool numbers_only = fields.size() == 3 && std::all_of(fields.begin(), fields.end(), [](const std::string& f) {
                                          return physreg::parse_number(trim(f)).has_value();
                                      });
            if (numbers_only) {
                header = {"x", "y", "z"};
                col_x = 0, col_y = 1, col_z = 2;
            }
        }
        if (header.empty()) {
            header = fields;
            for (std::size_t c = 0; c < fields.size(); ++c) {
                const std::string h = lower(fields[c]);
                if (h == "name" || h == "label" || h == "id") col_name = static_cast<int>(c);
                else if (h == "x" || h == "x_mm" || h == "x_mm_lps" || h == "l") col_x = static_cast<int>(c);
                else if (h == "y" || h == "y_mm" || h == "y_mm_lps" || h == "p") col_y = static_cast<int>(c);
                else if (h == "z" || h == "z_mm" || h == "z_mm_lps" || h == "s") col_z = static_cast<int>(c);
                else if (h == "type") col_type = static_cast<int>(c);
                else if (h == "r" || h == "a" || h.ends_with("_ras")) fail("{}: column '{}' suggests RAS; add '# coordinate_system = RAS' and name the columns x,y,z", what, fields[c]);
                else if (h.ends_with("_m") || h.ends_with("_cm")) fail("{}: column '{}' is not in mm", what, fields[c]);
            }
            if (col_name < 0 || col_x < 0 || col_y < 0 || col_z < 0)
                fail("{}: header must name the columns name|id|label,x,y,z[,type], or the file holds rows of three numbers x,y,z "
                     "(found '{}')", what, line);
            continue;
        }
        const std::string where = fmt::format("{}: line {}", what, line_number);
        if (fields.size() != header.size()) fail("{}: {} fields, the header has {}", where, fields.size(), header.size());
        Landmark l;
        l.name = col_name >= 0 ? fields[col_name] : std::to_string(out.size() + 1);
        l.position = to_lps(Vec3(parse_number(fields[col_x], where), parse_number(fields[col_y], where),
                                 parse_number(fields[col_z], where)), ras);
        if (col_type >= 0) {
            const auto type = parse_landmark_type(lower(fields[col_type]));
            if (!type) fail("{}: landmark type '{}' is not surface, tumour or vessel", where, fields[col_type]);
            l.type = *type;
        }
        out.push_back(l);
    }
    if (header.empty()) fail("{}: empty file (no header)", what);
    return out;
}

LandmarkSet read_fcsv(std::istream& in, const std::string& what)
{
    LandmarkSet out;
    bool ras = true; // Slicer before 4.11 wrote RAS without saying so
    std::vector<std::string> columns = {"id", "x", "y", "z", "ow", "ox", "oy", "oz", "vis", "sel", "lock", "label", "desc", "associatedNodeID"};
    std::string line;
    std::size_t line_number = 0;
    bool saw_version = false;
    while (std::getline(in, line)) {
        ++line_number;
        line = trim(line);
        if (line.empty()) continue;
        if (line[0] == '#') {
            const auto setting = header_setting(line);
            if (!setting) continue;
            const auto& [key, value] = *setting;
            if (key.find("markups fiducial file version") != std::string::npos) saw_version = true;
            if (key == "coordinatesystem") ras = is_ras(value, what);
            if (key == "columns") {
                columns.clear();
                for (const auto& c : split_csv(value)) columns.push_back(c);
            }
            continue;
        }
        if (!saw_version) fail("{}: not a Slicer markups fiducial file (no '# Markups fiducial file version' line)", what);
        const std::string where = fmt::format("{}: line {}", what, line_number);
        const auto fields = split_csv(line);
        auto col = [&](const char* name) {
            const auto it = std::find(columns.begin(), columns.end(), name);
            if (it == columns.end()) fail("{}: no '{}' column", what, name);
            const auto c = static_cast<std::size_t>(it - columns.begin());
            if (c >= fields.size()) fail("{}: missing field '{}'", where, name);
            return fields[c];
        };
        Landmark l;
        l.name = col("label");
        l.position = to_lps(Vec3(parse_number(col("x"), where), parse_number(col("y"), where), parse_number(col("z"), where)), ras);
        const auto type = parse_landmark_type(lower(col("desc")));
        l.type = type ? *type : LandmarkType::unspecified;
        out.push_back(l);
    }
    if (!saw_version) fail("{}: empty or not a Slicer .fcsv file", what);
    return out;
}

LandmarkSet read_mrk_json(std::istream& in, const std::string& what)
{
    nlohmann::json doc;
    try {
        doc = nlohmann::json::parse(in);
    } catch (const nlohmann::json::exception& e) {
        fail("{}: not valid JSON: {}", what, e.what());
    }
    if (!doc.contains("markups") || !doc["markups"].is_array() || doc["markups"].empty())
        fail("{}: no 'markups' list (not a Slicer .mrk.json file)", what);
    LandmarkSet out;
    try {
        for (const auto& markup : doc["markups"]) {
            const std::string system = markup.value("coordinateSystem", "LPS");
            if (system != "LPS" && system != "RAS") fail("{}: unknown coordinateSystem '{}'", what, system);
            const std::string units = markup.value("coordinateUnits", "mm");
            if (units != "mm") fail("{}: coordinateUnits '{}' are not supported (mm only)", what, units);
            for (const auto& point : markup.value("controlPoints", nlohmann::json::array())) {
                Landmark l;
                l.name = point.value("label", "");
                const auto& p = point.at("position");
                if (!p.is_array() || p.size() != 3) fail("{}: control point '{}' has no 3-D position", what, l.name);
                Vec3 v(p[0].get<double>(), p[1].get<double>(), p[2].get<double>());
                if (!v.allFinite()) fail("{}: control point '{}' is not finite", what, l.name);
                l.position = to_lps(v, system == "RAS");
                const auto type = parse_landmark_type(lower(point.value("description", "")));
                l.type = type ? *type : LandmarkType::unspecified;
                out.push_back(l);
            }
        }
    } catch (const nlohmann::json::exception& e) {
        fail("{}: unexpected content: {}", what, e.what());
    }
    return out;
}

} // namespace

LandmarkSet read_landmarks(const fs::path& path)
{
    const std::string what = "landmarks '" + path.string() + "'";
    require_existing_file(path, what);
    std::ifstream in(path);
    if (!in) fail("{}: cannot open file", what);
    const std::string ext = full_extension(path);
    LandmarkSet set;
    if (ext == ".csv") set = read_csv(in, what);
    else if (ext == ".fcsv") set = read_fcsv(in, what);
    else if (ext == ".mrk.json" || ext == ".json") set = read_mrk_json(in, what);
    else fail("{}: unknown extension '{}' (use .csv, .fcsv or .mrk.json)", what, ext);
    std::set<std::string> names;
    for (const auto& l : set) {
        if (l.name.empty()) fail("{}: a landmark has no name", what);
        if (!names.insert(l.name).second) fail("{}: landmark name '{}' appears twice", what, l.name);
    }
    return set;
}

void write_landmarks(const fs::path& path, const LandmarkSet& landmarks)
{
    const std::string ext = full_extension(path);
    for (const auto& l : landmarks)
        if (!l.position.allFinite()) fail("landmarks for '{}': '{}' is not finite", path.string(), l.name);
    write_atomically(path, [&](const fs::path& tmp) {
        std::ofstream out(tmp);
        out.precision(17);
        if (ext == ".csv") {
            out << "# coordinate_system = LPS\n# units = mm\nname,x,y,z,type\n";
            for (const auto& l : landmarks)
                out << csv_quote(l.name) << ',' << l.position[0] << ',' << l.position[1] << ',' << l.position[2] << ','
                    << to_string(l.type) << "\n";
        } else if (ext == ".fcsv") {
            out << "# Markups fiducial file version = 4.11\n# CoordinateSystem = LPS\n"
                   "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n";
            for (std::size_t i = 0; i < landmarks.size(); ++i) {
                const auto& l = landmarks[i];
                out << "vtkMRMLMarkupsFiducialNode_" << i << ',' << l.position[0] << ',' << l.position[1] << ','
                    << l.position[2] << ",0,0,0,1,1,1,0," << csv_quote(l.name) << ',' << to_string(l.type) << ",\n";
            }
        } else if (ext == ".mrk.json" || ext == ".json") {
            nlohmann::json points = nlohmann::json::array();
            for (std::size_t i = 0; i < landmarks.size(); ++i) {
                const auto& l = landmarks[i];
                points.push_back({{"id", std::to_string(i + 1)},
                                  {"label", l.name},
                                  {"description", to_string(l.type)},
                                  {"position", {l.position[0], l.position[1], l.position[2]}},
                                  {"orientation", {-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0}},
                                  {"selected", true},
                                  {"locked", false},
                                  {"visibility", true},
                                  {"positionStatus", "defined"}});
            }
            nlohmann::json doc = {
                {"@schema", "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#"},
                {"markups", {{{"type", "Fiducial"}, {"coordinateSystem", "LPS"}, {"coordinateUnits", "mm"}, {"controlPoints", points}}}}};
            out << doc.dump(2) << "\n";
        } else {
            fail("landmarks '{}': unknown extension '{}' (use .csv, .fcsv or .mrk.json)", path.string(), ext);
        }
        out.close();
        if (!out) fail("landmarks '{}': write failed: {}", path.string(), std::strerror(errno));
    });
}

} // namespace physreg
