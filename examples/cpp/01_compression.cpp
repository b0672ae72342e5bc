// SPDX-License-Identifier: GPL-3.0-or-later
// Predict a tool compression with the C++ library (paper 000's mode): the same pipeline as
// `physreg register-compression --dataset DIR --state A` and Python's physreg.predict_compression.
//
//   example_01_compression DATASET [STATE]   a phantom dataset (`physreg phantom --preset small -o DIR`);
//                                            ctest runs it on the test suite's small phantom
//
// Outside this build tree: find_package(physreg CONFIG REQUIRED) and link physreg::physreg.
#include "physreg/core/error.hpp"
#include "physreg/io/dataset.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/compression/estimation.hpp"

#include <cstdio>
#include <string>

int main(int argc, char** argv)
{
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s DATASET [STATE]\n", argv[0]);
        return 2;
    }
    try {
        const std::string state = argc > 2 ? argv[2] : "A";
        physreg::CompressionRegistrationSettings settings; // the command's defaults
        settings.grid = "16x12x8";                          // cells: a coarse model of the small phantom
        // The body at rest and the model built on it: once per patient.
        const physreg::CompressionSubject subject = physreg::read_dataset_compression_subject(argv[1], settings);
        // One compression: the tool's path, and the truth to score it by.
        const physreg::PhantomDataset dataset = physreg::read_phantom_dataset(argv[1]);
        const physreg::CompressionCase observed = physreg::compression_cases(dataset, {state}).front();
        const physreg::CompressionRegistrationResult r = physreg::register_compression(subject, observed, settings);

        std::printf("compression %s: tool in contact: %s\n", state.c_str(), r.contact ? "yes" : "no");
        std::printf("targets: %.2f mm mean error (at rest %.2f mm) over %zu landmarks\n", r.tre->all.mean_mm, r.at_rest->all.mean_mm, r.tre->all.count);
        std::printf("dense field: %lld x %lld x %lld voxels of %.1f mm\n", static_cast<long long>(r.field.field.geometry.size[0]),
                    static_cast<long long>(r.field.field.geometry.size[1]), static_cast<long long>(r.field.field.geometry.size[2]), r.field.field.geometry.spacing[0]);
        // What the example promises: a prediction scored on every landmark, no worse than doing nothing.
        if (!r.tre || r.tre->all.count == 0 || r.tre->all.mean_mm > r.at_rest->all.mean_mm + 0.05) {
            std::fprintf(stderr, "example: the prediction is worse than leaving the body at rest\n");
            return 1;
        }
        return 0;
    } catch (const physreg::Error& e) {
        std::fprintf(stderr, "example: %s\n", e.what());
        return 1;
    }
}
