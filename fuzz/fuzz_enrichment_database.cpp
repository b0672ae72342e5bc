// SPDX-License-Identifier: GPL-3.0-or-later
// The enrichment database reader (physreg's own binary format with per-block checksums). An
// accepted database must pass EnrichmentDatabase::validate.
#include "fuzz_support.hpp"
#include "physreg/registration/compression/enrichment.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    const auto path = physreg::fuzz::write_input(data, size, ".phe");
    physreg::fuzz::expect_success_or_error([&] {
        const physreg::EnrichmentDatabase database = physreg::read_enrichment_database(path);
        database.validate("fuzzed database");
    });
    return 0;
}
