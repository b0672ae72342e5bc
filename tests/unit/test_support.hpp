// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Helpers shared by the unit tests: temporary directories, synthetic label volumes, shared data.
#include "physreg/image/image_geometry.hpp"

#include <cstdlib>
#include <filesystem>
#include <functional>
#include <gtest/gtest.h>
#include <string>

namespace physreg::test {

/// A fresh directory removed at the end of the test.
class TempDir {
public:
    TempDir();
    ~TempDir();
    const std::filesystem::path& path() const { return m_path; }
    std::filesystem::path operator/(const std::string& name) const { return m_path / name; }
    /// Names of the files in the directory (to check that nothing partial was left behind).
    std::vector<std::string> files() const;

private:
    std::filesystem::path m_path;
};

/// A label volume of `size` voxels whose label at (i,j,k) is label(i,j,k).
LabelVolume make_volume(Index3 size, const std::function<std::uint16_t(int, int, int)>& label,
                        Vec3 spacing = Vec3::Ones(), Vec3 origin = Vec3::Zero(), Mat3 direction = Mat3::Identity());

/// A proper rotation (det +1) about an oblique axis.
Mat3 oblique_rotation();

/// The message of the physreg::Error that `f` throws, or "" when it throws none.
std::string error_message(const std::function<void()>& f);

/// ../shared/data next to the checkout, or empty when it is absent.
std::filesystem::path shared_data_dir();

/// Whether the tests run in CI (CI=true), where every fixture must be there: a test that would
/// skip for want of one fails instead (issue 43).
inline bool in_ci()
{
    const char* ci = std::getenv("CI");
    return ci && std::string(ci) == "true";
}

} // namespace physreg::test

/// Skips the test for want of `message`'s fixture, or fails it in CI.
#define PHYSREG_MISSING_FIXTURE(message)                                                              \
    do {                                                                                              \
        if (::physreg::test::in_ci()) {                                                               \
            FAIL() << "a fixture is missing in CI (a skip there is a failure): " << message;          \
        } else {                                                                                      \
            GTEST_SKIP() << message;                                                                  \
        }                                                                                             \
    } while (0)

#define PHYSREG_REQUIRE_SHARED_DATA(sub)                                                             \
    const auto shared_data = ::physreg::test::shared_data_dir() / (sub);                            \
    if (::physreg::test::shared_data_dir().empty() || !std::filesystem::exists(shared_data))        \
    PHYSREG_MISSING_FIXTURE("shared data '" << (sub) << "' is absent")
