#pragma once
// Triangulated surfaces: the outer boundary and tissue interfaces of a volume mesh, or a surface
// read from STL/PLY/OBJ. Each triangle carries the label of the tissue on each side.
#include "physreg/core/types.hpp"

#include <array>
#include <vector>

namespace physreg {

struct SurfaceMesh {
    std::vector<Vec3> vertices;                        ///< mm, LPS
    std::vector<std::array<std::int32_t, 3>> triangles; ///< counter-clockwise seen from outside
    /// Per triangle: {label inside, label outside}; outside 0 = exterior. Empty if unlabelled.
    std::vector<std::array<std::int32_t, 2>> labels;

    void validate(const std::string& what) const;
};

} // namespace physreg
