// The glTF binary reader: .glb files written here accessor by accessor (the axis conversion
// checked against rotation matrices and SH evaluated at a direction), the files it refuses,
// and splat-transform's .glb of random scenes against the PLY they came from (the oracle,
// tests/oracle_harness.hpp).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "catgs/error.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_format.hpp"
#include "catgs/scene_io.hpp"
#include "oracle_harness.hpp"
#include "scene_io_fixtures.hpp"

namespace {

using namespace catgs::scene_io_test;
using json = nlohmann::json;

constexpr int kFloat = 5126, kUnsignedByte = 5121, kByte = 5120;
const std::string kPrefix = "KHR_gaussian_splatting:";

/// A .glb built attribute by attribute: each one a tightly packed bufferView of the BIN chunk.
struct HandGlb {
    json gltf;
    std::string bin;
    json attributes = json::object();

    HandGlb() {
        gltf = {{"asset", {{"version", "2.0"}}},
                {"extensionsUsed", {"KHR_gaussian_splatting"}},
                {"scene", 0},
                {"scenes", {{{"nodes", {0}}}}},
                {"nodes", {{{"mesh", 0}}}},
                {"bufferViews", json::array()},
                {"accessors", json::array()}};
    }

    template <typename T>
    void add(const std::string& name, const std::vector<T>& values, int component_type, const std::string& type,
             std::size_t count, bool normalized = false) {
        while (bin.size() % 4) bin.push_back('\0');
        const std::size_t offset = bin.size();
        bin.append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
        json accessor = {{"bufferView", gltf["bufferViews"].size()},
                         {"componentType", component_type},
                         {"count", count},
                         {"type", type}};
        if (normalized) accessor["normalized"] = true;
        gltf["bufferViews"].push_back(
            {{"buffer", 0}, {"byteOffset", offset}, {"byteLength", values.size() * sizeof(T)}});
        attributes[name] = gltf["accessors"].size();
        gltf["accessors"].push_back(accessor);
    }
    void add_floats(const std::string& name, const std::vector<float>& values, const std::string& type,
                    std::size_t count) {
        add(name, values, kFloat, type, count);
    }

    /// One Gaussian per entry of the vectors, SH coefficients per degree as (r, g, b) triples.
    void splats(const std::vector<float>& positions, const std::vector<float>& xyzw, const std::vector<float>& scales,
                const std::vector<float>& opacities, const std::vector<std::vector<float>>& sh) {
        const std::size_t n = opacities.size();
        add_floats("POSITION", positions, "VEC3", n);
        add_floats(kPrefix + "ROTATION", xyzw, "VEC4", n);
        add_floats(kPrefix + "SCALE", scales, "VEC3", n);
        add_floats(kPrefix + "OPACITY", opacities, "SCALAR", n);
        std::size_t k = 0;
        for (int l = 0; k < sh.size(); ++l)
            for (int c = 0; c < 2 * l + 1 && k < sh.size(); ++c, ++k)
                add_floats(kPrefix + "SH_DEGREE_" + std::to_string(l) + "_COEF_" + std::to_string(c), sh[k], "VEC3", n);
    }

    std::string bytes() const { return bytes_with({attributes}); }

    /// One mesh of one splat primitive per attribute map, all over the same BIN chunk.
    std::string bytes_with(const std::vector<json>& primitive_attributes) const {
        json g = gltf;
        g["buffers"] = {{{"byteLength", bin.size()}}};
        json primitives = json::array();
        for (const json& a : primitive_attributes)
            primitives.push_back(
                {{"attributes", a}, {"mode", 0}, {"extensions", {{"KHR_gaussian_splatting", json::object()}}}});
        g["meshes"] = {{{"primitives", primitives}}};
        return container(g.dump(), bin);
    }

    static std::string container(std::string text, std::string binary) {
        while (text.size() % 4) text.push_back(' ');
        while (binary.size() % 4) binary.push_back('\0');
        std::string out;
        auto u32 = [&](std::uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
        u32(0x46546C67);
        u32(2);
        u32(static_cast<std::uint32_t>(12 + 8 + text.size() + (binary.empty() ? 0 : 8 + binary.size())));
        u32(static_cast<std::uint32_t>(text.size()));
        u32(0x4E4F534A);
        out += text;
        if (!binary.empty()) {
            u32(static_cast<std::uint32_t>(binary.size()));
            u32(0x004E4942);
            out += binary;
        }
        return out;
    }
};

/// One Gaussian of SH degree 1 with every value distinct.
HandGlb one_gaussian() {
    HandGlb glb;
    const double norm = std::sqrt(0.1 * 0.1 + 0.2 * 0.2 + 0.3 * 0.3 + 0.9 * 0.9);
    glb.splats({1, 2, 3},
               {static_cast<float>(0.1 / norm), static_cast<float>(0.2 / norm), static_cast<float>(0.3 / norm),
                static_cast<float>(0.9 / norm)},
               {0.5f, 0.25f, 2.0f}, {0.5f},
               {{0.1f, 0.2f, 0.3f}, {0.4f, 0.5f, 0.6f}, {0.7f, 0.8f, 0.9f}, {-0.1f, -0.2f, -0.3f}});
    return glb;
}

std::string write_glb(const std::string& bytes, const std::string& name = "hand.glb") {
    const std::string path = tmp_path(name);
    write_file(path, bytes);
    return path;
}

using Matrix = std::array<std::array<double, 3>, 3>;

/// The rotation matrix of a unit quaternion (w, x, y, z).
Matrix rotation_matrix(double w, double x, double y, double z) {
    return {{{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
             {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
             {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}}};
}

/// 3DGS's real degree-1 SH basis (without the constant): -y, z, -x for coefficients 0, 1, 2.
double degree1(const std::array<double, 3>& coefficients, const std::array<double, 3>& d) {
    return -coefficients[0] * d[1] + coefficients[1] * d[2] - coefficients[2] * d[0];
}

// =======================================================================================

TEST(SceneIoGlb, TurnsGltfAxesIntoRdf) {
    const std::string path = write_glb(one_gaussian().bytes());
    EXPECT_EQ(catgs::detect_scene_format(path), catgs::SceneFormat::glb);
    catgs::LoadReport report;
    const catgs::Scene s = catgs::read_glb(path, absolute(), &report);
    ASSERT_EQ(s.count(), 1u);
    EXPECT_EQ(s.sh_degree, 1);
    // glTF LUF -> RDF: a half turn about z, x and y flip.
    EXPECT_EQ(s.positions, (std::vector<float>{-1, -2, 3}));
    EXPECT_EQ(s.scales, (std::vector<float>{0.5f, 0.25f, 2.0f}));
    EXPECT_FLOAT_EQ(s.opacities[0], 0.5f);
    // The loaded rotation is the half turn after the file's: R' = diag(-1, -1, 1) R.
    const double norm = std::sqrt(0.1 * 0.1 + 0.2 * 0.2 + 0.3 * 0.3 + 0.9 * 0.9);
    const Matrix file = rotation_matrix(0.9 / norm, 0.1 / norm, 0.2 / norm, 0.3 / norm);
    const Matrix loaded = rotation_matrix(s.rotations[0], s.rotations[1], s.rotations[2], s.rotations[3]);
    const double flip[3] = {-1, -1, 1};
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(loaded[r][c], flip[r] * file[r][c], 1e-6) << r << c;
    // f_dc unchanged; degree 1 evaluated at d in RDF equals the file's at the turned direction.
    EXPECT_EQ(std::vector<float>(s.sh.begin(), s.sh.begin() + 3), (std::vector<float>{0.1f, 0.2f, 0.3f}));
    const std::array<double, 3> d = {0.3, 0.5, 0.8}, turned = {-0.3, -0.5, 0.8};
    const float file_sh[3][3] = {{0.4f, 0.5f, 0.6f}, {0.7f, 0.8f, 0.9f}, {-0.1f, -0.2f, -0.3f}};
    for (int channel = 0; channel < 3; ++channel) {
        const std::array<double, 3> in_file = {file_sh[0][channel], file_sh[1][channel], file_sh[2][channel]};
        const std::array<double, 3> in_scene = {s.sh[3 + channel], s.sh[6 + channel], s.sh[9 + channel]};
        EXPECT_NEAR(degree1(in_scene, d), degree1(in_file, turned), 1e-6) << channel;
    }
}

TEST(SceneIoGlb, NormalisedIntegerAccessors) {
    HandGlb glb;
    glb.add_floats("POSITION", {0, 0, 0, 1, 1, 1}, "VEC3", 2);
    glb.add(kPrefix + "ROTATION", std::vector<std::int8_t>{0, 0, 0, 127, 0, 0, -128, 0}, kByte, "VEC4", 2, true);
    glb.add_floats(kPrefix + "SCALE", {1, 1, 1, 1, 1, 1}, "VEC3", 2);
    glb.add(kPrefix + "OPACITY", std::vector<std::uint8_t>{255, 51}, kUnsignedByte, "SCALAR", 2, true);
    glb.add_floats(kPrefix + "SH_DEGREE_0_COEF_0", {0, 0, 0, 0, 0, 0}, "VEC3", 2);
    const catgs::Scene s = catgs::read_glb(write_glb(glb.bytes()), absolute());
    ASSERT_EQ(s.count(), 2u);
    EXPECT_EQ(s.opacities, (std::vector<float>{1.0f, 0.2f}));
    // (x, y, z, w) = (0, 0, 0, 1) is the identity, turned: (w, x, y, z) = (0, 0, 0, 1).
    EXPECT_EQ(std::vector<float>(s.rotations.begin(), s.rotations.begin() + 4), (std::vector<float>{0, 0, 0, 1}));
    // z = -128 clamps to -1: (-z, -y, x, w) = (1, 0, 0, 0).
    EXPECT_EQ(std::vector<float>(s.rotations.begin() + 4, s.rotations.end()), (std::vector<float>{1, 0, 0, 0}));
}

TEST(SceneIoGlb, IncompleteShDegreeIsRefused) {
    HandGlb glb;
    glb.splats({0, 0, 0}, {0, 0, 0, 1}, {1, 1, 1}, {1}, {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}});
    const std::string path = write_glb(glb.bytes());
    expect_error([&] { catgs::read_glb(path); }, path,
                 {"SH degree 2 lacks 'KHR_gaussian_splatting:SH_DEGREE_2_COEF_1'", "mesh 0, primitive 0"});
}

// ---------------------------------------------------------------------------------------
// Bad input.

TEST(SceneIoGlb, BadContainers) {
    const std::string good = one_gaussian().bytes();
    struct Case {
        std::string bytes;
        std::vector<std::string> parts;
    };
    std::string bad_magic = good, bad_version = good, long_json = good, bad_bin = good;
    bad_magic[0] = 'x';
    bad_version[4] = 1;
    const std::uint32_t huge = 1u << 30;
    std::memcpy(long_json.data() + 12, &huge, 4);
    std::uint32_t json_length = 0;
    std::memcpy(&json_length, good.data() + 12, 4);
    bad_bin[20 + json_length + 4] = 'X';
    const std::vector<Case> cases = {
        {good.substr(0, 8), {"too short for the 12-byte GLB header", "byte offset 0"}},
        {good.substr(0, good.size() - 16), {"the header declares", "the file is truncated", "byte offset 8"}},
        {bad_magic, {"not a GLB file: magic 'xlTF'", "byte offset 0"}},
        {bad_version, {"GLB version 1; expected 2", "byte offset 4"}},
        {long_json, {"JSON chunk of 1073741824 bytes runs past the end of the file", "byte offset 12"}},
        {bad_bin, {"the second chunk is not BIN", "byte offset " + std::to_string(20 + json_length + 4)}},
        {HandGlb::container("{\"asset\": ", ""), {"invalid glTF", "JSON chunk"}},
        {HandGlb::container(std::string(100, '[') + std::string(100, ']'), ""), {"nests deeper than 64 levels"}},
    };
    for (std::size_t i = 0; i < cases.size(); ++i) {
        SCOPED_TRACE(i);
        const std::string path = write_glb(cases[i].bytes, "case" + std::to_string(i) + ".glb");
        expect_error([&] { catgs::read_glb(path); }, path, cases[i].parts);
    }
}

TEST(SceneIoGlb, LyingCountIsRefusedBeforeAllocating) {
    HandGlb glb = one_gaussian();
    for (json& accessor : glb.gltf["accessors"]) accessor["count"] = 1'000'000'000;
    const std::string path = write_glb(glb.bytes());
    expect_error(
        [&] { catgs::read_glb(path); }, path,
        {"1000000000 elements at byteOffset 0 run past bufferView 0 or its buffer", "accessor 0 ('POSITION')"});
}

TEST(SceneIoGlb, PrimitivesWithTheirOwnBytesLoadTogether) {
    HandGlb glb;
    glb.splats({1, 2, 3}, {0, 0, 0, 1}, {1, 1, 1}, {1}, {{0, 0, 0}});
    const json first = glb.attributes;
    glb.splats({4, 5, 6}, {0, 0, 0, 1}, {1, 1, 1}, {1}, {{0, 0, 0}});
    const catgs::Scene s = catgs::read_glb(write_glb(glb.bytes_with({first, glb.attributes})), absolute());
    EXPECT_EQ(s.positions, (std::vector<float>{-1, -2, 3, -4, -5, 6}));
}

// Primitives' counts add up: naming one accessor from many primitives would declare many
// times the Gaussians whose bytes the file holds (a 2 MB file asking for 128 GB).
TEST(SceneIoGlb, PrimitivesSharingAnAccessorAreRefusedBeforeAllocating) {
    const HandGlb glb = one_gaussian();
    const std::string path = write_glb(glb.bytes_with(std::vector<json>(1000, glb.attributes)));
    expect_error([&] { catgs::read_glb(path); }, path,
                 {"reuses accessor 0 ('POSITION') of mesh 0, primitive 0 (mesh 0, primitive 1)"});
}

TEST(SceneIoGlb, PrimitivesAliasingTheSameBytesAreRefusedBeforeAllocating) {
    HandGlb glb = one_gaussian();
    // Each primitive gets accessors of its own, all viewing the first primitive's bytes.
    std::vector<json> primitives;
    const json accessors = glb.gltf["accessors"];
    for (int p = 0; p < 1000; ++p) {
        json a = glb.attributes;
        for (auto& [name, index] : a.items()) index = index.get<std::size_t>() + accessors.size() * p;
        primitives.push_back(a);
        if (p > 0)
            for (const json& accessor : accessors) glb.gltf["accessors"].push_back(accessor);
    }
    const std::string path = write_glb(glb.bytes_with(primitives));
    expect_error([&] { catgs::read_glb(path); }, path,
                 {"the splat primitives' POSITION elements need more than the 92 bytes the buffers hold: primitives "
                  "share their bytes",
                  "(meshes)"});
}

TEST(SceneIoGlb, MismatchedAttributeCount) {
    HandGlb glb = one_gaussian();
    glb.gltf["accessors"][3]["count"] = 2;
    const std::string path = write_glb(glb.bytes());
    expect_error([&] { catgs::read_glb(path); }, path,
                 {"holds 2 elements; POSITION has 1", "accessor 3 ('KHR_gaussian_splatting:OPACITY')"});
}

TEST(SceneIoGlb, NanValue) {
    HandGlb glb;
    glb.splats({0, 0, 0, 0, 0, std::nanf("")}, {0, 0, 0, 1, 0, 0, 0, 1}, {1, 1, 1, 1, 1, 1}, {1, 1},
               {{0, 0, 0, 0, 0, 0}});
    const std::string path = write_glb(glb.bytes());
    expect_error([&] { catgs::read_glb(path); }, path, {"non-finite value nan", "record 1, attribute 'POSITION.z'"});
    catgs::LoadReport report;
    EXPECT_EQ(catgs::read_glb(path, dropping(), &report).count(), 1u);
    EXPECT_EQ(report.dropped_invalid, 1u);
}

TEST(SceneIoGlb, RefusedStructures) {
    HandGlb transformed = one_gaussian();
    transformed.gltf["nodes"][0]["translation"] = {1, 0, 0};
    HandGlb external = one_gaussian();
    HandGlb plain = one_gaussian();
    plain.attributes.erase(kPrefix + "ROTATION");
    const std::string external_bytes = [&] {
        json g = external.gltf;
        g["buffers"] = {{{"byteLength", 4}, {"uri", "/etc/hostname"}}};
        g["meshes"] = json::array();
        return HandGlb::container(g.dump(), "");
    }();
    const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
        {transformed.bytes(), {"node transforms are not supported", "node 0"}},
        {external_bytes, {"invalid glTF", "/etc/hostname"}},
        {plain.bytes(), {"missing attribute 'KHR_gaussian_splatting:ROTATION'", "mesh 0, primitive 0"}},
        {HandGlb::container(R"({"asset": {"version": "2.0"}, "meshes": []})", ""),
         {"no mesh primitive carries KHR_gaussian_splatting attributes", "meshes"}},
    };
    for (std::size_t i = 0; i < cases.size(); ++i) {
        SCOPED_TRACE(i);
        const std::string path = write_glb(cases[i].first, "refused" + std::to_string(i) + ".glb");
        expect_error([&] { catgs::read_glb(path); }, path, cases[i].second);
    }
}

TEST(SceneIoGlb, MaxRecords) {
    const std::string path = write_glb(one_gaussian().bytes());
    catgs::LoadOptions options;
    options.max_records = 0;
    expect_error([&] { catgs::read_glb(path, options); }, path, {"1 records exceed the limit of 0"});
}

// ---------------------------------------------------------------------------------------
// Against splat-transform: lossless, so its .glb loads as the PLY it was made from.

TEST(SceneIoGlbOracle, SplatTransformGlbLoadsAsItsSourceAtEveryShDegree) {
    CATGS_NEED_ORACLE();
    catgs::oracle::TempDir dir("glb_oracle");
    std::vector<catgs::oracle::Conversion> to_glb;
    for (int degree = 0; degree <= catgs::kMaxShDegree; ++degree) {
        const std::string d = std::to_string(degree);
        catgs::write_ply(catgs::oracle::asymmetric_scene(degree, 300, 21 + static_cast<unsigned>(degree)),
                         dir.path("in" + d + ".ply"));
        to_glb.push_back({dir.path("in" + d + ".ply"), dir.path("out" + d + ".glb"), {}});
    }
    ASSERT_TRUE(catgs::oracle::convert_all(to_glb));
    for (int degree = 0; degree <= catgs::kMaxShDegree; ++degree) {
        SCOPED_TRACE(degree);
        const std::string& ply = to_glb[static_cast<std::size_t>(degree)].in;
        const std::string& glb = to_glb[static_cast<std::size_t>(degree)].out;
        const catgs::Scene source = catgs::read_ply(ply, absolute());
        const catgs::Scene loaded = catgs::read_glb(glb, absolute());
        ASSERT_EQ(loaded.count(), source.count());
        ASSERT_EQ(loaded.sh_degree, degree);
        for (std::size_t i = 0; i < source.positions.size(); ++i)
            ASSERT_NEAR(loaded.positions[i], source.positions[i], 1e-6) << i;
        for (std::size_t i = 0; i < source.scales.size(); ++i)
            ASSERT_NEAR(loaded.scales[i], source.scales[i], 1e-6 * source.scales[i]) << i;
        for (std::size_t i = 0; i < source.count(); ++i) {
            ASSERT_NEAR(loaded.opacities[i], source.opacities[i], 1e-6) << i;
            double dot = 0;
            for (int c = 0; c < 4; ++c) dot += loaded.rotations[4 * i + c] * source.rotations[4 * i + c];
            ASSERT_NEAR(std::fabs(dot), 1.0, 1e-6) << i;
        }
        // splat-transform turns the SH with its general rotation code; the reader's signs
        // must agree with it coefficient by coefficient.
        for (std::size_t i = 0; i < source.sh.size(); ++i) ASSERT_NEAR(loaded.sh[i], source.sh[i], 1e-5) << i;
    }
}

}  // namespace
