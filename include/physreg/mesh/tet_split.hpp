// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
#include "physreg/mesh/volume_mesh.hpp"

namespace physreg {

/// Splits every hexahedron into 6 tetrahedra around its 0–6 diagonal (Kuhn's split). Every
/// quadrilateral face is cut along the diagonal through its lowest and highest corner in the
/// hexahedron's local axes, so neighbours with the same local orientation (all meshes built on a
/// grid) get matching triangles: the result is conforming. Tetrahedron t comes from hexahedron
/// t / 6 and keeps its label; nodes are unchanged. Throws Error if a tetrahedron is not positive.
VolumeMesh split_hexahedra_into_tetrahedra(const VolumeMesh& hex_mesh);

} // namespace physreg
