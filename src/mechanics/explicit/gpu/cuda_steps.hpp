// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The CUDA back end's entry points (cuda_steps.cu; compiled only when the CUDA toolkit is found).
// Standard C++ only; errors are std::runtime_error, which gpu_tled.cpp turns into physreg errors.
#include "host_model.hpp"

#include <memory>
#include <string>
#include <vector>

namespace physreg::gpu {

struct CudaQuery {
    int devices = 0;
    std::string name;  ///< the first device's
    std::string error; ///< the runtime's answer when it found none
};
CudaQuery query_cuda();

class CudaSteps {
public:
    explicit CudaSteps(const HostModel& model);
    ~CudaSteps();
    void set_loads(const HostModel& model);
    void upload(const std::vector<double>& u, const std::vector<double>& u_prev);
    void download(std::vector<double>& u, std::vector<double>& u_prev);
    ChunkReport run(const std::vector<double>& s, const std::vector<double>& sn, double limit_mm);

private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
};

} // namespace physreg::gpu
