// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/explicit/gpu_tled.hpp"

#include "backend.hpp"
#if PHYSREG_HAVE_CUDA
#include "cuda_steps.hpp"
#endif
#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace physreg {

namespace gpu {

StepModel HostModel::view() const
{
    StepModel m;
    m.elements = elements;
    m.nodes = nodes;
    m.law = law;
    m.connectivity = connectivity.data();
    m.material = material.data();
    m.geometry = geometry.data();
    m.dn = dn.data();
    m.gamma = gamma.data();
    m.volume = volume.data();
    m.vb2 = vb2.data();
    m.mu = mu.data();
    m.lambda = lambda.data();
    m.kappa = kappa.data();
    m.hourglass = hourglass.data();
    m.incidence_offset = incidence_offset.data();
    m.incidence = incidence.data();
    m.coefficient_a = coefficient_a.data();
    m.coefficient_b = coefficient_b.data();
    m.coefficient_c = coefficient_c.data();
    m.constrained = constrained.data();
    m.prescribed = prescribed.data();
    m.external = external.empty() ? nullptr : external.data();
    return m;
}

namespace {

/// The GPU algorithm on the CPU (OpenMP over elements, then over nodes): slow, for checking.
class HostBackend final : public GpuTledSolver::Backend {
public:
    explicit HostBackend(const HostModel& model)
        : m_model(model), m_force(24 * static_cast<std::size_t>(model.elements)), m_u(3 * model.nodes), m_u_prev(m_u.size()), m_u_next(m_u.size())
    {
    }
    void set_loads(const HostModel& model) override { m_model = model; }
    void upload_state(const std::vector<double>& u, const std::vector<double>& u_prev) override
    {
        m_u = u;
        m_u_prev = u_prev;
    }
    void download_state(std::vector<double>& u, std::vector<double>& u_prev) override
    {
        u = m_u;
        u_prev = m_u_prev;
    }
    ChunkReport run(const std::vector<double>& s, const std::vector<double>& sn, double limit_mm) override
    {
        const StepModel m = m_model.view();
        ChunkReport report;
        for (std::size_t step = 0; step < s.size(); ++step) {
            std::int64_t inverted = std::numeric_limits<std::int64_t>::max();
            double largest = 0.0;
#pragma omp parallel
            {
#pragma omp for schedule(static) reduction(min : inverted)
                for (std::int64_t e = 0; e < m.elements; ++e)
                    if (!element_forces(m, e, m_u.data(), m_force.data())) inverted = std::min(inverted, e);
#pragma omp for schedule(static) reduction(max : largest)
                for (std::int64_t i = 0; i < m.nodes; ++i)
                    largest = std::max(largest, node_update(m, i, m_force.data(), m_u.data(), m_u_prev.data(), m_u_next.data(), s[step], sn[step]));
            }
            std::swap(m_u_prev, m_u);
            std::swap(m_u, m_u_next);
            report.largest_mm = std::max(report.largest_mm, largest);
            if (inverted != std::numeric_limits<std::int64_t>::max()) {
                report.inverted_element = inverted;
                report.inverted_step = static_cast<long>(step);
                break;
            }
            if (!(largest <= limit_mm)) break;
        }
        return report;
    }

private:
    HostModel m_model;
    std::vector<double> m_force, m_u, m_u_prev, m_u_next;
};

#if PHYSREG_HAVE_CUDA
template <typename F>
auto guard(F&& f)
{
    try {
        return f();
    } catch (const std::runtime_error& e) {
        fail("GPU path (CUDA): {}", e.what());
    }
}

/// The CUDA back end; its standard exceptions become errors that name the GPU path.
class CudaBackend final : public GpuTledSolver::Backend {
public:
    explicit CudaBackend(const HostModel& model) : m_steps(guard([&] { return std::make_unique<CudaSteps>(model); })) {}
    void set_loads(const HostModel& model) override
    {
        guard([&] { m_steps->set_loads(model); return 0; });
    }
    void upload_state(const std::vector<double>& u, const std::vector<double>& u_prev) override
    {
        guard([&] { m_steps->upload(u, u_prev); return 0; });
    }
    void download_state(std::vector<double>& u, std::vector<double>& u_prev) override
    {
        guard([&] { m_steps->download(u, u_prev); return 0; });
    }
    ChunkReport run(const std::vector<double>& s, const std::vector<double>& sn, double limit_mm) override
    {
        return guard([&] { return m_steps->run(s, sn, limit_mm); });
    }

private:
    std::unique_ptr<CudaSteps> m_steps;
};
#endif

} // namespace

std::unique_ptr<GpuTledSolver::Backend> make_host_backend(const HostModel& model)
{
    return std::make_unique<HostBackend>(model);
}

std::unique_ptr<GpuTledSolver::Backend> make_cuda_backend([[maybe_unused]] const HostModel& model)
{
    const GpuStatus status = gpu_status();
    if (!status.usable()) fail("--device gpu: {}", status.reason);
#if PHYSREG_HAVE_CUDA
    return std::make_unique<CudaBackend>(model);
#else
    fail("--device gpu: this physreg was built without the GPU path");
#endif
}

} // namespace gpu

GpuStatus gpu_status()
{
    GpuStatus status;
#if PHYSREG_HAVE_CUDA
    status.built = true;
    const gpu::CudaQuery query = gpu::query_cuda();
    status.devices = query.devices;
    status.device_name = query.name;
    if (query.devices == 0)
        status.reason = query.error.empty() ? "no CUDA device on this machine" : "no usable CUDA device (the CUDA runtime says: " + query.error + ")";
#else
    status.reason = "this physreg was built without the GPU path (no CUDA compiler was found at configure time: install the CUDA "
                    "toolkit and configure again, or pass -DPHYSREG_CUDA=ON to require it)";
#endif
    return status;
}

namespace {

gpu::HostModel pack(const TledModel& model, double dt)
{
    if (model.nodes_per_element() != 8)
        fail("GPU path: hexahedral meshes only (this model has {}-node elements); run it on the CPU (--device cpu)", model.nodes_per_element());
    const MaterialLaw law = model.options().law;
    if (law != MaterialLaw::neo_hookean && law != MaterialLaw::st_venant_kirchhoff)
        fail("GPU path: the Neo-Hookean and St Venant–Kirchhoff laws only; run this law on the CPU (--device cpu)");
    gpu::HostModel h;
    h.law = law == MaterialLaw::neo_hookean ? gpu::step_neo_hookean : gpu::step_st_venant_kirchhoff;
    h.elements = static_cast<std::int64_t>(model.element_count());
    h.nodes = static_cast<std::int64_t>(model.node_count());
    h.connectivity = model.connectivity();
    h.material = model.element_material();
    h.geometry = model.element_geometry();
    for (const auto& g : model.geometries()) {
        h.dn.insert(h.dn.end(), g.dn_dx.begin(), g.dn_dx.end());
        h.gamma.insert(h.gamma.end(), g.gamma.begin(), g.gamma.end());
        h.volume.push_back(g.volume_mm3);
        h.vb2.push_back(g.volume_mm3 * g.b_squared);
    }
    for (const auto& m : model.materials()) {
        h.mu.push_back(m.mu_mpa);
        h.lambda.push_back(m.lambda_mpa);
        h.kappa.push_back(m.kappa_mpa);
        h.hourglass.push_back(model.options().hourglass_kappa * hourglass_modulus_mpa(model.options(), m) / 8.0);
    }
    // Incidence per node in element order (the sum's order is fixed: deterministic results).
    std::vector<std::int64_t> count(h.nodes + 1, 0);
    for (std::int64_t e = 0; e < h.elements; ++e)
        for (int a = 0; a < 8; ++a) ++count[h.connectivity[8 * e + a] + 1];
    for (std::int64_t i = 0; i < h.nodes; ++i) count[i + 1] += count[i];
    h.incidence_offset = count;
    h.incidence.resize(static_cast<std::size_t>(count.back()));
    for (std::int64_t e = 0; e < h.elements; ++e)
        for (int a = 0; a < 8; ++a) h.incidence[count[h.connectivity[8 * e + a]]++] = 3 * a * h.elements + e;
    const double alpha = model.options().damping_per_s;
    h.coefficient_a.resize(h.nodes);
    h.coefficient_b.resize(h.nodes);
    h.coefficient_c.resize(h.nodes);
    for (std::int64_t i = 0; i < h.nodes; ++i) {
        const double m = model.lumped_mass()[i];
        const double denominator = m / (dt * dt) + alpha * m / (2 * dt);
        h.coefficient_a[i] = 1.0 / denominator;
        h.coefficient_b[i] = 2.0 * m / (dt * dt) / denominator;
        h.coefficient_c[i] = (m / (dt * dt) - alpha * m / (2 * dt)) / denominator;
    }
    h.constrained.assign(3 * h.nodes, 0);
    h.prescribed.assign(3 * h.nodes, 0.0);
    return h;
}

} // namespace

GpuTledSolver::GpuTledSolver(const TledModel& model, Device device) : m_model(model), m_device(device)
{
    if (device == Device::cpu) fail("GpuTledSolver: device cpu (use TledSolver)");
    m_time_step = model.time_step_s();
    const gpu::HostModel packed = pack(model, m_time_step);
    m_backend = device == Device::gpu ? gpu::make_cuda_backend(packed) : gpu::make_host_backend(packed);
    const std::vector<double> zero(3 * model.node_count(), 0.0);
    m_backend->upload_state(zero, zero);
}

GpuTledSolver::~GpuTledSolver() = default;

void GpuTledSolver::set_loads(Loads loads)
{
    loads.validate(m_model.node_count());
    if (!loads.indenters.empty())
        fail("GPU path: tools (indenters) are not on the GPU; run tool contact on the CPU (--device cpu)");
    m_loads = std::move(loads);
    gpu::HostModel h = pack(m_model, m_time_step);
    for (const auto& c : m_loads.constraints)
        for (auto node : c.nodes)
            for (int d = 0; d < 3; ++d)
                if (c.dofs[d]) {
                    h.constrained[3 * node + d] = 1;
                    h.prescribed[3 * node + d] = c.displacement_mm[d];
                }
    if (!m_loads.external_forces_n.empty()) h.external = m_loads.external_forces_n;
    m_backend->set_loads(h);
}

void GpuTledSolver::set_displacement(const std::vector<double>& u)
{
    if (u.size() != 3 * m_model.node_count()) fail("displacement: {} values for {} nodes", u.size(), m_model.node_count());
    for (std::size_t k = 0; k < u.size(); ++k)
        if (!std::isfinite(u[k])) fail("displacement: node {} is not finite", k / 3);
    m_backend->upload_state(u, u);
}

std::vector<double> GpuTledSolver::displacement_mm() const
{
    std::vector<double> u, u_prev;
    m_backend->download_state(u, u_prev);
    return u;
}

void GpuTledSolver::advance(double duration_s, const ProgressCallback& progress)
{
    if (!(duration_s >= 0 && std::isfinite(duration_s))) fail("simulation duration {} s must be ≥ 0", duration_s);
    const double dt = m_time_step;
    const long steps = static_cast<long>(std::ceil(duration_s / dt - 1e-9));
    const double limit = 10.0 * m_model.diagonal_mm();
    constexpr long chunk = 64; // steps between the host's checks of inversion and divergence
    for (long begin = 0; begin < steps; begin += chunk) {
        const long count = std::min(chunk, steps - begin);
        std::vector<double> s(count), sn(count);
        for (long k = 0; k < count; ++k) {
            s[k] = m_loads.load_factor(m_time + double(k) * dt);
            sn[k] = m_loads.load_factor(m_time + double(k + 1) * dt);
        }
        const gpu::ChunkReport report = m_backend->run(s, sn, limit);
        if (report.inverted_element >= 0)
            fail("dynamics, by step {} ({}): element {} is inverted (det F ≤ 0); the load is too large for this mesh, or the run is "
                 "unstable (reduce the time step or the load)",
                 m_steps + report.inverted_step + 1, to_string(m_device), report.inverted_element);
        if (!(report.largest_mm <= limit))
            fail("dynamics steps {}–{} ({}): the solution diverged (|u| = {:.3g} mm, model size {:.3g} mm)", m_steps + 1, m_steps + count,
                 to_string(m_device), report.largest_mm, m_model.diagonal_mm());
        m_steps += count;
        m_time += double(count) * dt;
        if (progress) progress(double(begin + count) / double(steps), m_steps);
        throw_if_interrupted();
    }
}

// Element kernel: gather 24 doubles and write 24 (element storage); node kernel: read 24 stored
// values per element (8 incidences of 3), 3 + 3 doubles of state and 3 written per node (≈ one
// node per element on a grid), plus connectivity (8 × 4 bytes) and incidences (8 × 8 bytes).
double GpuTledSolver::bytes_per_element_step()
{
    return 8.0 * (24 + 24 + 24 + 9) + 8 * 4 + 8 * 8;
}

// F (72 FMA), S (≈ 45), P (27 FMA + 9), hourglass modes (96 FMA + 12), forces (8 × 3 × 7 FMA):
// counting an FMA as 2 operations.
double GpuTledSolver::flops_per_element_step()
{
    return 2 * 72 + 45 + 2 * 27 + 9 + 2 * 96 + 12 + 2 * 168;
}

} // namespace physreg
