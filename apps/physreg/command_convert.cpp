// SPDX-License-Identifier: GPL-3.0-or-later
// physreg convert: between the formats physreg reads and writes, by extension.
#include "cli_support.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mesh/surface_extraction.hpp"
#include "physreg/mesh/tet_split.hpp"

namespace physreg::cli {
namespace {

enum class Kind { image, mesh, surface, landmarks, unknown };

Kind kind_of(const std::string& path)
{
    const std::string ext = full_extension(path);
    if (ext == ".vtu" || ext == ".msh") return Kind::mesh;
    if (ext == ".stl" || ext == ".ply" || ext == ".obj") return Kind::surface;
    if (ext == ".csv" || ext == ".fcsv" || ext == ".mrk.json") return Kind::landmarks;
    if (ext == ".nii" || ext == ".nii.gz" || ext == ".nrrd" || ext == ".nhdr" || ext == ".mha" || ext == ".mhd" ||
        std::filesystem::is_directory(path))
        return Kind::image;
    return Kind::unknown;
}

} // namespace

void add_subcommand_convert(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string input, output;
        bool tetrahedra = false;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand(
        "convert", "Convert between formats by extension: images (.nii[.gz]/.nrrd/.mha/DICOM dir), volume meshes "
                   "(.vtu/.msh; a volume mesh to .stl/.ply/.obj writes its surfaces), surfaces, landmarks "
                   "(.csv/.fcsv/.mrk.json)");
    sub->add_option("input", o->input, "Input file")->required();
    sub->add_option("output", o->output, "Output file")->required();
    sub->add_flag("--tetrahedra", o->tetrahedra, "Mesh to mesh: split hexahedra into conforming tetrahedra");
    sub->callback([o] {
        check_output_path(o->output, "output");
        check_distinct_paths({{"OUTPUT", o->output}}, {{"INPUT", o->input}});
        const Kind in = kind_of(o->input), out = kind_of(o->output);
        if (in == Kind::unknown) fail("convert: input '{}' has an unknown extension", o->input);
        if (out == Kind::unknown) fail("convert: output '{}' has an unknown extension", o->output);
        if (in == Kind::mesh && out == Kind::mesh) {
            MeshData data;
            VolumeMesh mesh = read_volume_mesh(o->input, &data);
            if (o->tetrahedra) {
                mesh = split_hexahedra_into_tetrahedra(mesh);
                data = {};
            }
            write_volume_mesh(o->output, mesh, data);
        } else if (in == Kind::mesh && out == Kind::surface) {
            write_surface(o->output, extract_surfaces(read_volume_mesh(o->input)));
        } else if (in == Kind::surface && out == Kind::surface) {
            write_surface(o->output, read_surface(o->input));
        } else if (in == Kind::landmarks && out == Kind::landmarks) {
            write_landmarks(o->output, read_landmarks(o->input));
        } else if (in == Kind::image && out == Kind::image) {
            const auto info = read_image_info(o->input);
            if (info.components == 3) write_displacement_field(o->output, read_displacement_field(o->input));
            else if (info.components == 1 && info.component_type.find("float") == std::string::npos &&
                     info.component_type.find("double") == std::string::npos)
                write_label_volume(o->output, read_label_volume(o->input)); // integers stay labels
            else if (info.components == 1) write_scalar_image(o->output, read_scalar_image(o->input));
            else fail("convert: image '{}' has {} components (1 or 3 supported)", o->input, info.components);
        } else {
            fail("convert: cannot convert '{}' to '{}' (different kinds of data)", o->input, o->output);
        }
        logger()->info("wrote '{}'", o->output);
    });
}

} // namespace physreg::cli
