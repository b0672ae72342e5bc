// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// How long an idle OpenMP thread spins before it sleeps, for a program on a shared machine.
//
// libgomp lets a waiting thread (at a barrier, or idle between parallel regions) spin for 300 000
// rounds, a good fraction of a millisecond, before it sleeps on a futex. Beside a competing process
// that spinning takes the core the working thread needs: two threads took 1.57× the time of one
// (bench/shared_load.sh, issue 30 item 5). Passive waiting (no spin) cured that but slowed the
// relaxation's many short regions 2× on a quiet machine. 1 000 rounds — a few µs — keep the hand-over
// between regions quick and let an idle thread give the core back: under load two threads as fast
// as one, on a quiet machine no slower (bench/README.md).
//
// libgomp reads its environment once, in its initializer, before any code of ours runs. Only the
// executable's .preinit_array runs earlier, and a setenv() there is undone when libc's initializer
// installs the original environment. So PHYSREG_OPENMP_SHORT_SPIN() puts in .preinit_array a function
// that, unless the user chose a policy (GOMP_SPINCOUNT or OMP_WAIT_POLICY set), executes the
// program again at once with GOMP_SPINCOUNT=1000 added: the same process (pid, signals, files),
// before any initializer ran; ≈ 50 ms more per start (loading its libraries again). If /proc/self/exe cannot be
// executed it goes on with libgomp's default. Use it once, in the file with main(), of an
// executable (a shared library's .preinit_array is ignored). The Python package sets the variable
// before it loads the module.
#include <unistd.h>

#include <cstring>

namespace physreg::detail {
// Runs before libc's and the sanitizers' initializers: no allocation, no instrumented stack.
__attribute__((no_sanitize("address", "undefined"))) inline void openmp_short_spin(int, char** argv, char** envp)
{
    static char setting[] = "GOMP_SPINCOUNT=1000";
    static char* environment[4096];
    int count = 0;
    for (char** e = envp; e && *e; ++e) {
        if (std::strncmp(*e, "GOMP_SPINCOUNT=", 15) == 0 || std::strncmp(*e, "OMP_WAIT_POLICY=", 16) == 0) return;
        if (count + 2 >= 4096) return; // an environment this large keeps libgomp's default
        environment[count++] = *e;
    }
    environment[count] = setting;
    environment[count + 1] = nullptr;
    execve("/proc/self/exe", argv, environment); // returns only on failure: go on as we are
}
} // namespace physreg::detail

#define PHYSREG_OPENMP_SHORT_SPIN()                                                                                                        \
    __attribute__((section(".preinit_array"), used)) static void (*const physreg_openmp_short_spin_entry)(int, char**, char**) =             \
        &physreg::detail::openmp_short_spin
