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

} // namespace physreg
