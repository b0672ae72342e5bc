// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/atomic_file.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"

#include <algorithm>
#include <atomic>
#include <unistd.h>

namespace physreg {

std::string full_extension(const std::filesystem::path& path)
{
    std::string name = path.filename().string();
    std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return std::tolower(c); });
    for (const char* two : {".nii.gz", ".mrk.json", ".vtk.gz"}) {
        const std::string suffix(two);
        if (name.size() > suffix.size() && name.ends_with(suffix)) return suffix;
    }
    const auto dot = name.rfind('.');
    return dot == std::string::npos || dot == 0 ? std::string() : name.substr(dot);
}

void write_atomically(const std::filesystem::path& target,
                      const std::function<void(const std::filesystem::path&)>& write)
{
    namespace fs = std::filesystem;
    static std::atomic<unsigned> counter{0};
    const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
    if (!fs::is_directory(dir))
        fail("cannot write '{}': directory '{}' does not exist", target.string(), dir.string());
    const std::string ext = full_extension(target);
    std::string stem = target.filename().string();
    stem = stem.substr(0, stem.size() - ext.size());
    const fs::path temporary = dir / fmt::format(".{}.tmp{}-{}{}", stem, ::getpid(), counter++, ext);
    try {
        write(temporary);
        throw_if_interrupted(); // an interrupted run commits nothing
        std::error_code ec;
        fs::rename(temporary, target, ec);
        if (ec) fail("cannot move '{}' onto '{}': {}", temporary.string(), target.string(), ec.message());
    } catch (...) {
        std::error_code ignored;
        fs::remove(temporary, ignored);
        throw;
    }
}

StagedDirectory::StagedDirectory(const std::filesystem::path& target, bool replace) : m_target(target)
{
    namespace fs = std::filesystem;
    std::error_code ec;
    if (fs::exists(target, ec)) {
        if (!fs::is_directory(target)) fail("output '{}' exists and is not a directory", target.string());
        if (!fs::is_empty(target) && !replace)
            fail("output directory '{}' exists and is not empty (choose another or allow replacing it)", target.string());
    }
    const fs::path parent = target.has_parent_path() ? target.parent_path() : fs::path(".");
    if (!fs::is_directory(parent)) fail("cannot write '{}': directory '{}' does not exist", target.string(), parent.string());
    m_path = parent / fmt::format(".{}.partial-{}", target.filename().string(), ::getpid());
    fs::remove_all(m_path, ec);
    fs::create_directories(m_path, ec);
    if (ec) fail("cannot write '{}': cannot create a folder in '{}': {}", target.string(), parent.string(), ec.message());
}

StagedDirectory::~StagedDirectory()
{
    if (m_committed) return;
    std::error_code ec;
    std::filesystem::remove_all(m_path, ec);
}

void StagedDirectory::commit()
{
    namespace fs = std::filesystem;
    throw_if_interrupted(); // an interrupted run commits nothing
    std::error_code ec;
    if (fs::exists(m_target, ec)) {
        const fs::path old = m_path.string() + ".old";
        fs::rename(m_target, old, ec);
        if (ec) fail("cannot move the old '{}' aside: {}", m_target.string(), ec.message());
        fs::rename(m_path, m_target, ec);
        if (ec) {
            std::error_code ignored;
            fs::rename(old, m_target, ignored);
            fail("cannot move '{}' onto '{}': {}", m_path.string(), m_target.string(), ec.message());
        }
        fs::remove_all(old, ec);
    } else {
        fs::rename(m_path, m_target, ec);
        if (ec) fail("cannot move '{}' onto '{}': {}", m_path.string(), m_target.string(), ec.message());
    }
    m_committed = true;
}

} // namespace physreg
