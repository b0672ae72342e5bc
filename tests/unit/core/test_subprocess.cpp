// SPDX-License-Identifier: GPL-3.0-or-later
// Child programs start with the signals the program blocks for its watcher unblocked, and a
// signal the watcher takes is passed on to them.
#include "test_support.hpp"

#include "physreg/core/interrupt.hpp"
#include "physreg/core/subprocess.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <fstream>
#include <sstream>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace physreg {
namespace {

std::string status_line(const std::string& text, const std::string& key)
{
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);)
        if (line.rfind(key + ":", 0) == 0) return line.substr(key.size() + 1);
    return {};
}

std::uint64_t mask_of(const std::string& text, const std::string& key) { return std::stoull(status_line(text, key), nullptr, 16); }
bool has(std::uint64_t mask, int signal_number) { return (mask >> (signal_number - 1)) & 1u; }

TEST(Subprocess, ChildStartsWithTheWatchedSignalsUnblockedAndDefault)
{
    test::TempDir dir;
    sigset_t watched, previous;
    sigemptyset(&watched);
    for (int s : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&watched, s);
    pthread_sigmask(SIG_BLOCK, &watched, &previous); // as the program's threads have them
    const auto old_xfsz = std::signal(SIGXFSZ, SIG_IGN); // as the program has it
    const int status = run_shell_command("cat /proc/self/status > '" + (dir / "status.txt").string() + "'");
    std::signal(SIGXFSZ, old_xfsz);
    pthread_sigmask(SIG_SETMASK, &previous, nullptr);
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 0);
    std::ifstream in(dir / "status.txt");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_FALSE(status_line(text, "SigBlk").empty()) << text;
    for (int s : {SIGINT, SIGTERM, SIGHUP}) {
        EXPECT_FALSE(has(mask_of(text, "SigBlk"), s)) << "signal " << s << " blocked in the child";
        EXPECT_FALSE(has(mask_of(text, "SigIgn"), s)) << "signal " << s << " ignored in the child";
    }
    EXPECT_FALSE(has(mask_of(text, "SigIgn"), SIGXFSZ));
}

TEST(Subprocess, ExitStatusAndBadCommands)
{
    const int status = run_shell_command("exit 7");
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 7);
    EXPECT_EQ(WEXITSTATUS(run_shell_command("no-such-program-physreg 2>/dev/null")), 127);
}

TEST(Subprocess, ASignalTakenByTheWatcherStopsTheChild)
{
    // In a child process of the test, which installs the watcher as the program does.
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
        install_interrupt_handlers();
        const int status = run_shell_command("sleep 30; exit 3");
        _exit(WIFSIGNALED(status) ? 100 + WTERMSIG(status) : 1);
    }
    // Wait until the watcher has the signal, and a little more for the shell to start.
    for (int tries = 0; tries < 500; ++tries) {
        std::ifstream in("/proc/" + std::to_string(pid) + "/status");
        const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        if (!status_line(text, "SigBlk").empty() && has(mask_of(text, "SigBlk"), SIGTERM)) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    const auto start = std::chrono::steady_clock::now();
    kill(pid, SIGTERM);
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 100 + SIGTERM) << "the shell was not ended by the forwarded SIGTERM";
    EXPECT_LT(seconds, 10.0) << "the child ran on after the signal";
}

} // namespace
} // namespace physreg
