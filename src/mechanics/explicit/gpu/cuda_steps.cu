// SPDX-License-Identifier: GPL-3.0-or-later
// The GPU path's CUDA back end: the model in device memory, one launch per kernel per step, the
// host reading two flags every chunk of steps (inversion, divergence).
#include "cuda_steps.hpp"

#include <cuda_runtime.h>

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>

namespace physreg::gpu {
namespace {

void check(cudaError_t status, const char* what)
{
    if (status != cudaSuccess) throw std::runtime_error(std::string(what) + " failed: " + cudaGetErrorString(status));
}

template <typename T>
class DeviceArray {
public:
    DeviceArray() = default;
    explicit DeviceArray(const std::vector<T>& host) { assign(host); }
    ~DeviceArray() { release(); }
    DeviceArray(const DeviceArray&) = delete;
    DeviceArray& operator=(const DeviceArray&) = delete;
    void assign(const std::vector<T>& host)
    {
        resize(host.size());
        if (!host.empty()) check(cudaMemcpy(m_data, host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice), "cudaMemcpy to the device");
    }
    void resize(std::size_t n)
    {
        if (n == m_size) return;
        release();
        if (n) check(cudaMalloc(reinterpret_cast<void**>(&m_data), n * sizeof(T)), "cudaMalloc");
        m_size = n;
    }
    void copy_to(std::vector<T>& host) const
    {
        host.resize(m_size);
        if (m_size) check(cudaMemcpy(host.data(), m_data, m_size * sizeof(T), cudaMemcpyDeviceToHost), "cudaMemcpy to the host");
    }
    T* data() { return m_data; }
    const T* data() const { return m_data; }
    std::size_t size() const { return m_size; }

private:
    void release()
    {
        if (m_data) cudaFree(m_data);
        m_data = nullptr;
        m_size = 0;
    }
    T* m_data = nullptr;
    std::size_t m_size = 0;
};

__global__ void element_kernel(StepModel m, const double* u, double* element_force, unsigned long long* inverted)
{
    const std::int64_t e = static_cast<std::int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (e >= m.elements) return;
    if (!element_forces(m, e, u, element_force)) atomicMin(inverted, static_cast<unsigned long long>(e));
}

__global__ void node_kernel(StepModel m, const double* element_force, const double* u, const double* u_prev, double* u_next, double s,
                            double sn, double limit, int* diverged)
{
    const std::int64_t i = static_cast<std::int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (i >= m.nodes) return;
    if (!(node_update(m, i, element_force, u, u_prev, u_next, s, sn) <= limit)) *diverged = 1;
}

__global__ void largest_kernel(std::int64_t n, const double* u, unsigned long long* largest_bits)
{
    // |u| ≥ 0, so the order of doubles is the order of their bit patterns.
    const std::int64_t k = static_cast<std::int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (k >= n) return;
    const double value = fabs(u[k]);
    const double magnitude = value == value ? value : INFINITY;
    atomicMax(largest_bits, static_cast<unsigned long long>(__double_as_longlong(magnitude)));
}

} // namespace

struct CudaSteps::Impl {
    explicit Impl(const HostModel& model)
        : m_connectivity(model.connectivity), m_geometry(model.geometry), m_material(model.material), m_dn(model.dn), m_gamma(model.gamma),
          m_volume(model.volume), m_vb2(model.vb2), m_mu(model.mu), m_lambda(model.lambda), m_kappa(model.kappa), m_hourglass(model.hourglass),
          m_offset(model.incidence_offset), m_incidence(model.incidence), m_a(model.coefficient_a), m_b(model.coefficient_b),
          m_c(model.coefficient_c)
    {
        m_view = model.view();
        m_force.resize(24 * static_cast<std::size_t>(model.elements));
        for (auto* buffer : {&m_u0, &m_u1, &m_u2}) buffer->resize(3 * static_cast<std::size_t>(model.nodes));
        m_flags.resize(1);
        m_diverged.resize(1);
        set_loads(model);
    }
    void set_loads(const HostModel& model)
    {
        m_constrained.assign(model.constrained);
        m_prescribed.assign(model.prescribed);
        m_external.assign(model.external);
        StepModel& v = m_view;
        v.connectivity = m_connectivity.data();
        v.geometry = m_geometry.data();
        v.material = m_material.data();
        v.dn = m_dn.data();
        v.gamma = m_gamma.data();
        v.volume = m_volume.data();
        v.vb2 = m_vb2.data();
        v.mu = m_mu.data();
        v.lambda = m_lambda.data();
        v.kappa = m_kappa.data();
        v.hourglass = m_hourglass.data();
        v.incidence_offset = m_offset.data();
        v.incidence = m_incidence.data();
        v.coefficient_a = m_a.data();
        v.coefficient_b = m_b.data();
        v.coefficient_c = m_c.data();
        v.constrained = m_constrained.data();
        v.prescribed = m_prescribed.data();
        v.external = model.external.empty() ? nullptr : m_external.data();
    }
    void upload(const std::vector<double>& u, const std::vector<double>& u_prev)
    {
        current().assign(u);
        previous().assign(u_prev);
    }
    void download(std::vector<double>& u, std::vector<double>& u_prev)
    {
        current().copy_to(u);
        previous().copy_to(u_prev);
    }
    ChunkReport run(const std::vector<double>& s, const std::vector<double>& sn, double limit_mm)
    {
        const unsigned long long none = ~0ull;
        const int zero = 0;
        check(cudaMemcpy(m_flags.data(), &none, sizeof none, cudaMemcpyHostToDevice), "cudaMemcpy");
        check(cudaMemcpy(m_diverged.data(), &zero, sizeof zero, cudaMemcpyHostToDevice), "cudaMemcpy");
        constexpr int threads = 128;
        const unsigned element_blocks = static_cast<unsigned>((m_view.elements + threads - 1) / threads);
        const unsigned node_blocks = static_cast<unsigned>((m_view.nodes + threads - 1) / threads);
        for (std::size_t step = 0; step < s.size(); ++step) {
            element_kernel<<<element_blocks, threads>>>(m_view, current().data(), m_force.data(), m_flags.data());
            node_kernel<<<node_blocks, threads>>>(m_view, m_force.data(), current().data(), previous().data(), next().data(), s[step], sn[step],
                                                  limit_mm, m_diverged.data());
            m_rotation = (m_rotation + 1) % 3;
        }
        check(cudaGetLastError(), "a kernel launch");
        check(cudaDeviceSynchronize(), "the steps");
        ChunkReport report;
        unsigned long long inverted = none;
        int diverged = 0;
        check(cudaMemcpy(&inverted, m_flags.data(), sizeof inverted, cudaMemcpyDeviceToHost), "cudaMemcpy");
        check(cudaMemcpy(&diverged, m_diverged.data(), sizeof diverged, cudaMemcpyDeviceToHost), "cudaMemcpy");
        if (inverted != none) {
            report.inverted_element = static_cast<std::int64_t>(inverted);
            report.inverted_step = static_cast<long>(s.size()) - 1; // within this chunk
        }
        if (diverged) {
            const unsigned long long zero_bits = 0;
            check(cudaMemcpy(m_flags.data(), &zero_bits, sizeof zero_bits, cudaMemcpyHostToDevice), "cudaMemcpy");
            const std::int64_t n = 3 * m_view.nodes;
            largest_kernel<<<static_cast<unsigned>((n + threads - 1) / threads), threads>>>(n, current().data(), m_flags.data());
            unsigned long long bits = 0;
            check(cudaMemcpy(&bits, m_flags.data(), sizeof bits, cudaMemcpyDeviceToHost), "cudaMemcpy");
            double largest;
            std::memcpy(&largest, &bits, sizeof largest);
            report.largest_mm = largest > limit_mm ? largest : INFINITY;
        }
        return report;
    }

    // m_rotation r: previous = buffer r, current = r + 1, next = r + 2 (mod 3).
    DeviceArray<double>& buffer(int k) { return k == 0 ? m_u0 : k == 1 ? m_u1 : m_u2; }
    DeviceArray<double>& previous() { return buffer(m_rotation); }
    DeviceArray<double>& current() { return buffer((m_rotation + 1) % 3); }
    DeviceArray<double>& next() { return buffer((m_rotation + 2) % 3); }

    DeviceArray<std::int32_t> m_connectivity, m_geometry;
    DeviceArray<std::uint16_t> m_material;
    DeviceArray<double> m_dn, m_gamma, m_volume, m_vb2, m_mu, m_lambda, m_kappa, m_hourglass;
    DeviceArray<std::int64_t> m_offset, m_incidence;
    DeviceArray<double> m_a, m_b, m_c;
    DeviceArray<std::uint8_t> m_constrained;
    DeviceArray<double> m_prescribed, m_external, m_force, m_u0, m_u1, m_u2;
    DeviceArray<unsigned long long> m_flags;
    DeviceArray<int> m_diverged;
    StepModel m_view;
    int m_rotation = 0;
};

CudaQuery query_cuda()
{
    CudaQuery query;
    const cudaError_t error = cudaGetDeviceCount(&query.devices);
    if (error != cudaSuccess) {
        query.devices = 0;
        query.error = cudaGetErrorString(error);
        return query;
    }
    cudaDeviceProp properties{};
    if (query.devices > 0 && cudaGetDeviceProperties(&properties, 0) == cudaSuccess) query.name = properties.name;
    return query;
}

CudaSteps::CudaSteps(const HostModel& model) : m_impl(std::make_unique<Impl>(model)) {}
CudaSteps::~CudaSteps() = default;
void CudaSteps::set_loads(const HostModel& model) { m_impl->set_loads(model); }
void CudaSteps::upload(const std::vector<double>& u, const std::vector<double>& u_prev) { m_impl->upload(u, u_prev); }
void CudaSteps::download(std::vector<double>& u, std::vector<double>& u_prev) { m_impl->download(u, u_prev); }
ChunkReport CudaSteps::run(const std::vector<double>& s, const std::vector<double>& sn, double limit_mm) { return m_impl->run(s, sn, limit_mm); }

} // namespace physreg::gpu
