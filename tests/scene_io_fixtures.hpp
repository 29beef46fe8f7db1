// Fixtures of the scene reader and writer tests (test_scene_io*.cpp): files under
// CATGS_TEST_TMP named after the test, so that tests run in parallel processes do not
// collide; PLY and .splat files built field by field; the activation rules a loaded Gaussian
// must satisfy; and the check that a bad input's error names the file on one line.
#pragma once

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"
#include "test_util.hpp"

namespace catgs::scene_io_test {

using ::testing::HasSubstr;
namespace fs = std::filesystem;

static_assert(std::endian::native == std::endian::little, "the fixture writer assumes a little-endian host");

inline constexpr double kSqrtPi = 1.7724538509055159;  // (1 - 0.5) / C0 for a colour byte of 255

// ---------------------------------------------------------------------------------------
// Files.

inline std::string tmp_path(const std::string& name) {
    fs::create_directories(CATGS_TEST_TMP);
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    return std::string(CATGS_TEST_TMP) + "/scene_io_" + info->name() + "_" + name;
}

inline void write_file(const std::string& path, const std::string& bytes) {
    // A new file, not a truncated one: ext4 flushes a truncated-and-rewritten file on close,
    // which makes the thousands of rewrites of the robustness test wait on the disk.
    fs::remove(path);
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    ASSERT_TRUE(out.good()) << path;
}

using test::error_of;

/// The message names the file, is one line, and contains every part.
inline void expect_error(const std::function<void()>& f, const std::string& path,
                         const std::vector<std::string>& parts) {
    std::string message = error_of(f);
    EXPECT_THAT(message, ::testing::StartsWith(path + ": "));
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    for (const auto& part : parts) EXPECT_THAT(message, HasSubstr(part));
}

inline catgs::LoadOptions absolute() {
    catgs::LoadOptions options;
    options.recentre = false;
    return options;
}

inline catgs::LoadOptions dropping() {
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

inline void put_value(std::string& out, const std::string& type, double v, bool big_endian) {
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

inline std::string ascii_value(const std::string& type, double v) {
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

inline std::vector<Prop> graphdeco_props(int degree, const std::string& type = "float") {
    std::vector<Prop> props;
    for (const char* n : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"}) props.push_back({type, n});
    const int rest = 3 * (catgs::sh_coefficient_count(degree) - 1);
    for (int j = 0; j < rest; ++j) props.push_back({type, "f_rest_" + std::to_string(j)});
    for (const char* n : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
        props.push_back({type, n});
    return props;
}

/// Distinct, exactly float-representable values per record and property.
inline Row gaussian(int i, int degree) {
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

inline Ply graphdeco_ply(int records, int degree, const std::string& format = "binary_little_endian",
                         const std::string& type = "float") {
    Ply ply;
    ply.format = format;
    ply.props = graphdeco_props(degree, type);
    for (int i = 0; i < records; ++i) ply.rows.push_back(gaussian(i, degree));
    return ply;
}

/// The value as the file holds it (rounded to float for float properties).
inline double stored(const Row& row, const std::string& name, bool as_float) {
    double v = row.at(name);
    return as_float ? static_cast<double>(static_cast<float>(v)) : v;
}

/// Checks Gaussian g (loaded with recentre off) against the activation rules of the issue.
inline void expect_gaussian(const catgs::Scene& s, std::size_t g, const Row& row, bool as_float = true) {
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

inline void expect_same_scene(const catgs::Scene& a, const catgs::Scene& b) {
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

inline std::string splat_bytes(const std::vector<SplatRecord>& records) {
    std::string out;
    for (const auto& r : records) {
        for (float v : r.position) put(out, v, false);
        for (float v : r.scale) put(out, v, false);
        out.append(reinterpret_cast<const char*>(r.rgba.data()), 4);
        out.append(reinterpret_cast<const char*>(r.quaternion.data()), 4);
    }
    return out;
}

/// A fresh seed per run (CATGS_TEST_SEED replays one), also recorded in the XML report.
inline std::uint64_t fresh_seed() {
    const std::uint64_t seed = catgs::test::fresh_seed(::testing::UnitTest::GetInstance()->current_test_info()->name());
    ::testing::Test::RecordProperty("seed", std::to_string(seed));
    return seed;
}

}  // namespace catgs::scene_io_test
