// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/thread_governor.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace physreg {

namespace {
// Which tasks ran, how often, and whether each ran inside a parallel region (one per thread) or
// outside it (on the full team).
struct Trace {
    std::vector<int> runs;
    std::vector<int> in_parallel;
};
Trace run_packed(std::size_t tasks, int threads)
{
    const int saved = omp_get_max_threads();
    omp_set_num_threads(threads);
    Trace t{std::vector<int>(tasks, 0), std::vector<int>(tasks, -1)};
    for_each_task_packed(tasks, [&](std::size_t i) {
#pragma omp atomic
        ++t.runs[i];
        t.in_parallel[i] = omp_in_parallel() ? 1 : 0;
    });
    omp_set_num_threads(saved);
    return t;
}
} // namespace

TEST(ThreadPacking, WholeRoundsOnePerThreadAndTheRestOnTheFullTeam)
{
    // Three solves on two threads: two side by side, the third alone with both threads.
    const Trace three = run_packed(3, 2);
    EXPECT_EQ(three.runs, (std::vector<int>{1, 1, 1}));
    EXPECT_EQ(three.in_parallel, (std::vector<int>{1, 1, 0}));
    // Four: two whole rounds.
    const Trace four = run_packed(4, 2);
    EXPECT_EQ(four.runs, (std::vector<int>{1, 1, 1, 1}));
    EXPECT_EQ(four.in_parallel, (std::vector<int>{1, 1, 1, 1}));
    // One thread, or fewer tasks than threads: one after another.
    EXPECT_EQ(run_packed(3, 1).in_parallel, (std::vector<int>{0, 0, 0}));
    EXPECT_EQ(run_packed(1, 2).in_parallel, (std::vector<int>{0}));
    EXPECT_TRUE(run_packed(0, 2).runs.empty());
}

} // namespace physreg
