#include "physreg/core/atomic_file.hpp"

#include "physreg/core/error.hpp"

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
        std::error_code ec;
        fs::rename(temporary, target, ec);
        if (ec) fail("cannot move '{}' onto '{}': {}", temporary.string(), target.string(), ec.message());
    } catch (...) {
        std::error_code ignored;
        fs::remove(temporary, ignored);
        throw;
    }
}

} // namespace physreg
