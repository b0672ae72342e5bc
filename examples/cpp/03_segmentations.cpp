// SPDX-License-Identifier: GPL-3.0-or-later
// Register one segmentation to another with the C++ library, from the label maps alone (paper 002's
// mode): the same pipeline as `physreg register-images --fixed-labels F --moving-labels M
// --baselines labels` and Python's physreg.register_image_pair.
//
//   example_03_segmentations                          a pair made here, checked (ctest runs this)
//   example_03_segmentations FIXED MOVING [FIELD]        your two label files; FIELD: where to write the
//                                                      fixed → moving displacement field (.nii.gz)
//
// Outside this build tree: find_package(physreg CONFIG REQUIRED) and link physreg::physreg.
#include "physreg/core/error.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/registration/images/image_registration.hpp"

#include <cmath>
#include <cstdio>
#include <string>

namespace {

using physreg::LabelVolume;

/// An ellipsoid gland (label 1, semi-axes 24, 16, 12 mm) with a lesion (label 2, radius 6 mm) on
/// 1.5 mm voxels, pressed along y by `squash` (its volume kept) and shifted by `shift` mm.
LabelVolume gland(double squash, const physreg::Vec3& shift)
{
    LabelVolume v;
    v.geometry.size = {60, 48, 40};
    v.geometry.spacing = physreg::Vec3::Constant(1.5);
    v.labels.resize(static_cast<std::size_t>(v.geometry.voxel_count()));
    const physreg::Vec3 centre = physreg::Vec3(45, 36, 30) + shift;
    const double widen = 1.0 / std::sqrt(squash);
    for (int k = 0; k < 40; ++k)
        for (int j = 0; j < 48; ++j)
            for (int i = 0; i < 60; ++i) {
                const physreg::Vec3 x = v.geometry.index_to_physical(physreg::Vec3(i, j, k)) - centre;
                const physreg::Vec3 p(x[0] / widen, x[1] / squash, x[2]);
                std::uint16_t label = std::pow(p[0] / 24, 2) + std::pow(p[1] / 16, 2) + std::pow(p[2] / 12, 2) < 1 ? 1 : 0;
                if ((p - physreg::Vec3(8, 4, 2)).norm() < 6.0) label = 2;
                v.labels[static_cast<std::size_t>(v.geometry.linear_index(i, j, k))] = label;
            }
    return v;
}

physreg::ScalarImage as_image(const LabelVolume& l) { return {l.geometry, std::vector<float>(l.labels.begin(), l.labels.end())}; }

} // namespace

int main(int argc, char** argv)
{
    try {
        physreg::ImagePair pair;
        const bool own_files = argc >= 3;
        const physreg::Vec3 shift(6, -4, 3);
        if (own_files) {
            pair.fixed_labels = physreg::read_label_volume(argv[1]);
            pair.moving_labels = physreg::read_label_volume(argv[2]);
        } else {
            pair.fixed_labels = gland(0.85, shift);
            pair.moving_labels = gland(1.0, physreg::Vec3::Zero());
            // The lesion's centre, as a user would pick it in both images (mm, LPS).
            const physreg::Vec3 rest(45 + 8, 36 + 4, 30 + 2);
            const physreg::Vec3 pressed = physreg::Vec3(45, 36, 30) + shift + physreg::Vec3(8 / std::sqrt(0.85), 4 * 0.85, 2);
            pair.landmarks_moving = physreg::LandmarkSet{{"lesion", rest, physreg::LandmarkType::tumour}};
            pair.landmarks_fixed = physreg::LandmarkSet{{"lesion", pressed, physreg::LandmarkType::tumour}};
        }
        // No intensity images: the label maps stand in, and only the label baselines run.
        pair.intensities = false;
        pair.fixed = as_image(pair.fixed_labels);
        pair.moving = as_image(pair.moving_labels);

        physreg::ImageRegistrationSettings settings;
        settings.baselines = "labels";
        settings.cell_size = 4.0; // mm: a 48 mm gland
        const physreg::ImageRegistrationResult r = physreg::register_images(pair, settings);

        std::printf("initial alignment: %s\n", r.alignment_decision.c_str());
        for (const auto& m : r.methods) {
            const auto& e = r.summary["methods"][m.name];
            std::printf("%-18s Dice", m.name.c_str());
            for (const auto& [label, dice] : e["dice"].items()) std::printf(" %s: %.3f", label.c_str(), dice.get<double>());
            if (e.contains("tre")) std::printf("   lesion error %.2f mm", e["tre"]["all"]["mean_mm"].get<double>());
            std::printf("\n");
        }
        std::printf("%s\n", r.summary["biomechanical_against_baselines"]["reading"].get<std::string>().c_str());
        if (argc >= 4) physreg::write_displacement_field(argv[3], r.chosen_method().field);
        if (!own_files) {
            // What the example promises: the lesion lands within 2 mm, the gland overlaps well.
            const auto& bio = r.summary["methods"]["biomechanical"];
            if (!(bio["tre"]["all"]["mean_mm"].get<double>() < 2.0) || !(bio["dice"]["1"].get<double>() > 0.9)) {
                std::fprintf(stderr, "example: the registration missed what it promises\n");
                return 1;
            }
        }
        return 0;
    } catch (const physreg::Error& e) {
        std::fprintf(stderr, "example: %s\n", e.what());
        return 1;
    }
}
