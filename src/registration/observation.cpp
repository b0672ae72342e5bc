// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/observation.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/mesh/triangle_search.hpp"
#include "physreg/registration/compression/compression_registration.hpp"

#include <chrono>

namespace physreg {

Indenter with_approach_path(const Model& model, Indenter tool)
{
    if (tool.path.size() != 1) return tool;
    if (tool.shape != IndenterShape::sphere) fail("tool '{}': a single pose needs a sphere to find its approach (give the path from first contact)", tool.name);
    if (model.surface.triangles.empty()) fail("tool '{}': a single pose needs the model's surface to find its approach", tool.name);
    const TriangleSearch search(model.mesh.nodes, model.surface.triangles);
    const Vec3 pose = tool.path.front();
    const ClosestTriangle nearest = search.closest(pose);
    const auto& t = model.surface.triangles[static_cast<std::size_t>(nearest.triangle)];
    const Vec3& a = model.mesh.nodes[static_cast<std::size_t>(t[0])];
    const Vec3 normal = (model.mesh.nodes[static_cast<std::size_t>(t[1])] - a).cross(model.mesh.nodes[static_cast<std::size_t>(t[2])] - a).normalized();
    // Clear of the skin: no contact, the tool stays where it is. Else it came in along the normal
    // from where it first touched the skin point nearest its pose.
    if ((pose - nearest.point).dot(normal) >= tool.radius_mm) {
        tool.path = {pose, pose};
        return tool;
    }
    tool.path = {nearest.point + tool.radius_mm * normal, pose};
    return tool;
}

ModelRegistration register_model(const Model& model, const Observation& observation, const ModelRegistrationSettings& settings,
                                 const std::function<void(double, const std::string&)>& progress)
{
    const auto start = std::chrono::steady_clock::now();
    ModelRegistration out;
    if (const auto* tool = std::get_if<ToolObservation>(&observation)) {
        out.mode = "compression";
        out.solver = settings.compression.method == StaticMethod::newton ? "TLED, Newton to equilibrium" : "TLED, dynamic relaxation to equilibrium";
        const LiverModel prepared = compression_model(model, "compression mode");
        if (progress) progress(0.0, "compression: equilibrium under the tool");
        const Indenter path = with_approach_path(model, tool->tool);
        if (tool->tool.path.size() == 1 && path.path.front() == path.path.back()) {
            // One pose clear of the skin: nothing touches the model.
            out.notes = "one pose, clear of the skin: no contact";
            out.displacement_mm.assign(3 * model.mesh.node_count(), 0.0);
        } else {
            if (tool->tool.path.size() == 1) out.notes = "one pose: the tool came in along the skin's normal from where it first touched it";
            std::string fallback;
            out.displacement_mm =
                predict_compression_with_fallback(prepared, path, {}, settings.compression, "the tool observation", 20, {}, &fallback).displacement_mm;
            if (!fallback.empty()) {
                out.solver = "the model linearised at rest, condensed contact (fallback)";
                out.notes += (out.notes.empty() ? "" : "; ") + fallback;
            }
        }
    } else if (const auto* cloud = std::get_if<CloudObservation>(&observation)) {
        out.mode = "surface";
        out.solver = "co-rotational backward Euler under annealed pair forces";
        out.displacement_mm = register_cloud(model, cloud->cloud, settings.cloud, progress).displacement_mm;
    } else {
        const auto& segmentation = std::get<SegmentationObservation>(observation);
        out.mode = "images";
        out.solver = "linear elasticity, L-BFGS with adjoint gradients";
        const auto r = register_segmentation(model, segmentation.labels, settings.segmentation, progress);
        out.displacement_mm.assign(r.displacement_mm.data(), r.displacement_mm.data() + r.displacement_mm.size());
        out.notes = "rigid pre-fit " + r.rigid_prefit + "; " + r.stop_reason;
    }
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return out;
}

std::vector<Vec3> displace_points(const Model& model, const std::vector<double>& displacement_mm, const std::vector<Vec3>& points,
                                  double max_distance_mm, const std::string& what)
{
    if (displacement_mm.size() != 3 * model.mesh.node_count())
        fail("{}: the displacement has {} values, the model {} nodes × 3", what, displacement_mm.size(), model.mesh.node_count());
    if (model.mesh.cell_type == CellType::hexahedron) {
        // Grid hexahedra (paper 000's models): cells are boxes of the grid, as move_landmarks embeds them.
        if (!model.mesh.grid) fail("{}: hexahedra without their grid cannot locate points (mesh them from a label volume)", what);
        const auto where = embed_in_grid_mesh(model.mesh, points);
        std::vector<Vec3> out(points.size());
        for (std::size_t i = 0; i < points.size(); ++i) {
            NodeEmbedding e = where[i];
            if (!e.inside && e.distance_mm > max_distance_mm)
                fail("{}: point {} at ({:.2f}, {:.2f}, {:.2f}) mm lies {:.2f} mm outside the model (at most {:.2f} mm allowed)", what, i + 1,
                     points[i].x(), points[i].y(), points[i].z(), e.distance_mm, max_distance_mm);
            e.natural = e.natural.cwiseMax(-1.0).cwiseMin(1.0); // just outside: the nearest cell's field, no extrapolation
            const auto u = interpolate_nodal(model.mesh, e, displacement_mm, 3);
            out[i] = points[i] + Vec3(u[0], u[1], u[2]);
        }
        return out;
    }
    LandmarkSet set(points.size());
    for (std::size_t n = 0; n < points.size(); ++n) set[n] = {std::to_string(n + 1), points[n], LandmarkType::unspecified};
    const auto where = embed_landmarks(model.mesh, set, max_distance_mm, what);
    const LandmarkSet moved = displace_landmarks(model.mesh, where, set, displacement_mm);
    std::vector<Vec3> out;
    for (const auto& l : moved) out.push_back(l.position);
    return out;
}

} // namespace physreg
