// SPDX-License-Identifier: GPL-3.0-or-later
#include "test_support.hpp"

#include "physreg/core/error.hpp"

#include <Eigen/Geometry>
#include <cstdlib>

namespace physreg::test {

TempDir::TempDir()
{
    std::string pattern = (std::filesystem::temp_directory_path() / "physreg-test-XXXXXX").string();
    if (!mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed");
    m_path = pattern;
}

TempDir::~TempDir()
{
    std::error_code ec;
    std::filesystem::remove_all(m_path, ec);
}

std::vector<std::string> TempDir::files() const
{
    std::vector<std::string> names;
    for (const auto& e : std::filesystem::directory_iterator(m_path)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

LabelVolume make_volume(Index3 size, const std::function<std::uint16_t(int, int, int)>& label, Vec3 spacing,
                        Vec3 origin, Mat3 direction)
{
    LabelVolume v;
    v.geometry.size = size;
    v.geometry.spacing = spacing;
    v.geometry.origin = origin;
    v.geometry.direction = direction;
    v.labels.resize(static_cast<std::size_t>(v.geometry.voxel_count()));
    for (int k = 0; k < size[2]; ++k)
        for (int j = 0; j < size[1]; ++j)
            for (int i = 0; i < size[0]; ++i) v.labels[static_cast<std::size_t>(v.geometry.linear_index(i, j, k))] = label(i, j, k);
    return v;
}

std::string error_message(const std::function<void()>& f)
{
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

Mat3 oblique_rotation()
{
    return Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
}

std::filesystem::path shared_data_dir()
{
    const std::filesystem::path dir(PHYSREG_SHARED_DATA_DIR);
    return std::filesystem::is_directory(dir) ? dir : std::filesystem::path();
}

} // namespace physreg::test
