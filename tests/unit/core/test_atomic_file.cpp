// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "test_support.hpp"

#include <fstream>

namespace physreg {

TEST(CoreAtomicFile, FullExtensionKeepsDoubleSuffixes)
{
    EXPECT_EQ(full_extension("a/b/labels.nii.gz"), ".nii.gz");
    EXPECT_EQ(full_extension("points.mrk.json"), ".mrk.json");
    EXPECT_EQ(full_extension("MESH.VTU"), ".vtu");
    EXPECT_EQ(full_extension("noext"), "");
}

TEST(CoreAtomicFile, CompleteWriteAppearsUnderTheTargetName)
{
    test::TempDir dir;
    write_atomically(dir / "out.txt", [](const std::filesystem::path& tmp) {
        EXPECT_NE(tmp.filename().string(), "out.txt");
        EXPECT_EQ(full_extension(tmp), ".txt");
        std::ofstream(tmp) << "hello";
    });
    EXPECT_EQ(dir.files(), std::vector<std::string>{"out.txt"});
}

TEST(CoreAtomicFile, FailedWriteLeavesNothingAndKeepsTheOldFile)
{
    test::TempDir dir;
    std::ofstream(dir / "out.txt") << "old";
    EXPECT_THROW(write_atomically(dir / "out.txt",
                                  [](const std::filesystem::path& tmp) {
                                      std::ofstream(tmp) << "half";
                                      fail("disk full");
                                  }),
                 Error);
    EXPECT_EQ(dir.files(), std::vector<std::string>{"out.txt"});
    std::ifstream in(dir / "out.txt");
    std::string content;
    in >> content;
    EXPECT_EQ(content, "old");
}

TEST(CoreAtomicFile, MissingDirectoryIsAnError)
{
    test::TempDir dir;
    try {
        write_atomically(dir / "no" / "out.txt", [](const std::filesystem::path&) {});
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos);
    }
}

} // namespace physreg
