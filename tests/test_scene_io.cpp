// Scene readers and writer: graphdeco PLY (binary LE/BE, ASCII), .splat, write_ply round
// trips, load_scene dispatch, and every bad-input case with the message it must give.
// Fixtures are generated here into CATGS_TEST_TMP; file names carry the test name so that
// tests run in parallel processes do not collide.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"
#include "test_util.hpp"

namespace {

using ::testing::HasSubstr;
namespace fs = std::filesystem;

static_assert(std::endian::native == std::endian::little, "the fixture writer assumes a little-endian host");

constexpr double kSqrtPi = 1.7724538509055159;  // (1 - 0.5) / C0 for a colour byte of 255

// ---------------------------------------------------------------------------------------
// Files.

std::string tmp_path(const std::string& name) {
    fs::create_directories(CATGS_TEST_TMP);
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    return std::string(CATGS_TEST_TMP) + "/scene_io_" + info->name() + "_" + name;
}

void write_file(const std::string& path, const std::string& bytes) {
    // A new file, not a truncated one: ext4 flushes a truncated-and-rewritten file on close,
    // which makes the thousands of rewrites of the robustness test wait on the disk.
    fs::remove(path);
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    ASSERT_TRUE(out.good()) << path;
}

std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

/// Runs f and returns the catgs::Error message; fails the test on no exception or another type.
std::string error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const catgs::Error& e) {
        return e.what();
    } catch (const std::exception& e) {
        ADD_FAILURE() << "expected catgs::Error, got another exception: " << e.what();
        return "";
    }
    ADD_FAILURE() << "expected catgs::Error, nothing was thrown";
    return "";
}

/// The message names the file, is one line, and contains every part.
void expect_error(const std::function<void()>& f, const std::string& path, const std::vector<std::string>& parts) {
    std::string message = error_of(f);
    EXPECT_THAT(message, ::testing::StartsWith(path + ": "));
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    for (const auto& part : parts) EXPECT_THAT(message, HasSubstr(part));
}

catgs::LoadOptions absolute() {
    catgs::LoadOptions options;
    options.recentre = false;
    return options;
}

catgs::LoadOptions dropping() {
    catgs::LoadOptions options;
    options.recentre = false;
    options.drop_invalid = true;
    return options;
}

// ---------------------------------------------------------------------------------------
// PLY fixtures.

struct Prop {
    std::string type;
    std::string name;
};
using Row = std::map<std::string, double>;

template <typename T>
void put(std::string& out, T value, bool big_endian) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    if (big_endian) std::reverse(bytes, bytes + sizeof(T));
    out.append(bytes, sizeof(T));
}

void put_value(std::string& out, const std::string& type, double v, bool big_endian) {
    if (type == "float" || type == "float32") return put(out, static_cast<float>(v), big_endian);
    if (type == "double" || type == "float64") return put(out, v, big_endian);
    if (type == "char" || type == "int8") return put(out, static_cast<std::int8_t>(v), big_endian);
    if (type == "uchar" || type == "uint8") return put(out, static_cast<std::uint8_t>(v), big_endian);
    if (type == "short" || type == "int16") return put(out, static_cast<std::int16_t>(v), big_endian);
    if (type == "ushort" || type == "uint16") return put(out, static_cast<std::uint16_t>(v), big_endian);
    if (type == "int" || type == "int32") return put(out, static_cast<std::int32_t>(v), big_endian);
    if (type == "uint" || type == "uint32") return put(out, static_cast<std::uint32_t>(v), big_endian);
    ADD_FAILURE() << "fixture: unknown type " << type;
}

std::string ascii_value(const std::string& type, double v) {
    char text[64];
    if (type == "float" || type == "float32") {
        std::snprintf(text, sizeof(text), "%.9g", static_cast<double>(static_cast<float>(v)));
    } else if (type == "double" || type == "float64") {
        std::snprintf(text, sizeof(text), "%.17g", v);
    } else {
        std::snprintf(text, sizeof(text), "%lld", static_cast<long long>(v));
    }
    return text;
}

struct Ply {
    std::string format = "binary_little_endian";
    std::vector<Prop> props;
    std::vector<Row> rows;
    std::optional<std::string> count;        ///< overrides the declared vertex count
    std::string before_header, before_data;  ///< elements before the vertex element
    std::string after_header, after_data;    ///< elements after it
    std::string newline = "\n";

    std::string header() const {
        std::string h = "ply" + newline + "format " + format + " 1.0" + newline + "comment fixture" + newline;
        h += before_header;
        h += "element vertex " + count.value_or(std::to_string(rows.size())) + newline;
        for (const auto& p : props) h += "property " + p.type + " " + p.name + newline;
        h += after_header;
        return h + "end_header" + newline;
    }

    std::string data() const {
        std::string d;
        for (const auto& row : rows) {
            for (std::size_t i = 0; i < props.size(); ++i) {
                auto it = row.find(props[i].name);
                double v = it == row.end() ? 0.0 : it->second;
                if (format == "ascii") {
                    if (i > 0) d += ' ';
                    d += ascii_value(props[i].type, v);
                } else {
                    put_value(d, props[i].type, v, format == "binary_big_endian");
                }
            }
            if (format == "ascii") d += newline;
        }
        return d;
    }

    std::string bytes() const { return header() + before_data + data() + after_data; }
};

std::vector<Prop> graphdeco_props(int degree, const std::string& type = "float") {
    std::vector<Prop> props;
    for (const char* n : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"}) props.push_back({type, n});
    const int rest = 3 * (catgs::sh_coefficient_count(degree) - 1);
    for (int j = 0; j < rest; ++j) props.push_back({type, "f_rest_" + std::to_string(j)});
    for (const char* n : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
        props.push_back({type, n});
    return props;
}

/// Distinct, exactly float-representable values per record and property.
Row gaussian(int i, int degree) {
    Row r;
    r["x"] = i + 0.25;
    r["y"] = -2.0 * i - 0.5;
    r["z"] = 0.125 * i;
    for (int c = 0; c < 3; ++c) r["f_dc_" + std::to_string(c)] = 0.5 * c - i;
    const int rest = 3 * (catgs::sh_coefficient_count(degree) - 1);
    for (int j = 0; j < rest; ++j) r["f_rest_" + std::to_string(j)] = 1000.0 * i + j;
    r["opacity"] = 0.25 * i;
    for (int a = 0; a < 3; ++a) r["scale_" + std::to_string(a)] = -1.0 - 0.5 * a + 0.125 * i;
    r["rot_0"] = 1.0 + i;
    r["rot_1"] = 0.5;
    r["rot_2"] = -0.25;
    r["rot_3"] = 0.125 * i;
    return r;
}

Ply graphdeco_ply(int records, int degree, const std::string& format = "binary_little_endian",
                  const std::string& type = "float") {
    Ply ply;
    ply.format = format;
    ply.props = graphdeco_props(degree, type);
    for (int i = 0; i < records; ++i) ply.rows.push_back(gaussian(i, degree));
    return ply;
}

/// The value as the file holds it (rounded to float for float properties).
double stored(const Row& row, const std::string& name, bool as_float) {
    double v = row.at(name);
    return as_float ? static_cast<double>(static_cast<float>(v)) : v;
}

/// Checks Gaussian g (loaded with recentre off) against the activation rules of the issue.
void expect_gaussian(const catgs::Scene& s, std::size_t g, const Row& row, bool as_float = true) {
    SCOPED_TRACE("gaussian " + std::to_string(g));
    auto v = [&](const std::string& name) { return stored(row, name, as_float); };
    for (int a = 0; a < 3; ++a) {
        EXPECT_EQ(s.positions[3 * g + a], static_cast<float>(v(std::string(1, "xyz"[a]))));
        EXPECT_EQ(s.scales[3 * g + a], static_cast<float>(std::exp(v("scale_" + std::to_string(a)))));
    }
    EXPECT_EQ(s.opacities[g], static_cast<float>(1.0 / (1.0 + std::exp(-v("opacity")))));
    double q[4], n2 = 0;
    for (int c = 0; c < 4; ++c) {
        q[c] = v("rot_" + std::to_string(c));
        n2 += q[c] * q[c];
    }
    for (int c = 0; c < 4; ++c) EXPECT_EQ(s.rotations[4 * g + c], static_cast<float>(q[c] / std::sqrt(n2)));
    const int k_count = s.sh_coefficients();
    for (int k = 0; k < k_count; ++k)
        for (int c = 0; c < 3; ++c) {
            std::string name =
                k == 0 ? "f_dc_" + std::to_string(c) : "f_rest_" + std::to_string(c * (k_count - 1) + (k - 1));
            EXPECT_EQ(s.sh[g * s.sh_floats_per_gaussian() + 3 * k + c], static_cast<float>(v(name))) << name;
        }
}

void expect_same_scene(const catgs::Scene& a, const catgs::Scene& b) {
    EXPECT_EQ(a.sh_degree, b.sh_degree);
    EXPECT_EQ(a.origin, b.origin);
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.scales, b.scales);
    EXPECT_EQ(a.rotations, b.rotations);
    EXPECT_EQ(a.opacities, b.opacities);
    EXPECT_EQ(a.sh, b.sh);
}

// ---------------------------------------------------------------------------------------
// .splat fixtures.

struct SplatRecord {
    std::array<float, 3> position{0, 0, 0};
    std::array<float, 3> scale{1, 1, 1};
    std::array<std::uint8_t, 4> rgba{128, 128, 128, 255};
    std::array<std::uint8_t, 4> quaternion{255, 128, 128, 128};
};

std::string splat_bytes(const std::vector<SplatRecord>& records) {
    std::string out;
    for (const auto& r : records) {
        for (float v : r.position) put(out, v, false);
        for (float v : r.scale) put(out, v, false);
        out.append(reinterpret_cast<const char*>(r.rgba.data()), 4);
        out.append(reinterpret_cast<const char*>(r.quaternion.data()), 4);
    }
    return out;
}

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
            ply.after_data = after;  // truncated face data: ignored, it follows the vertices
        }
        std::string path = tmp_path(format + ".ply");
        write_file(path, ply.bytes());
        catgs::Scene s = catgs::read_ply(path, absolute());
        ASSERT_EQ(s.count(), 4u);
        EXPECT_EQ(s.sh_degree, 1);
        for (std::size_t g = 0; g < 4; ++g) expect_gaussian(s, g, ply.rows[g]);
    }
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

// =======================================================================================
// .splat.

TEST(SceneIoSplat, DecodesHandComputedValues) {
    std::vector<SplatRecord> records(4);
    records[0] = {{1.5f, -2.25f, 1e-3f}, {0.5f, 0.25f, 0.0f}, {255, 0, 128, 255}, {255, 128, 128, 128}};
    records[1] = {{0, 0, 0}, {1, 1, 1}, {128, 128, 128, 51}, {192, 192, 128, 128}};
    records[2] = {{0, 0, 0}, {1, 1, 1}, {128, 128, 128, 0}, {0, 128, 128, 128}};  // transparent
    records[3] = {{0, 0, 0}, {1, 1, 1}, {128, 128, 128, 1}, {0, 128, 128, 128}};  // 1/255: kept
    std::string path = tmp_path("hand.splat");
    write_file(path, splat_bytes(records));
    catgs::LoadReport report;
    catgs::Scene s = catgs::read_splat(path, absolute(), &report);
    EXPECT_EQ(report.records, 4u);
    EXPECT_EQ(report.dropped_transparent, 1u);
    EXPECT_EQ(report.dropped_invalid, 0u);
    ASSERT_EQ(s.count(), 3u);
    EXPECT_EQ(s.sh_degree, 0);
    EXPECT_EQ(std::vector<float>(s.positions.begin(), s.positions.begin() + 3),
              (std::vector<float>{1.5f, -2.25f, 1e-3f}));
    EXPECT_EQ(std::vector<float>(s.scales.begin(), s.scales.begin() + 3), (std::vector<float>{0.5f, 0.25f, 0.0f}));
    EXPECT_FLOAT_EQ(s.sh[0], static_cast<float>(kSqrtPi));
    EXPECT_FLOAT_EQ(s.sh[1], static_cast<float>(-kSqrtPi));
    EXPECT_FLOAT_EQ(s.sh[2], 0.0069508f);  // (128/255 - 0.5) / 0.28209479
    EXPECT_EQ(s.sh[0], static_cast<float>((255 / 255.0 - 0.5) / 0.28209479177387814));
    EXPECT_EQ(s.sh[2], static_cast<float>((128 / 255.0 - 0.5) / 0.28209479177387814));
    EXPECT_EQ(s.opacities, (std::vector<float>{1.0f, 0.2f, static_cast<float>(1 / 255.0)}));
    // (255-128)/128 normalises to 1; (64, 64, 0, 0)/128 to 1/sqrt(2); 0 decodes to -1.
    EXPECT_EQ(s.rotations, (std::vector<float>{1, 0, 0, 0, 0.70710677f, 0.70710677f, 0, 0, -1, 0, 0, 0}));
}

TEST(SceneIoSplat, SizeNotMultipleOf32) {
    std::string path = tmp_path("odd.splat");
    write_file(path, splat_bytes({SplatRecord{}, SplatRecord{}}) + "abcde");
    expect_error([&] { catgs::read_splat(path); }, path,
                 {"69", "not a multiple", "5 trailing bytes", "byte offset 64"});
}

TEST(SceneIoSplat, EmptyFileHasNoGaussians) {
    std::string path = tmp_path("empty.splat");
    write_file(path, "");
    expect_error([&] { catgs::read_splat(path); }, path, {"no Gaussians", "empty", "byte offset 0"});
}

TEST(SceneIoSplat, InvalidRecords) {
    std::vector<SplatRecord> records(5);
    records[1].position[1] = std::numeric_limits<float>::quiet_NaN();
    records[3].quaternion = {128, 128, 128, 128};  // decodes to a zero quaternion
    std::string path = tmp_path("bad.splat");
    write_file(path, splat_bytes(records));
    expect_error([&] { catgs::read_splat(path); }, path, {"non-finite value nan", "record 1", "'y'"});
    records[1].position[1] = 0;
    write_file(path, splat_bytes(records));
    expect_error([&] { catgs::read_splat(path); }, path, {"zero-norm quaternion", "record 3, fields 'rot_0'..'rot_3'"});
    records[1].scale[2] = std::numeric_limits<float>::infinity();
    write_file(path, splat_bytes(records));
    catgs::LoadReport report;
    catgs::Scene s = catgs::read_splat(path, dropping(), &report);
    EXPECT_EQ(s.count(), 3u);
    EXPECT_EQ(report.records, 5u);
    EXPECT_EQ(report.dropped_invalid, 2u);
}

// =======================================================================================
// write_ply.

/// Rounded to a multiple of 2^-20 so that origin +- extent is exact in double and the reader's
/// bounds centre reproduces the origin bit for bit.
double grid(double v) { return std::round(std::ldexp(v, 20)) / std::ldexp(1.0, 20); }

catgs::Scene random_scene(std::mt19937_64& rng, int degree, std::array<double, 3> origin, float extent, std::size_t n) {
    catgs::Scene s;
    s.sh_degree = degree;
    s.resize(n);
    s.origin = origin;
    std::uniform_real_distribution<float> position(-extent, extent);
    std::uniform_real_distribution<double> log_scale(-12.0, 2.0);
    std::uniform_real_distribution<double> opacity(0.004, 1.0);
    std::normal_distribution<double> normal;
    for (std::size_t i = 0; i < n; ++i) {
        for (int a = 0; a < 3; ++a) {
            s.positions[3 * i + a] = position(rng);
            s.scales[3 * i + a] = static_cast<float>(std::exp(log_scale(rng)));
        }
        double q[4], n2 = 0;
        for (double& c : q) {
            c = normal(rng);
            n2 += c * c;
        }
        for (int c = 0; c < 4; ++c) s.rotations[4 * i + c] = static_cast<float>(q[c] / std::sqrt(n2));
        s.opacities[i] = static_cast<float>(opacity(rng));
        for (std::size_t k = 0; k < s.sh_floats_per_gaussian(); ++k)
            s.sh[i * s.sh_floats_per_gaussian() + k] = static_cast<float>(normal(rng));
    }
    // Extremes on every axis, so that the bounds centre is the origin.
    for (int a = 0; a < 3; ++a) s.positions[a] = -extent, s.positions[3 + a] = extent;
    s.opacities[0] = 1.0f;   // .splat alpha 255: logit is +inf before clamping
    s.scales[3 * 2] = 0.0f;  // .splat may hold a zero scale: log is -inf before clamping
    s.update_bounds();
    return s;
}

/// A fresh seed per run (CATGS_TEST_SEED replays one), also recorded in the XML report.
std::uint64_t fresh_seed() {
    const std::uint64_t seed = catgs::test::fresh_seed(::testing::UnitTest::GetInstance()->current_test_info()->name());
    ::testing::Test::RecordProperty("seed", std::to_string(seed));
    return seed;
}

TEST(SceneIoWritePly, RoundTripIsExact) {
    const std::uint64_t seed = fresh_seed();
    SCOPED_TRACE("CATGS_TEST_SEED=" + std::to_string(seed));
    std::mt19937_64 rng(seed);
    for (int degree = 0; degree <= catgs::kMaxShDegree; ++degree) {
        SCOPED_TRACE("degree " + std::to_string(degree));
        // Origin 0 with recentre off: world = position exactly.
        catgs::Scene s = random_scene(rng, degree, {0, 0, 0}, 50.0f, 500);
        std::string path = tmp_path("rt" + std::to_string(degree) + ".ply");
        catgs::write_ply(s, path);
        catgs::LoadReport report;
        catgs::Scene back = catgs::read_ply(path, absolute(), &report);
        EXPECT_EQ(report.records, 500u);
        EXPECT_EQ(report.dropped_transparent + report.dropped_invalid, 0u);
        expect_same_scene(back, s);
        EXPECT_EQ(back.bounds.min, s.bounds.min);
        EXPECT_EQ(back.bounds.max, s.bounds.max);
        // Small non-zero origin with recentre on: the reader finds the same origin.
        catgs::Scene centred = random_scene(rng, degree, {grid(1.7), grid(-0.3), grid(12.1)}, 2.0f, 300);
        catgs::write_ply(centred, path);
        back = catgs::read_ply(path);
        expect_same_scene(back, centred);
    }
}

TEST(SceneIoWritePly, RoundTripWithUtmOriginKeepsWhatDoubleWorldCanHold) {
    const std::uint64_t seed = fresh_seed();
    SCOPED_TRACE("CATGS_TEST_SEED=" + std::to_string(seed));
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> jitter(0.0, 1000.0);
    const std::array<double, 3> origin{grid(4.5e6 + jitter(rng)), grid(5.4e6 + jitter(rng)), grid(120.0 + jitter(rng))};
    catgs::Scene s = random_scene(rng, 3, origin, 100.0f, 2000);
    s.positions[3 * 5] = 1e-6f;  // below the grain of a double at 4.5e6 (2^-30 m): cannot survive
    std::string path = tmp_path("utm.ply");
    catgs::write_ply(s, path);
    catgs::Scene back = catgs::read_ply(path);
    EXPECT_EQ(back.origin, s.origin);
    EXPECT_EQ(back.scales, s.scales);
    EXPECT_EQ(back.rotations, s.rotations);
    EXPECT_EQ(back.opacities, s.opacities);
    EXPECT_EQ(back.sh, s.sh);
    // The file holds world = origin + position in double. Guaranteed: the reader returns
    // float(world - origin), which is the position itself whenever |position| >= 2^-7 (its
    // float grain is then no finer than the double grain at the origin, 2^-30).
    std::size_t exact = 0;
    for (std::size_t i = 0; i < s.positions.size(); ++i) {
        const float p = s.positions[i];
        const double o = s.origin[i % 3];
        const float guaranteed = static_cast<float>((o + static_cast<double>(p)) - o);
        ASSERT_EQ(back.positions[i], guaranteed) << "index " << i;
        if (std::fabs(p) >= 0x1p-7f) {
            ASSERT_EQ(back.positions[i], p) << "index " << i;
        }
        exact += back.positions[i] == p;
    }
    EXPECT_NE(back.positions[3 * 5], 1e-6f);  // the documented limit, so this test can tell
    EXPECT_GE(exact, s.positions.size() - 30);
}

TEST(SceneIoWritePly, RoundTripOfDecodedSplat) {
    std::vector<SplatRecord> records(3);
    records[0].scale = {0.0f, 1e-12f, 0.3f};
    records[1].rgba = {10, 20, 30, 255};
    records[2].quaternion = {200, 100, 50, 25};
    std::string splat = tmp_path("in.splat");
    write_file(splat, splat_bytes(records));
    catgs::Scene s = catgs::read_splat(splat);
    std::string ply = tmp_path("out.ply");
    catgs::write_ply(s, ply);
    expect_same_scene(catgs::read_ply(ply), s);
}

TEST(SceneIoWritePly, LayoutIsGraphdecoWithDoubles) {
    std::mt19937_64 rng(3);
    catgs::Scene s = random_scene(rng, 1, {0, 0, 0}, 1.0f, 10);
    std::string path = tmp_path("layout.ply");
    catgs::write_ply(s, path);
    std::string bytes = read_file(path);
    const std::string expected_header =
        "ply\nformat binary_little_endian 1.0\ncomment written by catgs\nelement vertex 10\n"
        "property double x\nproperty double y\nproperty double z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n"
        "property float f_rest_0\nproperty float f_rest_1\nproperty float f_rest_2\nproperty float f_rest_3\n"
        "property float f_rest_4\nproperty float f_rest_5\nproperty float f_rest_6\nproperty float f_rest_7\n"
        "property float f_rest_8\nproperty double opacity\n"
        "property double scale_0\nproperty double scale_1\nproperty double scale_2\n"
        "property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\nend_header\n";
    ASSERT_EQ(bytes.substr(0, expected_header.size()), expected_header);
    const std::size_t stride = 3 * 8 + 3 * 4 + 3 * 4 + 9 * 4 + 8 + 3 * 8 + 4 * 4;
    ASSERT_EQ(bytes.size(), expected_header.size() + 10 * stride);
    // Gaussian 3, f_rest_4 = green coefficient 2 (channel-major: 1 * (4 - 1) + (2 - 1)).
    float f_rest_4;
    std::memcpy(&f_rest_4, bytes.data() + expected_header.size() + 3 * stride + 3 * 8 + 6 * 4 + 4 * 4, 4);
    EXPECT_EQ(f_rest_4, s.sh[3 * 12 + 3 * 2 + 1]);
    double scale_1;
    std::memcpy(&scale_1, bytes.data() + expected_header.size() + 3 * stride + stride - 16 - 16, 8);
    EXPECT_EQ(scale_1, std::log(static_cast<double>(s.scales[3 * 3 + 1])));
}

TEST(SceneIoWritePly, ErrorsNameThePathAndReason) {
    std::mt19937_64 rng(4);
    catgs::Scene s = random_scene(rng, 0, {0, 0, 0}, 1.0f, 10);
    const std::string missing_dir = std::string(CATGS_TEST_TMP) + "/no_such_dir/x.ply";
    expect_error([&] { catgs::write_ply(s, missing_dir); }, missing_dir,
                 {"cannot open for writing", "No such file or directory"});
    if (fs::exists("/dev/full"))
        expect_error([&] { catgs::write_ply(s, "/dev/full"); }, "/dev/full", {"cannot write", "No space left"});
    s.opacities.pop_back();
    expect_error([&] { catgs::write_ply(s, tmp_path("x.ply")); }, tmp_path("x.ply"), {"positions"});
}

// =======================================================================================
// Bad input: header.

void expect_ply_error(const std::string& bytes, const std::vector<std::string>& parts,
                      const std::string& name = "bad.ply") {
    std::string path = tmp_path(name);
    write_file(path, bytes);
    expect_error([&] { catgs::read_ply(path); }, path, parts);
}

TEST(SceneIoBadPly, NotAPly) {
    expect_ply_error("PK\x03\x04 this is a zip", {"not a PLY file", "byte offset 0"});
    expect_ply_error("", {"not a PLY file", "byte offset 0"});
    expect_ply_error("plyx\n", {"not a PLY file"});
}

TEST(SceneIoBadPly, MissingEndHeader) {
    std::string header = graphdeco_ply(1, 0).header();
    header = header.substr(0, header.find("end_header"));
    expect_ply_error(header, {"header ends without end_header", "byte offset " + std::to_string(header.size())});
}

TEST(SceneIoBadPly, HeaderTooLargeIsBounded) {
    std::string bytes = "ply\nformat binary_little_endian 1.0\n";
    const std::string comment = "comment " + std::string(100, 'c') + "\n";
    while (bytes.size() < (std::size_t{3} << 20)) bytes += comment;
    expect_ply_error(bytes, {"no end_header within the first 1048576 bytes", "byte offset 1048576"});
}

TEST(SceneIoBadPly, HeaderLineTooLong) {
    expect_ply_error("ply\nformat ascii 1.0\ncomment " + std::string(10000, 'x') + "\nend_header\n",
                     {"header line longer than 8192 bytes", "header line 3"});
    // A binary blob after the magic has no newline for megabytes.
    expect_ply_error("ply\n" + std::string(std::size_t{2} << 20, '\x01'), {"header line longer", "header line 2"});
}

TEST(SceneIoBadPly, UnknownFormat) {
    Ply ply = graphdeco_ply(1, 0, "binary_middle_endian");
    expect_ply_error(ply.bytes(), {"unknown format 'binary_middle_endian'", "header line 2"});
    std::string v2 = graphdeco_ply(1, 0).bytes();
    v2.replace(v2.find("1.0"), 3, "2.0");
    expect_ply_error(v2, {"unknown format 'format binary_little_endian 2.0'", "header line 2"});
    std::string none = graphdeco_ply(1, 0).bytes();
    none.erase(none.find("format"), std::string("format binary_little_endian 1.0\n").size());
    expect_ply_error(none, {"no format line", "header line"});
}

TEST(SceneIoBadPly, UnknownPropertyType) {
    std::string bytes = graphdeco_ply(1, 0).bytes();
    bytes.replace(bytes.find("float ny"), 5, "float16");
    expect_ply_error(bytes, {"unknown property type 'float16'", "'ny'", "header line 9"});
}

TEST(SceneIoBadPly, ListPropertyInVertex) {
    std::string header = graphdeco_ply(1, 0).header();
    header.insert(header.find("end_header"), "property list uchar float normals\n");
    expect_ply_error(header, {"list property 'normals'", "vertex element", "not supported", "header line"});
}

TEST(SceneIoBadPly, MalformedHeaderLines) {
    const std::string base = graphdeco_ply(1, 0).bytes();
    auto with = [&](const std::string& from, const std::string& to) {
        std::string b = base;
        b.replace(b.find(from), from.size(), to);
        return b;
    };
    expect_ply_error(with("element vertex 1", "element vertex"),
                     {"malformed header line 'element vertex'", "header line 4"});
    expect_ply_error(with("element vertex 1", "element vertex -1"),
                     {"malformed element line", "'-1'", "header line 4"});
    expect_ply_error(with("element vertex 1", "element vertex 1x"), {"malformed element line", "header line 4"});
    expect_ply_error(with("element vertex 1", "element vertex 18446744073709551616"),
                     {"not a non-negative 64-bit integer", "header line 4"});
    expect_ply_error(with("property float x", "property float"),
                     {"malformed header line 'property float'", "header line 5"});
    expect_ply_error(with("property float x", "property float x y"), {"malformed header line", "header line 5"});
    expect_ply_error(with("property float x", "property list uchar x"), {"malformed header line", "header line 5"});
    expect_ply_error(with("comment fixture", "property float q"),
                     {"property line before any element", "header line 3"});
    expect_ply_error(with("comment fixture", "colour red"), {"unknown header keyword 'colour'", "header line 3"});
    expect_ply_error(with("end_header", "end_header now"), {"malformed header line", "end_header"});
    expect_ply_error(with("element vertex 1", "element points 1"), {"no vertex element"});
    expect_ply_error(with("comment fixture", "element vertex 0"), {"second vertex element", "header line 4"});
    expect_ply_error(with("comment fixture", "format ascii 1.0"), {"second format line", "header line 3"});
    std::string face = with("comment fixture", "element face 1\nproperty list float int idx");
    expect_ply_error(face, {"list count type 'float'", "'idx'", "not an integer type", "header line 4"});
}

TEST(SceneIoBadPly, MissingRequiredProperties) {
    Ply ply = graphdeco_ply(1, 0);
    std::erase_if(ply.props, [](const Prop& p) { return p.name == "opacity" || p.name == "rot_3" || p.name == "x"; });
    expect_ply_error(ply.bytes(),
                     {"missing required properties 'x', 'opacity', 'rot_3'", "vertex element", "header line 4"});
    Ply one = graphdeco_ply(1, 0);
    std::erase_if(one.props, [](const Prop& p) { return p.name == "f_dc_2"; });
    expect_ply_error(one.bytes(), {"missing required property 'f_dc_2'"});
}

TEST(SceneIoBadPly, FRestCountAndGaps) {
    Ply ten = graphdeco_ply(1, 1);
    ten.props.push_back({"float", "f_rest_9"});
    expect_ply_error(ten.bytes(), {"10 f_rest_* properties", "expected 0, 9, 24 or 45", "header line 4"});
    Ply gap = graphdeco_ply(1, 1);
    for (auto& p : gap.props)
        if (p.name == "f_rest_4") p.name = "f_rest_12";
    expect_ply_error(gap.bytes(), {"missing required property 'f_rest_4'"});
    Ply duplicate = graphdeco_ply(1, 0);
    duplicate.props.push_back({"float", "scale_1"});
    expect_ply_error(duplicate.bytes(), {"duplicate property 'scale_1'"});
}

// =======================================================================================
// Bad input: counts and data.

TEST(SceneIoBadPly, ZeroVertices) {
    Ply ply = graphdeco_ply(0, 0);
    expect_ply_error(ply.bytes(), {"no Gaussians", "0 records", "header line 4"});
}

TEST(SceneIoBadPly, TruncatedBinary) {
    Ply ply = graphdeco_ply(10, 0);
    std::string bytes = ply.bytes();
    bytes.pop_back();
    const std::size_t stride = 17 * 4;
    expect_ply_error(bytes, {"element 'vertex' declares 10 records", "need " + std::to_string(10 * stride) + " bytes",
                             "only " + std::to_string(10 * stride - 1) + " bytes follow",
                             "byte offset " + std::to_string(ply.header().size())});
    ply.count = "11";
    expect_ply_error(ply.bytes(), {"declares 11 records"});
}

TEST(SceneIoBadPly, HugeCountsFailFastWithoutAllocating) {
    for (const std::string format : {"binary_little_endian", "ascii"}) {
        SCOPED_TRACE(format);
        Ply ply = graphdeco_ply(2, 3, format);
        ply.count = "1000000000000";
        auto start = std::chrono::steady_clock::now();
        expect_ply_error(ply.bytes(), {"declares 1000000000000 records", "bytes follow", "byte offset"});
        EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
        ply.count = "18446744073709551615";
        expect_ply_error(ply.bytes(), {"declares 18446744073709551615 records: too many", "header line 4"});
        ply.count = "3074457345618258603";  // * 62 * 4 wraps to a small number in 64 bits
        expect_ply_error(ply.bytes(), {"too many"});
    }
    // An element before the vertex with a huge count: fixed size and walked (list) variants.
    Ply before = graphdeco_ply(2, 0);
    before.before_header = "element camera 1000000000000\nproperty double fx\n";
    expect_ply_error(before.bytes(), {"element 'camera' declares 1000000000000 records"});
    before.before_header = "element edge 1000000000000\nproperty list uchar int ids\n";
    expect_ply_error(before.bytes(), {"data ends inside element 'edge'", "record", "'ids'"});
    before.before_header = "element edge 2\nproperty list uint int ids\n";
    before.before_data = std::string("\xff\xff\xff\x0f", 4);
    expect_ply_error(before.bytes(), {"data ends inside element 'edge'", "record 0, property 'ids'"});
    before.before_header = "element edge 2\nproperty list int int ids\n";
    before.before_data = std::string("\xff\xff\xff\xff", 4);
    expect_ply_error(before.bytes(), {"negative list length -1", "record 0, property 'ids'"});
}

// LoadOptions::max_records (the fuzz targets' allocation cap): a file that declares more
// records is refused before anything is allocated for it; the default changes nothing.
TEST(SceneIoLimits, MaxRecordsRefusesLargerFiles) {
    const std::string ply = tmp_path("limit.ply");
    write_file(ply, graphdeco_ply(3, 0).bytes());
    catgs::LoadOptions options;
    EXPECT_EQ(options.max_records, std::numeric_limits<std::uint64_t>::max());
    options.max_records = 2;
    expect_error([&] { catgs::read_ply(ply, options); }, ply,
                 {"3 records exceed the limit of 2", "(LoadOptions::max_records)"});
    options.max_records = 3;
    EXPECT_EQ(catgs::read_ply(ply, options).count(), 3u);

    const std::string splat = tmp_path("limit.splat");
    write_file(splat, splat_bytes({SplatRecord{}, SplatRecord{}}));
    options.max_records = 1;
    expect_error([&] { catgs::read_splat(splat, options); }, splat,
                 {"2 records exceed the limit of 1", "(LoadOptions::max_records)"});
}

TEST(SceneIoBadPly, AsciiMissingExtraAndUnparsableValues) {
    Ply ply = graphdeco_ply(5, 0, "ascii");
    const std::string header = ply.header();
    std::string data = ply.data();
    auto line_start = [&](int record) {
        std::size_t pos = 0;
        for (int i = 0; i < record; ++i) pos = data.find('\n', pos) + 1;
        return pos;
    };
    {
        std::string d = data;
        std::size_t end = d.find('\n', line_start(3));
        d.erase(d.rfind(' ', end), end - d.rfind(' ', end));  // drop the last value (rot_3)
        expect_ply_error(header + d, {"missing value", "16 of 17", "record 3, property 'rot_3'"});
    }
    {
        std::string d = data;
        d.insert(d.find('\n', line_start(2)), " 7");
        expect_ply_error(header + d, {"more than 17 values", "record 2"});
    }
    {
        std::string d = data;
        std::size_t opacity_at = line_start(4);
        for (int i = 0; i < 9; ++i) opacity_at = d.find(' ', opacity_at) + 1;  // 10th token: opacity
        d.replace(opacity_at, d.find(' ', opacity_at) - opacity_at, "0.5abc");
        expect_ply_error(header + d, {"cannot parse '0.5abc' as a number", "record 4, property 'opacity'"});
    }
    {
        std::string d = data.substr(0, line_start(4));
        ply.count = "5";
        expect_ply_error(header + d, {"data ends after 4 of 5", "record 4, property 'x'"});
    }
}

TEST(SceneIoBadPly, NonFiniteValuesNameRecordAndProperty) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    for (const std::string name : {"x", "z", "f_dc_1", "f_rest_7", "opacity", "scale_2", "rot_0", "rot_3"})
        for (const std::string format : {"binary_little_endian", "ascii"})
            for (double bad : {nan, inf, -inf}) {
                SCOPED_TRACE(name + " " + format);
                Ply ply = graphdeco_ply(5, 1, format);
                ply.rows[3][name] = bad;
                expect_ply_error(ply.bytes(), {"non-finite value", "record 3, property '" + name + "'"});
            }
}

TEST(SceneIoBadPly, ValuesThatOverflowAfterActivation) {
    Ply ply = graphdeco_ply(3, 0, "binary_little_endian", "double");
    ply.rows[1]["scale_1"] = 100.0;  // exp(100) > FLT_MAX
    expect_ply_error(ply.bytes(), {"scale 100 overflows float", "record 1, property 'scale_1'"});
    ply = graphdeco_ply(3, 0, "binary_little_endian", "double");
    ply.rows[2]["f_dc_0"] = 1e300;
    expect_ply_error(ply.bytes(), {"overflows float", "record 2, property 'f_dc_0'"});
    ply = graphdeco_ply(3, 0, "binary_little_endian", "double");
    ply.rows[0]["y"] = 1e35;
    expect_ply_error(ply.bytes(), {"coordinate 1e+35", "record 0, property 'y'"});
    ply = graphdeco_ply(3, 0, "binary_little_endian", "double");
    ply.rows[0]["rot_2"] = 1e300;
    expect_ply_error(ply.bytes(), {"quaternion norm overflows", "record 0, properties 'rot_0'..'rot_3'"});
}

TEST(SceneIoBadPly, ZeroNormQuaternion) {
    Ply ply = graphdeco_ply(6, 0);
    for (int c = 0; c < 4; ++c) ply.rows[4]["rot_" + std::to_string(c)] = 0.0;
    expect_ply_error(ply.bytes(), {"zero-norm quaternion", "record 4", "'rot_0'..'rot_3'"});
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

TEST(SceneIoDrop, InvalidRecordsAreDroppedAndCounted) {
    Ply ply = graphdeco_ply(8, 1);
    ply.rows[1]["f_rest_3"] = std::numeric_limits<double>::quiet_NaN();
    for (int c = 0; c < 4; ++c) ply.rows[4]["rot_" + std::to_string(c)] = 0.0;
    ply.rows[6]["x"] = std::numeric_limits<double>::infinity();
    ply.rows[5]["opacity"] = -10.0;  // sigmoid ~ 4.5e-5 < 1/255
    std::string path = tmp_path("drop.ply");
    write_file(path, ply.bytes());
    expect_error([&] { catgs::read_ply(path); }, path, {"non-finite value nan", "record 1, property 'f_rest_3'"});
    catgs::LoadReport report;
    catgs::Scene s = catgs::read_ply(path, dropping(), &report);
    EXPECT_EQ(report.records, 8u);
    EXPECT_EQ(report.dropped_invalid, 3u);
    EXPECT_EQ(report.dropped_transparent, 1u);
    ASSERT_EQ(s.count(), 4u);
    s.check_consistent("dropped");
    const int kept[] = {0, 2, 3, 7};
    for (std::size_t g = 0; g < 4; ++g) expect_gaussian(s, g, ply.rows[kept[g]]);
}

TEST(SceneIoDrop, TransparentAlwaysDroppedAndBoundsIgnoreThem) {
    Ply ply = graphdeco_ply(4, 0);
    const double threshold_logit = std::log((1 / 255.0) / (1 - 1 / 255.0));
    ply.rows[0]["opacity"] = threshold_logit - 0.01;
    ply.rows[0]["x"] = 1000.0;  // far away, must not move the origin
    ply.rows[2]["opacity"] = threshold_logit + 0.01;
    std::string path = tmp_path("transparent.ply");
    write_file(path, ply.bytes());
    catgs::LoadReport report;
    catgs::Scene s = catgs::read_ply(path, {}, &report);
    EXPECT_EQ(report.dropped_transparent, 1u);
    EXPECT_EQ(report.dropped_invalid, 0u);
    EXPECT_EQ(s.count(), 3u);
    EXPECT_LT(s.bounds.max[0], 10.0);
    EXPECT_EQ(s.origin[0], 0.5 * (1.25 + 3.25));
}

TEST(SceneIoDrop, NothingLeftIsTheZeroGaussianError) {
    Ply ply = graphdeco_ply(3, 0);
    ply.rows[0]["opacity"] = -20.0;
    ply.rows[1]["opacity"] = -30.0;
    ply.rows[2]["scale_0"] = std::numeric_limits<double>::quiet_NaN();
    std::string path = tmp_path("none.ply");
    write_file(path, ply.bytes());
    expect_error([&] { catgs::read_ply(path, dropping()); }, path,
                 {"no Gaussians left after dropping 3 transparent/invalid records", "2 with opacity < 1/255",
                  "1 invalid", "all 3 records"});
}

// =======================================================================================
// load_scene.

TEST(SceneIoLoadScene, DispatchesByExtensionCaseInsensitively) {
    std::string ply = tmp_path("upper.PLY");
    write_file(ply, graphdeco_ply(3, 0).bytes());
    catgs::LoadReport report;
    EXPECT_EQ(catgs::load_scene(ply, {}, &report).count(), 3u);
    EXPECT_EQ(report.records, 3u);
    std::string splat = tmp_path("mixed.Splat");
    write_file(splat, splat_bytes(std::vector<SplatRecord>(2)));
    EXPECT_EQ(catgs::load_scene(splat, {}, &report).count(), 2u);
    EXPECT_EQ(report.records, 2u);
    // The extension decides, not the content.
    std::string misnamed = tmp_path("really_ply.splat");
    write_file(misnamed, graphdeco_ply(3, 0).bytes());
    expect_error([&] { catgs::load_scene(misnamed); }, misnamed, {"not a multiple of the 32-byte record"});
}

TEST(SceneIoLoadScene, UnknownExtensionAndMissingFile) {
    std::string xyz = tmp_path("cloud.xyz");
    write_file(xyz, "1 2 3\n");
    expect_error([&] { catgs::load_scene(xyz); }, xyz,
                 {"unknown scene format", ".ply", ".splat", "builtin:", "'.xyz'"});
    expect_error([&] { catgs::load_scene("noext"); }, "noext", {"unknown scene format", "no file extension"});
    const std::string missing = std::string(CATGS_TEST_TMP) + "/definitely_missing.ply";
    EXPECT_EQ(error_of([&] { catgs::load_scene(missing); }), missing + ": cannot open: No such file or directory");
    const std::string missing_splat = std::string(CATGS_TEST_TMP) + "/definitely_missing.splat";
    EXPECT_EQ(error_of([&] { catgs::load_scene(missing_splat); }),
              missing_splat + ": cannot open: No such file or directory");
    fs::create_directories(std::string(CATGS_TEST_TMP) + "/a_directory.ply");
    expect_error([&] { catgs::load_scene(std::string(CATGS_TEST_TMP) + "/a_directory.ply"); },
                 std::string(CATGS_TEST_TMP) + "/a_directory.ply", {"not a regular file"});
}

TEST(SceneIoLoadScene, Builtin) {
    catgs::LoadReport report;
    catgs::Scene s = catgs::load_scene("builtin:city?gaussians=10000&seed=2", {}, &report);
    EXPECT_EQ(s.count(), 10000u);
    EXPECT_EQ(report.records, 10000u);
    EXPECT_THROW(catgs::load_scene("builtin:nothing"), catgs::Error);
}

TEST(SceneIoLoadScene, ReportsProgress) {
    std::string path = tmp_path("progress.ply");
    write_file(path, graphdeco_ply(20, 3).bytes());
    std::vector<std::pair<double, std::string>> calls;
    catgs::LoadOptions options;
    options.progress = [&](double f, const std::string& label) { calls.emplace_back(f, label); };
    catgs::load_scene(path, options);
    ASSERT_FALSE(calls.empty());
    EXPECT_EQ(calls.back().first, 1.0);
    for (std::size_t i = 0; i < calls.size(); ++i) {
        EXPECT_EQ(calls[i].second, "loading scene_io_ReportsProgress_progress.ply");
        if (i > 0) {
            EXPECT_GE(calls[i].first, calls[i - 1].first);
        }
    }
}

TEST(SceneIoLoadScene, RealTruckSplat) {
    const std::string path = catgs::test::shared_dir() + "/data/scenes/tandt-truck-uav4geo/truck.splat";
    if (!fs::exists(path)) GTEST_SKIP() << path << " is absent";
    catgs::LoadReport report;
    catgs::Scene s = catgs::load_scene(path, {}, &report);
    EXPECT_EQ(report.records, 116544u);
    EXPECT_EQ(report.dropped_invalid, 0u);
    EXPECT_EQ(s.count() + report.dropped_transparent, 116544u);
    EXPECT_EQ(s.count(), 116544u);  // alpha runs 25..254 in this file
    s.check_consistent(path);
    auto finite = [](const std::vector<float>& v) {
        return std::all_of(v.begin(), v.end(), [](float x) { return std::isfinite(x); });
    };
    EXPECT_TRUE(finite(s.positions) && finite(s.scales) && finite(s.rotations) && finite(s.opacities) && finite(s.sh));
    EXPECT_NEAR(s.bounds.min[0], -1.476, 2e-3);
    EXPECT_NEAR(s.bounds.max[0], 1.727, 2e-3);
    EXPECT_NEAR(s.bounds.min[1], -0.960, 2e-3);
    EXPECT_NEAR(s.bounds.max[1], 0.624, 2e-3);
    EXPECT_NEAR(s.bounds.min[2], -1.381, 2e-3);
    EXPECT_NEAR(s.bounds.max[2], 1.452, 2e-3);
    EXPECT_NEAR(s.origin[0], 0.5 * (s.bounds.min[0] + s.bounds.max[0]), 1e-6);
    for (std::size_t i = 0; i < s.count(); ++i) {
        double n2 = 0;
        for (int c = 0; c < 4; ++c) n2 += double(s.rotations[4 * i + c]) * s.rotations[4 * i + c];
        ASSERT_NEAR(n2, 1.0, 1e-6) << "record " << i;
    }
}

// =======================================================================================
// Robustness: any byte string either loads or raises catgs::Error.

void expect_loads_or_errors(const std::string& path, bool splat, const std::string& what) {
    try {
        catgs::Scene s = splat ? catgs::read_splat(path) : catgs::read_ply(path);
        s.check_consistent(what);
        ASSERT_GT(s.count(), 0u) << what;
    } catch (const catgs::Error& e) {
        ASSERT_EQ(std::string(e.what()).find('\n'), std::string::npos) << what << ": " << e.what();
    } catch (const std::exception& e) {
        FAIL() << what << ": unexpected exception " << e.what();
    }
}

TEST(SceneIoRobustness, TruncationsAndMutationsNeverEscape) {
    const std::uint64_t seed = fresh_seed();
    SCOPED_TRACE("CATGS_TEST_SEED=" + std::to_string(seed));
    std::mt19937_64 rng(seed);
    Ply with_face = graphdeco_ply(4, 1);
    with_face.before_header = "element edge 1\nproperty list uchar int ids\n";
    std::string list;
    put(list, std::uint8_t(2), false), put(list, std::int32_t(1), false), put(list, std::int32_t(2), false);
    with_face.before_data = list;
    const std::vector<std::pair<std::string, bool>> originals = {
        {graphdeco_ply(4, 1).bytes(), false},
        {graphdeco_ply(3, 2, "ascii").bytes(), false},
        {graphdeco_ply(3, 0, "binary_big_endian", "double").bytes(), false},
        {with_face.bytes(), false},
        {splat_bytes(std::vector<SplatRecord>(3)), true},
    };
    const std::string path_ply = tmp_path("m.ply"), path_splat = tmp_path("m.splat");
    for (std::size_t o = 0; o < originals.size(); ++o) {
        const auto& [bytes, splat] = originals[o];
        const std::string& path = splat ? path_splat : path_ply;
        for (std::size_t n = 0; n < bytes.size(); ++n) {
            write_file(path, bytes.substr(0, n));
            expect_loads_or_errors(path, splat, "original " + std::to_string(o) + " cut to " + std::to_string(n));
        }
        // Mutations favour the header and control-ish bytes, where the parser branches.
        const char interesting[] = {'\0', '\n', ' ', '\xff', '-', '9', 'e', '\x80', '\r'};
        for (int m = 0; m < 400; ++m) {
            std::string b = bytes;
            const int edits = 1 + static_cast<int>(rng() % 4);
            for (int e = 0; e < edits; ++e) {
                std::size_t at = rng() % 2 ? rng() % std::min<std::size_t>(b.size(), 600) : rng() % b.size();
                b[at] = rng() % 2 ? interesting[rng() % sizeof(interesting)] : static_cast<char>(rng());
            }
            write_file(path, b);
            expect_loads_or_errors(path, splat, "original " + std::to_string(o) + " mutation " + std::to_string(m));
        }
    }
}

}  // namespace
