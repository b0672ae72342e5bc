// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Which OpenBLAS kernels this process runs. Debian's OpenBLAS picks its kernels once, when it loads,
// from the CPU's family and model. On a CPU it does not know — a virtual machine that masks the
// model, or a CPU newer than the library — it falls back to its generic "Prescott" kernels: dgemm at
// 16 instead of 78 GFlop/s on this project's AVX-512 machines, and CHOLMOD's supernodal
// factorisation (the phantom's ground truth, paper 001's model) about 3× slower (measured: 11.7 against 4.0 s). OPENBLAS_CORETYPE,
// read at load time, chooses the kernels instead; physreg's main() starts the program again with it
// when the library fell back on a CPU that can run better ones.
#include <string>

namespace physreg {

/// OpenBLAS's kernel set in this process ("SkylakeX", "Haswell", "Prescott", …); empty when the
/// BLAS linked in is not OpenBLAS.
std::string openblas_kernels();

/// The OPENBLAS_CORETYPE to ask for when OpenBLAS fell back to its generic kernels on a CPU with
/// AVX-512 (F, BW, DQ, VL: "SkylakeX") or AVX2 and FMA ("Haswell"); empty when it did not fall back,
/// the CPU has neither, or the BLAS is not OpenBLAS.
std::string openblas_better_kernels();

/// For a program's main(), first thing: when openblas_better_kernels() names kernels and the user set
/// no OPENBLAS_CORETYPE, executes the program again (the same process) with OPENBLAS_CORETYPE set —
/// ≈ 50 ms. Returns when there is nothing to do, or when the restart failed (then with the generic
/// kernels). After the restart the variable is set, so it happens at most once.
void restart_with_fast_blas_kernels(char** argv);

} // namespace physreg
