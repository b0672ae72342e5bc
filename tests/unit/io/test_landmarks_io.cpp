// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/error.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "test_support.hpp"

#include <fstream>

namespace physreg {
namespace {

LandmarkSet sample()
{
    return {{"tip", Vec3(-12.345678901234567, 98.7654321, 0.1), LandmarkType::surface},
            {"lesion, centre", Vec3(1.0 / 3.0, -2.0 / 7.0, 1e-9), LandmarkType::tumour},
            {"bifurcation", Vec3(-0.0, 250.5, -33.25), LandmarkType::vessel},
            {"plain", Vec3(1, 2, 3), LandmarkType::unspecified}};
}

std::string error_of(const std::filesystem::path& p)
{
    return test::error_message([&] { read_landmarks(p); });
}

} // namespace

TEST(IoLandmarks, RoundTripsAreExactInEveryFormat)
{
    test::TempDir dir;
    for (const char* name : {"l.csv", "l.fcsv", "l.mrk.json"}) {
        SCOPED_TRACE(name);
        write_landmarks(dir / name, sample());
        const auto back = read_landmarks(dir / name);
        ASSERT_EQ(back.size(), sample().size());
        for (std::size_t i = 0; i < back.size(); ++i) {
            EXPECT_EQ(back[i].name, sample()[i].name);
            EXPECT_EQ(back[i].type, sample()[i].type);
            for (int a = 0; a < 3; ++a) EXPECT_EQ(back[i].position[a], sample()[i].position[a]); // bit-exact
        }
    }
}

TEST(IoLandmarks, RasFilesAreConvertedToLps)
{
    test::TempDir dir;
    std::ofstream(dir / "ras.fcsv") << "# Markups fiducial file version = 4.11\n# CoordinateSystem = RAS\n"
                                       "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n"
                                       "vtkMRMLMarkupsFiducialNode_0,10.5,-20.25,30,0,0,0,1,1,1,0,F-1,tumour,\n";
    auto l = read_landmarks(dir / "ras.fcsv");
    ASSERT_EQ(l.size(), 1u);
    EXPECT_EQ(l[0].position, Vec3(-10.5, 20.25, 30));
    EXPECT_EQ(l[0].type, LandmarkType::tumour);
    // Slicer before 4.11 wrote no coordinate system line: RAS.
    std::ofstream(dir / "old.fcsv") << "# Markups fiducial file version = 4.10\n"
                                       "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n"
                                       "vtkMRMLMarkupsFiducialNode_0,1,2,3,0,0,0,1,1,1,0,F-1,,\n";
    EXPECT_EQ(read_landmarks(dir / "old.fcsv")[0].position, Vec3(-1, -2, 3));
    std::ofstream(dir / "numeric.fcsv") << "# Markups fiducial file version = 4.11\n# CoordinateSystem = 1\n"
                                           "vtkMRMLMarkupsFiducialNode_0,1,2,3,0,0,0,1,1,1,0,F-1,,\n";
    EXPECT_EQ(read_landmarks(dir / "numeric.fcsv")[0].position, Vec3(1, 2, 3));
    std::ofstream(dir / "ras.mrk.json") << R"({"markups": [{"type": "Fiducial", "coordinateSystem": "RAS",
        "controlPoints": [{"label": "a", "position": [1.5, 2.5, -3.5], "description": "vessel"}]}]})";
    l = read_landmarks(dir / "ras.mrk.json");
    EXPECT_EQ(l[0].position, Vec3(-1.5, -2.5, -3.5));
    EXPECT_EQ(l[0].type, LandmarkType::vessel);
    std::ofstream(dir / "ras.csv") << "# coordinate_system = RAS\nname,x,y,z\np,1,2,3\n";
    EXPECT_EQ(read_landmarks(dir / "ras.csv")[0].position, Vec3(-1, -2, 3));
}

TEST(IoLandmarks, CsvAsUsersWriteThem)
{
    // `id` (or `label`) for the name column, and headerless rows of x,y,z named 1…N.
    test::TempDir dir;
    std::ofstream(dir / "id.csv") << "id,x,y,z\n7,1,2,3\n9,4,5,6\n";
    LandmarkSet l = read_landmarks(dir / "id.csv");
    ASSERT_EQ(l.size(), 2u);
    EXPECT_EQ(l[1].name, "9");
    EXPECT_EQ(l[1].position, Vec3(4, 5, 6));
    std::ofstream(dir / "bare.csv") << "# a comment\n1.5, -2, 3e1\n4,5,6\n";
    l = read_landmarks(dir / "bare.csv");
    ASSERT_EQ(l.size(), 2u);
    EXPECT_EQ(l[0].name, "1");
    EXPECT_EQ(l[0].position, Vec3(1.5, -2, 30));
    EXPECT_EQ(l[1].name, "2");
    // A row of three numbers after them that is not a number is still an error naming the line.
    std::ofstream(dir / "bare_bad.csv") << "1,2,3\n4,x,6\n";
    EXPECT_NE(error_of(dir / "bare_bad.csv").find("line 2"), std::string::npos);
    // Two numbers are neither a header nor a point.
    std::ofstream(dir / "two.csv") << "1,2\n";
    EXPECT_NE(error_of(dir / "two.csv").find("header must name"), std::string::npos);
}

TEST(IoLandmarks, BadFilesAreRefusedWithReasons)
{
    test::TempDir dir;
    std::ofstream(dir / "cm.csv") << "# units = cm\nname,x,y,z\na,1,2,3\n";
    EXPECT_NE(error_of(dir / "cm.csv").find("units"), std::string::npos);
    std::ofstream(dir / "um.mrk.json") << R"({"markups": [{"coordinateSystem": "LPS", "coordinateUnits": "um", "controlPoints": []}]})";
    EXPECT_NE(error_of(dir / "um.mrk.json").find("coordinateUnits"), std::string::npos);
    std::ofstream(dir / "nan.csv") << "name,x,y,z\na,1,nan,3\n";
    EXPECT_NE(error_of(dir / "nan.csv").find("line 2"), std::string::npos);
    std::ofstream(dir / "short.csv") << "name,x,y,z\na,1,2\n";
    EXPECT_NE(error_of(dir / "short.csv").find("fields"), std::string::npos);
    std::ofstream(dir / "dup.csv") << "name,x,y,z\na,1,2,3\na,4,5,6\n";
    EXPECT_NE(error_of(dir / "dup.csv").find("twice"), std::string::npos);
    std::ofstream(dir / "type.csv") << "name,x,y,z,type\na,1,2,3,bone\n";
    EXPECT_NE(error_of(dir / "type.csv").find("bone"), std::string::npos);
    std::ofstream(dir / "broken.mrk.json") << R"({"markups": [{"controlPoints": [{"label": "a", "position": [1, 2)";
    EXPECT_NE(error_of(dir / "broken.mrk.json").find("JSON"), std::string::npos);
    std::ofstream(dir / "nothing.fcsv") << "1,2,3\n";
    EXPECT_FALSE(error_of(dir / "nothing.fcsv").empty());
    EXPECT_NE(error_of(dir / "missing.csv").find("missing.csv': file does not exist"), std::string::npos);
    EXPECT_THROW(read_landmarks(dir / "missing.csv"), MissingFileError);
}

} // namespace physreg
