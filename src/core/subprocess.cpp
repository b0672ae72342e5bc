// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/subprocess.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"

#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstring>
#include <spawn.h>
#include <sys/wait.h>
#include <thread>

extern char** environ;

namespace physreg {

int run_shell_command(const std::string& command)
{
    posix_spawnattr_t attributes;
    posix_spawnattr_init(&attributes);
    sigset_t none, defaults;
    sigemptyset(&none);
    sigemptyset(&defaults);
    for (int s : {SIGINT, SIGTERM, SIGHUP, SIGXFSZ, SIGPIPE}) sigaddset(&defaults, s);
    posix_spawnattr_setsigmask(&attributes, &none);
    posix_spawnattr_setsigdefault(&attributes, &defaults);
    posix_spawnattr_setpgroup(&attributes, 0); // its own group: a forwarded signal reaches the shell's children too
    posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF | POSIX_SPAWN_SETPGROUP);
    const char* shell = "/bin/sh";
    char* argv[] = {const_cast<char*>("sh"), const_cast<char*>("-c"), const_cast<char*>(command.c_str()), nullptr};
    pid_t child = 0;
    const int spawned = posix_spawn(&child, shell, nullptr, &attributes, argv, environ);
    posix_spawnattr_destroy(&attributes);
    if (spawned != 0) fail("cannot start {} -c '{}': {}", shell, command, std::strerror(spawned));

    // Polled rather than a blocking waitpid(), so that a signal the watcher takes meanwhile is
    // passed on within 20 ms.
    bool forwarded = false;
    for (;;) {
        int status = 0;
        const pid_t done = waitpid(child, &status, WNOHANG);
        if (done == child) return status;
        if (done < 0 && errno != EINTR) fail("waiting for '{}': {}", command, std::strerror(errno));
        if (const int s = interrupt_signal(); s != 0 && !forwarded) {
            kill(-child, s);
            forwarded = true;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
}

} // namespace physreg
