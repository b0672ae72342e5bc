// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Outputs are written to a temporary file beside the target and renamed into place only when
// complete, so a failure never leaves a partial or corrupted output behind.
#include <filesystem>
#include <functional>
#include <string>

namespace physreg {

// Calls write(temporary_path), then renames the temporary onto `target`. The temporary keeps the
// target's extensions (ITK picks the format from them). On any exception the temporary is removed
// and the exception propagates; `target` is untouched.
void write_atomically(const std::filesystem::path& target,
                      const std::function<void(const std::filesystem::path&)>& write);

// Lower-case extension with compression suffix kept: "a/b.nii.gz" -> ".nii.gz", "x.mrk.json" -> ".mrk.json".
std::string full_extension(const std::filesystem::path& path);

/// A folder of outputs that appears whole or not at all: written under a hidden sibling
/// (".NAME.partial-PID"), renamed onto `target` by commit(), removed if destroyed before. An
/// existing non-empty `target` is refused at construction unless `replace` is set (then it is
/// replaced at commit).
class StagedDirectory {
public:
    StagedDirectory(const std::filesystem::path& target, bool replace);
    ~StagedDirectory();
    StagedDirectory(const StagedDirectory&) = delete;
    StagedDirectory& operator=(const StagedDirectory&) = delete;
    const std::filesystem::path& path() const { return m_path; }
    void commit();

private:
    std::filesystem::path m_target, m_path;
    bool m_committed = false;
};

} // namespace physreg
