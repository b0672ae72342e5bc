// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/blas_kernels.hpp"

#include <dlfcn.h>
#include <unistd.h>

#include <cctype>
#include <cstdlib>

namespace physreg {

std::string openblas_kernels()
{
    // Looked up at run time: the BLAS behind CHOLMOD is whatever libblas.so.3 the system chose.
    using CoreName = char* (*)();
    const auto core_name = reinterpret_cast<CoreName>(dlsym(RTLD_DEFAULT, "openblas_get_corename"));
    if (!core_name) return {};
    const char* name = core_name();
    return name ? std::string(name) : std::string();
}

std::string openblas_better_kernels()
{
    std::string core = openblas_kernels();
    for (auto& c : core) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (core != "prescott") return {}; // OpenBLAS knew the CPU (or is absent): keep its choice
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq") &&
        __builtin_cpu_supports("avx512vl"))
        return "SkylakeX";
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
    return {};
}

void restart_with_fast_blas_kernels(char** argv)
{
    if (std::getenv("OPENBLAS_CORETYPE")) return;
    const std::string better = openblas_better_kernels();
    if (better.empty()) return;
    if (setenv("OPENBLAS_CORETYPE", better.c_str(), 1) != 0) return;
    execv("/proc/self/exe", argv); // returns only on failure: go on with the generic kernels
    unsetenv("OPENBLAS_CORETYPE");
}

} // namespace physreg
