// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 000's coarse-to-fine on top of condensed contact (issue 30 item 3). The coarse model is
// condensed (linearised at rest, factorised once, the compliance of its candidate skin nodes
// kept, see condensed_contact.hpp). Each tool update then
//   1. solves the contact on the coarse candidates (an LCP);
//   2. recovers the coarse displacement where the synthesis needs it: the corners of the coarse
//      cells that hold the fine nodes asked for (with field matching, the whole coarse field: one
//      back-substitution);
//   3. matches the enrichment database and synthesises those fine nodes (eq. 10).
// Each stage is timed. Only the fine nodes asked for (e.g. around the landmarks, or the displayed
// surface) are synthesised: the work per update does not grow with the fine mesh.
#include "physreg/registration/compression/condensed_contact.hpp"
#include "physreg/registration/compression/enrichment.hpp"

#include <cstdint>
#include <vector>

namespace physreg {

class CondensedCoarseToFine {
public:
    /// `coarse` and `fine_nodes` as coarsen_liver_model made them for `fine`; `db` built for both
    /// (the caller checks with check_database_fits); `fine_query`: the fine nodes each update
    /// returns. Throws Error for a fine node out of range or a bad blend, and as
    /// CondensedContactModel does.
    CondensedCoarseToFine(const LiverModel& fine, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                          const EnrichmentDatabase& db, const std::vector<Indenter>& session_tools, std::vector<std::int32_t> fine_query,
                          EnrichmentMatching how, const EnrichmentBlend& blend, const CondensedContactOptions& options = {});

    struct Update {
        CondensedContactModel::Update contact; ///< its contact_ms (step 1) and recovery_ms (step 2)
        double synthesis_ms = 0.0;             ///< step 3: matching and synthesis
        EnrichmentMatch match;
        double total_ms() const { return contact.contact_ms + contact.recovery_ms + synthesis_ms; }
    };
    /// The tool at `position_mm`; `condition`: where it first touched, its direction and depth (the
    /// database's matching by parameters reads them).
    Update move_to(const Indenter& tool, const Vec3& position_mm, const EnrichmentCondition& condition);
    void reset();
    /// 3 per fine node, mm: the fine query nodes filled after the last update, zero elsewhere.
    const std::vector<double>& fine_field_mm() const { return m_fine_u; }
    const CondensedContactModel& coarse_model() const { return m_coarse; }

private:
    const LiverModel& m_fine;
    const LiverModel& m_coarse_model;
    const std::vector<NodeEmbedding>& m_fine_nodes;
    const EnrichmentDatabase& m_db;
    std::vector<std::int32_t> m_fine_query;
    EnrichmentMatching m_how;
    EnrichmentBlend m_blend;
    CondensedContactModel m_coarse;
    std::vector<double> m_fine_u;
};

} // namespace physreg
