// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Connected pieces of a mesh. Cells count as connected only through a shared face: pieces that
// touch only along an edge or at a vertex would hinge or pivot there in a finite-element model,
// so those shared nodes are split (one copy per piece), or the mesh is refused.
#include "physreg/mesh/volume_mesh.hpp"

namespace physreg {

enum class ComponentPolicy {
    keep_all,     ///< keep every piece (warn when there is more than one)
    keep_largest, ///< keep the piece with most volume, drop (and report) the others
    refuse,       ///< throw Error when there is more than one piece
};
ComponentPolicy parse_component_policy(const std::string& text); ///< "all", "largest", "refuse"

struct ComponentReport {
    struct Piece {
        std::int64_t cells = 0;
        double volume_mm3 = 0.0;
    };
    std::vector<Piece> pieces;                 ///< before the policy, largest volume first
    std::int64_t nonmanifold_nodes = 0;        ///< nodes shared by pieces touching at an edge/vertex
    std::int64_t dropped_cells = 0;
    double dropped_volume_mm3 = 0.0;
};

struct FaceConnectedPieces {
    std::vector<std::int32_t> piece_of_cell;    ///< 0 = the piece with most volume
    std::vector<ComponentReport::Piece> pieces; ///< largest volume first
};
FaceConnectedPieces face_connected_pieces(const VolumeMesh& mesh);

/// Finds the pieces, splits nodes shared by different pieces (if split_nonmanifold; otherwise such
/// nodes are an Error), then applies the policy. Nodes no longer used are removed.
ComponentReport repair_components(VolumeMesh& mesh, ComponentPolicy policy, bool split_nonmanifold,
                                  const std::string& what);

/// Keeps the cells with keep[c] true and the nodes they use (renumbered in order).
void keep_cells(VolumeMesh& mesh, const std::vector<bool>& keep);

} // namespace physreg
