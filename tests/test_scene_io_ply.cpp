// The PLY reader on good files: graphdeco binary (little and big endian) and ASCII, every
// property type and order, SH degrees 0..3, recentring of UTM-sized coordinates, and the
// activations of each field computed by hand.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "catgs/error.hpp"
#include "catgs/progress.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"
#include "scene_io_fixtures.hpp"

namespace {

using namespace catgs::scene_io_test;

// =======================================================================================
// PLY: reading good files.

TEST(SceneIoPly, HandComputedActivations) {
    Ply ply;
    ply.props = graphdeco_props(0);
    ply.rows = {{{"x", 1.5},
                 {"y", -2.0},
                 {"z", 3.25},
                 {"f_dc_0", 0.5},
                 {"f_dc_1", -1.0},
                 {"f_dc_2", 2.0},
                 {"opacity", 0.0},
                 {"scale_0", 0.0},
                 {"scale_1", 1.3862943611198906},
                 {"scale_2", -0.6931471805599453},
                 {"rot_0", 0.0},
                 {"rot_1", 3.0},
                 {"rot_2", 0.0},
                 {"rot_3", 4.0}}};
    std::string path = tmp_path("a.ply");
    write_file(path, ply.bytes());
    catgs::LoadReport report;
    catgs::Scene s = catgs::read_ply(path, absolute(), &report);
    ASSERT_EQ(s.count(), 1u);
    EXPECT_EQ(report.records, 1u);
    EXPECT_EQ(s.sh_degree, 0);
    EXPECT_EQ(s.positions, (std::vector<float>{1.5f, -2.0f, 3.25f}));
    EXPECT_EQ(s.scales[0], 1.0f);
    EXPECT_FLOAT_EQ(s.scales[1], 4.0f);
    EXPECT_FLOAT_EQ(s.scales[2], 0.5f);
    EXPECT_EQ(s.opacities[0], 0.5f);
    EXPECT_EQ(s.rotations, (std::vector<float>{0.0f, 0.6f, 0.0f, 0.8f}));
    EXPECT_EQ(s.sh, (std::vector<float>{0.5f, -1.0f, 2.0f}));
    EXPECT_EQ(s.origin, (std::array<double, 3>{0, 0, 0}));
    EXPECT_EQ(s.bounds.min, (std::array<double, 3>{1.5, -2.0, 3.25}));
}

TEST(SceneIoPly, BinaryLittleEndianMatchesFormula) {
    Ply ply = graphdeco_ply(5, 1);
    std::string path = tmp_path("le.ply");
    write_file(path, ply.bytes());
    catgs::Scene s = catgs::read_ply(path, absolute());
    ASSERT_EQ(s.count(), 5u);
    EXPECT_EQ(s.sh_degree, 1);
    for (std::size_t g = 0; g < 5; ++g) expect_gaussian(s, g, ply.rows[g]);
}

TEST(SceneIoPly, BigEndianAndAsciiMatchLittleEndian) {
    Ply le = graphdeco_ply(7, 2);
    std::string le_path = tmp_path("le.ply");
    write_file(le_path, le.bytes());
    catgs::Scene reference = catgs::read_ply(le_path);
    for (const std::string format : {"binary_big_endian", "ascii"}) {
        SCOPED_TRACE(format);
        Ply other = graphdeco_ply(7, 2, format);
        std::string path = tmp_path(format + ".ply");
        write_file(path, other.bytes());
        expect_same_scene(catgs::read_ply(path), reference);
    }
    Ply crlf = graphdeco_ply(7, 2, "ascii");
    crlf.newline = "\r\n";
    std::string path = tmp_path("crlf.ply");
    write_file(path, crlf.bytes());
    expect_same_scene(catgs::read_ply(path), reference);
}

TEST(SceneIoPly, AsciiNumberForms) {
    Ply ply = graphdeco_ply(1, 0, "ascii");
    std::string text = ply.bytes();
    // Replace the x value (first token of the data line) with forms some writers emit.
    const std::string header = ply.header();
    for (const auto& [token, expected] : std::vector<std::pair<std::string, float>>{
             {"+2.5", 2.5f}, {"1e-400", 0.0f}, {"-1e-400", -0.0f}, {"3", 3.0f}, {".5", 0.5f}, {"1.25E+1", 12.5f}}) {
        SCOPED_TRACE(token);
        std::string data = text.substr(header.size());
        data = token + data.substr(data.find(' '));
        std::string path = tmp_path("num.ply");
        write_file(path, header + data);
        catgs::Scene s = catgs::read_ply(path, absolute());
        EXPECT_EQ(s.positions[0], expected);
        EXPECT_EQ(std::signbit(s.positions[0]), std::signbit(expected));
    }
}

TEST(SceneIoPly, DoubleIntegerAndAliasTypes) {
    Ply ply;
    ply.props = {{"float64", "x"},      {"int", "y"},        {"uchar", "z"},         {"double", "f_dc_0"},
                 {"int8", "f_dc_1"},    {"short", "f_dc_2"}, {"float32", "opacity"}, {"int16", "scale_0"},
                 {"uint16", "scale_1"}, {"char", "scale_2"}, {"uint8", "rot_0"},     {"uint32", "rot_1"},
                 {"int32", "rot_2"},    {"ushort", "rot_3"}, {"uint", "extra"}};
    ply.rows = {{{"x", 4500000.123456789},
                 {"y", -70000},
                 {"z", 200},
                 {"f_dc_0", 0.1},
                 {"f_dc_1", -5},
                 {"f_dc_2", -300},
                 {"opacity", 2.0},
                 {"scale_0", -3},
                 {"scale_1", 2},
                 {"scale_2", -1},
                 {"rot_0", 3},
                 {"rot_1", 4},
                 {"rot_2", -12},
                 {"rot_3", 0},
                 {"extra", 7}}};
    for (const std::string format : {"binary_little_endian", "binary_big_endian", "ascii"}) {
        SCOPED_TRACE(format);
        ply.format = format;
        std::string path = tmp_path(format + ".ply");
        write_file(path, ply.bytes());
        catgs::Scene s = catgs::read_ply(path, absolute());
        ASSERT_EQ(s.count(), 1u);
        expect_gaussian(s, 0, ply.rows[0], false);
        EXPECT_EQ(s.positions[0], static_cast<float>(4500000.123456789));  // read as double, one rounding
        EXPECT_EQ(s.positions[1], -70000.0f);
        EXPECT_EQ(s.sh[0], 0.1f);
        EXPECT_EQ(s.rotations[2], static_cast<float>(-12.0 / 13.0));
    }
}

TEST(SceneIoPly, ShuffledPropertiesExtraPropertiesAndElements) {
    Ply ply = graphdeco_ply(4, 1);
    std::mt19937 rng(7);
    ply.props.push_back({"uchar", "red"});
    ply.props.push_back({"double", "confidence"});
    ply.props.push_back({"short", "f_other"});
    std::shuffle(ply.props.begin(), ply.props.end(), rng);
    for (auto& row : ply.rows) row["red"] = 200, row["confidence"] = 0.5, row["f_other"] = -3;
    ply.after_header = "element face 2\nproperty list uchar int vertex_indices\nproperty float quality\n";
    for (const std::string format : {"binary_little_endian", "binary_big_endian", "ascii"}) {
        SCOPED_TRACE(format);
        ply.format = format;
        bool big = format == "binary_big_endian";
        // Elements before the vertex must be skipped: a fixed-size one and one with a list.
        ply.before_header =
            "element camera 2\nproperty double fx\nproperty uchar id\n"
            "element edge 2\nproperty list ushort uint ids\nproperty float w\n";
        if (format == "ascii") {
            ply.before_data = "100.5 1\n200.5 2\n3 1 2 3 0.5\n0 0.25\n";
            ply.after_data = "3 0 1 2 0.5\n3 1 2 3 0.25\n";
        } else {
            std::string d;
            for (int i = 0; i < 2; ++i) put(d, 100.5 * (i + 1), big), put(d, std::uint8_t(i), big);
            put(d, std::uint16_t(3), big);
            for (std::uint32_t i : {1u, 2u, 3u}) put(d, i, big);
            put(d, 0.5f, big);
            put(d, std::uint16_t(0), big);
            put(d, 0.25f, big);
            ply.before_data = d;
            std::string after;
            put(after, std::uint8_t(3), big);
            for (std::int32_t i : {0, 1, 2}) put(after, i, big);
            put(after, 0.5f, big);
            put(after, std::uint8_t(3), big);
            for (std::int32_t i : {1, 2, 3}) put(after, i, big);
            put(after, 0.25f, big);
            ply.after_data = after;  // read over, not used (a truncated one is refused: test_scene_io_bad_ply.cpp)
        }
        std::string path = tmp_path(format + ".ply");
        write_file(path, ply.bytes());
        catgs::Scene s = catgs::read_ply(path, absolute());
        ASSERT_EQ(s.count(), 4u);
        EXPECT_EQ(s.sh_degree, 1);
        for (std::size_t g = 0; g < 4; ++g) expect_gaussian(s, g, ply.rows[g]);
    }
}

/// The tools' progress on stderr: a load reports its last chunk and then its end, both at
/// 100%; the line is printed once. A step run again under the same label (rate-limited in
/// between) prints its own 100% line.
TEST(SceneIoPly, StderrProgressPrintsTheFinalLineOnce) {
    const std::string path = tmp_path("progress-once.ply");
    write_file(path, graphdeco_ply(50, 0).bytes());
    catgs::LoadOptions options;
    options.progress = catgs::stderr_progress(true);
    testing::internal::CaptureStderr();
    catgs::read_ply(path, options);
    options.progress(0.5, "another step");
    options.progress(1.0, "another step");
    options.progress(1.0, "another step");
    options.progress(0.0, "another step");
    options.progress(1.0, "another step");
    const std::string out = testing::internal::GetCapturedStderr();
    const std::string line = "loading " + std::filesystem::path(path).filename().string() + ": 100%\n";
    ASSERT_NE(out.find(line), std::string::npos) << out;
    EXPECT_EQ(out.find(line, out.find(line) + 1), std::string::npos) << out;
    EXPECT_EQ(out.substr(out.find("another step")), "another step:  50%\nanother step: 100%\nanother step: 100%\n");
}

TEST(SceneIoPly, ShDegreeOneChannelMajorByHand) {
    Ply ply = graphdeco_ply(1, 1);
    Row& r = ply.rows[0];
    r["f_dc_0"] = 1, r["f_dc_1"] = 2, r["f_dc_2"] = 3;
    for (int j = 0; j < 9; ++j) r["f_rest_" + std::to_string(j)] = 10 + j;
    std::string path = tmp_path("deg1.ply");
    write_file(path, ply.bytes());
    catgs::Scene s = catgs::read_ply(path);
    // [coefficient][rgb]: coefficient k of red is f_rest_{k-1}, of green f_rest_{3+k-1}, of blue f_rest_{6+k-1}.
    EXPECT_EQ(s.sh, (std::vector<float>{1, 2, 3, 10, 13, 16, 11, 14, 17, 12, 15, 18}));
}

TEST(SceneIoPly, ShDegreesZeroToThreeChannelMajor) {
    for (int degree = 0; degree <= catgs::kMaxShDegree; ++degree) {
        SCOPED_TRACE("degree " + std::to_string(degree));
        Ply ply = graphdeco_ply(3, degree);
        std::string path = tmp_path("deg" + std::to_string(degree) + ".ply");
        write_file(path, ply.bytes());
        catgs::Scene s = catgs::read_ply(path, absolute());
        ASSERT_EQ(s.sh_degree, degree);
        const std::size_t k = static_cast<std::size_t>(catgs::sh_coefficient_count(degree));
        ASSERT_EQ(s.sh.size(), 3 * 3 * k);
        for (std::size_t g = 0; g < 3; ++g) expect_gaussian(s, g, ply.rows[g]);
        if (degree == 3) {
            // Gaussian 2: f_rest_j = 2000 + j. Blue's last coefficient (15) is f_rest_{2*15+14}.
            EXPECT_EQ(s.sh[2 * 48 + 3 * 15 + 2], 2044.0f);
            EXPECT_EQ(s.sh[2 * 48 + 3 * 1 + 1], 2015.0f);  // green coefficient 1 = f_rest_15
            EXPECT_EQ(s.sh[2 * 48 + 3 * 2 + 0], 2001.0f);  // red coefficient 2 = f_rest_1
        }
    }
}

TEST(SceneIoPly, RecentreUsesDoubleBoundsForUtmCoordinates) {
    Ply ply = graphdeco_ply(3, 0);
    for (auto& p : ply.props)
        if (p.name == "x" || p.name == "y" || p.name == "z") p.type = "double";
    // None of these is a float: a float at 4.5e6 has a grain of 0.5 m.
    ply.rows[0]["x"] = 4500000.03, ply.rows[1]["x"] = 4500100.07, ply.rows[2]["x"] = 4500012.345678;
    ply.rows[0]["y"] = 5400000.2, ply.rows[1]["y"] = 5400001.1, ply.rows[2]["y"] = 5400000.7;
    std::string path = tmp_path("utm.ply");
    write_file(path, ply.bytes());
    catgs::Scene s = catgs::read_ply(path);
    EXPECT_NEAR(s.origin[0], 4500050.05, 1e-8);
    EXPECT_EQ(s.origin[0], 0.5 * (4500000.03 + 4500100.07));
    EXPECT_EQ(s.origin[1], 0.5 * (5400000.2 + 5400001.1));
    EXPECT_EQ(s.positions[0], static_cast<float>(4500000.03 - s.origin[0]));
    EXPECT_EQ(s.positions[3 * 2 + 0], static_cast<float>(4500012.345678 - s.origin[0]));
    EXPECT_EQ(s.positions[3 * 2 + 1], static_cast<float>(5400000.7 - s.origin[1]));
    // A float of the absolute coordinate would be up to 0.25 m off; the offset keeps micrometres.
    EXPECT_NEAR(s.origin[0] + s.positions[6], 4500012.345678, 1e-5);
    EXPECT_NEAR(s.bounds.max[0], 4500100.07, 1e-5);
}

// Found by fuzzing (fuzz_ply): double components below ~1e-154 have a subnormal norm^2 that
// kept only a few bits, and the "normalised" quaternion was off unit length by ~1e-4.
TEST(SceneIoPly, TinyQuaternionsAreNormalised) {
    Ply ply = graphdeco_ply(1, 0, "binary_little_endian", "double");
    ply.rows[0]["rot_0"] = 1e-200;
    ply.rows[0]["rot_1"] = 1.5e-160;
    ply.rows[0]["rot_2"] = -1.5e-160;
    ply.rows[0]["rot_3"] = 0.0;
    const std::string path = tmp_path("tiny.ply");
    write_file(path, ply.bytes());
    const catgs::Scene s = catgs::read_ply(path, absolute());
    ASSERT_EQ(s.count(), 1u);
    EXPECT_EQ(s.rotations[1], static_cast<float>(std::sqrt(0.5)));
    EXPECT_EQ(s.rotations[2], -static_cast<float>(std::sqrt(0.5)));
    EXPECT_EQ(s.rotations[3], 0.0f);
    double norm2 = 0;
    for (int c = 0; c < 4; ++c) norm2 += double{s.rotations[c]} * s.rotations[c];
    EXPECT_NEAR(norm2, 1.0, 1e-6);
}

}  // namespace
