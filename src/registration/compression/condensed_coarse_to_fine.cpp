// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/compression/condensed_coarse_to_fine.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <chrono>

namespace physreg {
namespace {

// The coarse nodes the synthesis of `fine_query` reads: the corners of the coarse cells holding them.
std::vector<std::int32_t> coarse_corners(const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                                         const std::vector<std::int32_t>& fine_query)
{
    std::vector<std::int32_t> out;
    for (const auto j : fine_query) {
        if (j < 0 || static_cast<std::size_t>(j) >= fine_nodes.size())
            fail("condensed coarse-to-fine: fine node {} out of range (0 … {})", j, fine_nodes.size() - 1);
        const auto ids = coarse.mesh.cell(static_cast<std::size_t>(fine_nodes[static_cast<std::size_t>(j)].cell));
        for (int a = 0; a < 8; ++a) out.push_back(ids[a]);
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

} // namespace

CondensedCoarseToFine::CondensedCoarseToFine(const LiverModel& fine, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                                             const EnrichmentDatabase& db, const std::vector<Indenter>& session_tools,
                                             std::vector<std::int32_t> fine_query, EnrichmentMatching how, const EnrichmentBlend& blend,
                                             const CondensedContactOptions& options)
    : m_fine(fine), m_coarse_model(coarse), m_fine_nodes(fine_nodes), m_db(db), m_fine_query(std::move(fine_query)), m_how(how), m_blend(blend),
      m_coarse(coarse, session_tools, coarse_corners(coarse, fine_nodes, m_fine_query), options),
      m_fine_u(3 * fine.mesh.node_count(), 0.0)
{
    blend.validate("condensed coarse-to-fine");
    if (fine_nodes.size() != fine.mesh.node_count())
        fail("condensed coarse-to-fine: {} embedded fine nodes for a fine mesh of {}", fine_nodes.size(), fine.mesh.node_count());
}

CondensedCoarseToFine::Update CondensedCoarseToFine::move_to(const Indenter& tool, const Vec3& position_mm, const EnrichmentCondition& condition)
{
    Update up;
    up.contact = m_coarse.move_to(tool, position_mm);
    // Step 2: the coarse field the synthesis reads (the whole field for field matching).
    const auto t1 = std::chrono::steady_clock::now();
    const std::vector<double> coarse_u = m_how == EnrichmentMatching::field ? m_coarse.full_displacement_mm() : m_coarse.query_field_mm();
    const auto t2 = std::chrono::steady_clock::now();
    up.contact.recovery_ms += 1e3 * std::chrono::duration<double>(t2 - t1).count();
    // Step 3.
    up.match = match_enrichment(m_db, m_how, m_blend, &condition, coarse_u);
    synthesize_fine_subset(m_coarse_model.mesh, coarse_u, m_fine_nodes, m_fine.mesh.nodes, m_db, up.match, m_fine_query, m_fine_u);
    up.synthesis_ms = 1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t2).count();
    return up;
}

void CondensedCoarseToFine::reset()
{
    m_coarse.reset();
    std::fill(m_fine_u.begin(), m_fine_u.end(), 0.0);
}

} // namespace physreg
