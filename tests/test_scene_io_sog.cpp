// The SOG reader: archives written here texel by texel (libwebp, libzip) with hand-computed
// values, the files it refuses, and splat-transform's own .sog files against the PLY that
// splat-transform decodes from them (the oracle, tests/oracle_harness.hpp).
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <webp/encode.h>
#include <zip.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
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

// ---------------------------------------------------------------------------------------
// A SOG written by hand: every texture 2 x 2 texels (4 >= count), meta.json as a json value.

constexpr int kSide = 2;
constexpr int kTexels = kSide * kSide;

/// Byte k of the codebooks decodes to these, so that a test can say which byte it stored.
double scale_code(int k) {
    return -k / 32.0;
}
double colour_code(int k) {
    return (k - 128) / 64.0;
}
double sh_code(int k) {
    return (k - 128) / 256.0;
}

struct HandSog {
    std::map<std::string, std::vector<unsigned char>> textures;  ///< RGBA, kTexels each
    std::map<std::string, std::string> raw;                      ///< entries stored as they are
    json meta;

    explicit HandSog(int count, int sh_bands = 0) {
        json scales = json::array(), colours = json::array(), sh = json::array();
        for (int k = 0; k < 256; ++k) {
            scales.push_back(scale_code(k));
            colours.push_back(colour_code(k));
            sh.push_back(sh_code(k));
        }
        meta = {{"version", 2},
                {"count", count},
                {"means",
                 {{"mins", {0.0, -std::log(3.0), 0.0}},
                  {"maxs", {std::log(2.0), std::log(3.0), std::log(5.0)}},
                  {"files", {"means_l.webp", "means_u.webp"}}}},
                {"scales", {{"codebook", scales}, {"files", {"scales.webp"}}}},
                {"quats", {{"files", {"quats.webp"}}}},
                {"sh0", {{"codebook", colours}, {"files", {"sh0.webp"}}}}};
        // Alpha 255 wherever it carries nothing: the lossless encoder drops the colour of
        // fully transparent texels.
        for (const char* name : {"means_l.webp", "means_u.webp", "scales.webp", "sh0.webp"}) {
            textures[name].assign(4 * kTexels, 0);
            for (int i = 0; i < kTexels; ++i) textures[name][4 * i + 3] = 255;
        }
        // Every Gaussian defaults to an opaque, unrotated one: w largest, the rest at byte 128
        // (a tiny (128/255 * 2 - 1) / sqrt 2 each), opacity 255.
        textures["quats.webp"].assign(4 * kTexels, 128);
        for (int i = 0; i < kTexels; ++i) {
            textures["quats.webp"][4 * i + 3] = 252;
            textures["sh0.webp"][4 * i + 3] = 255;
        }
        if (sh_bands > 0) {
            const int coefficients = (sh_bands + 1) * (sh_bands + 1) - 1;
            meta["shN"] = {{"count", 2},
                           {"bands", sh_bands},
                           {"codebook", sh},
                           {"files", {"shN_centroids.webp", "shN_labels.webp"}}};
            centroids_width = 64 * coefficients;
            textures["shN_centroids.webp"].assign(4 * static_cast<std::size_t>(centroids_width), 128);
            textures["shN_labels.webp"].assign(4 * kTexels, 0);
            for (int i = 0; i < kTexels; ++i) textures["shN_labels.webp"][4 * i + 3] = 255;
        }
    }

    void set(const std::string& texture, int texel, std::array<int, 4> rgba) {
        for (int c = 0; c < 4; ++c) textures[texture][4 * texel + c] = static_cast<unsigned char>(rgba[c]);
    }
    /// Gaussian i's 16-bit position steps.
    void set_means(int i, std::array<int, 3> steps) {
        for (int a = 0; a < 3; ++a) {
            textures["means_l.webp"][4 * i + a] = static_cast<unsigned char>(steps[a] & 0xff);
            textures["means_u.webp"][4 * i + a] = static_cast<unsigned char>(steps[a] >> 8);
        }
    }

    std::map<std::string, std::string> entries() const {
        std::map<std::string, std::string> out = raw;
        if (!out.count("meta.json")) out["meta.json"] = meta.dump();
        for (const auto& [name, rgba] : textures) {
            if (out.count(name)) continue;
            const int width = name == "shN_centroids.webp" ? centroids_width : kSide;
            const int height = name == "shN_centroids.webp" ? 1 : kSide;
            out[name] = webp(rgba, width, height);
        }
        return out;
    }

    static std::string webp(const std::vector<unsigned char>& rgba, int width, int height) {
        uint8_t* encoded = nullptr;
        const std::size_t size = WebPEncodeLosslessRGBA(rgba.data(), width, height, width * 4, &encoded);
        std::string bytes(reinterpret_cast<const char*>(encoded), size);
        WebPFree(encoded);
        return bytes;
    }

    int centroids_width = 0;
};

void write_zip(const std::string& path, const std::map<std::string, std::string>& entries) {
    std::filesystem::remove(path);
    int error = 0;
    zip_t* archive = zip_open(path.c_str(), ZIP_CREATE | ZIP_TRUNCATE, &error);
    ASSERT_NE(archive, nullptr) << path;
    for (const auto& [name, bytes] : entries) {
        zip_source_t* source = zip_source_buffer(archive, bytes.data(), bytes.size(), 0);
        ASSERT_GE(zip_file_add(archive, name.c_str(), source, ZIP_FL_OVERWRITE), 0) << name;
    }
    // zip_source_buffer does not copy: the entries must live until zip_close writes them.
    ASSERT_EQ(zip_close(archive), 0) << zip_strerror(archive);
}

std::string write_sog(const HandSog& sog, const std::string& name = "hand.sog") {
    const std::string path = tmp_path(name);
    write_zip(path, sog.entries());
    return path;
}

std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

// =======================================================================================

TEST(SceneIoSog, DecodesHandComputedValues) {
    HandSog sog(3, 1);
    sog.set_means(0, {65535, 0, 65535});  // maxs x, mins y, maxs z: e^ln2 - 1, -(e^ln3 - 1), e^ln5 - 1
    sog.set_means(1, {0, 65535, 0});
    sog.set("scales.webp", 0, {0, 32, 64, 255});           // log scales 0, -1, -2
    sog.set("sh0.webp", 0, {192, 64, 128, 51});            // f_dc 1, -1, 0; opacity 0.2
    sog.set("quats.webp", 1, {255, 128, 0, 253});          // x largest: w = 1/sqrt2, y ~ 0, z = -1/sqrt2
    sog.set("shN_labels.webp", 0, {1, 0, 0, 255});         // palette entry 1: texels 3..5
    sog.set("shN_centroids.webp", 3, {0, 128, 255, 255});  // coefficient 1: -0.5, 0, 127/256
    sog.set("shN_centroids.webp", 5, {64, 64, 64, 255});   // coefficient 3: -0.25 each
    sog.set("sh0.webp", 2, {128, 128, 128, 0});            // transparent: dropped
    const std::string path = write_sog(sog);
    catgs::LoadReport report;
    const catgs::Scene s = catgs::read_sog(path, absolute(), &report);
    EXPECT_EQ(report.records, 3u);
    EXPECT_EQ(report.dropped_transparent, 1u);
    ASSERT_EQ(s.count(), 2u);
    EXPECT_EQ(s.sh_degree, 1);
    EXPECT_NEAR(s.positions[0], 1.0, 1e-6);
    EXPECT_NEAR(s.positions[1], -2.0, 1e-6);
    EXPECT_NEAR(s.positions[2], 4.0, 1e-6);
    EXPECT_NEAR(s.positions[3], 0.0, 1e-6);
    EXPECT_NEAR(s.positions[4], 2.0, 1e-6);
    EXPECT_FLOAT_EQ(s.scales[0], 1.0f);
    EXPECT_FLOAT_EQ(s.scales[1], static_cast<float>(std::exp(-1.0)));
    EXPECT_FLOAT_EQ(s.scales[2], static_cast<float>(std::exp(-2.0)));
    EXPECT_FLOAT_EQ(s.sh[0], 1.0f);
    EXPECT_FLOAT_EQ(s.sh[1], -1.0f);
    EXPECT_FLOAT_EQ(s.sh[2], 0.0f);
    EXPECT_NEAR(s.opacities[0], 0.2, 1e-6);
    EXPECT_NEAR(s.opacities[1], 1.0, 1e-5);
    // [coefficient][rgb]: coefficient 1 from texel 3, 2 from texel 4 (bytes 128: 0), 3 from 5.
    EXPECT_EQ(std::vector<float>(s.sh.begin() + 3, s.sh.begin() + 12),
              (std::vector<float>{-0.5f, 0.0f, 127 / 256.0f, 0, 0, 0, -0.25f, -0.25f, -0.25f}));
    // Gaussian 1: (w, x, y, z) with x reconstructed from the other three: 1 - w^2 - y^2 - z^2
    // is below 0 here, so x is 0 and the quaternion is then normalised.
    const double small = (128 / 255.0 * 2 - 1) / std::sqrt(2.0);
    const double norm = std::sqrt(1.0 + small * small);
    EXPECT_NEAR(s.rotations[4], std::sqrt(0.5) / norm, 1e-6);
    EXPECT_NEAR(s.rotations[5], 0.0, 1e-6);
    EXPECT_NEAR(s.rotations[6], small / norm, 1e-6);
    EXPECT_NEAR(s.rotations[7], -std::sqrt(0.5) / norm, 1e-6);
}

TEST(SceneIoSog, UnbundledMetaJsonReadsLikeTheArchive) {
    HandSog sog(3);
    sog.set_means(0, {1000, 2000, 3000});
    sog.set_means(2, {60000, 50000, 40000});
    const std::string archive = write_sog(sog);
    const std::string dir = tmp_path("unbundled");
    std::filesystem::create_directories(dir);
    for (const auto& [name, bytes] : sog.entries()) write_file(dir + "/" + name, bytes);
    EXPECT_EQ(catgs::detect_scene_format(dir + "/meta.json"), catgs::SceneFormat::sog_meta);
    EXPECT_EQ(catgs::detect_scene_format(archive), catgs::SceneFormat::sog);
    const catgs::Scene a = catgs::read_sog(archive, absolute());
    const catgs::Scene b = catgs::load_scene(dir + "/meta.json", [] {
        catgs::LoadOptions o = absolute();
        o.chunks = false;
        return o;
    }());
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.rotations, b.rotations);
    EXPECT_EQ(a.count(), 3u);
}

// ---------------------------------------------------------------------------------------
// Bad input: the message names the file, the problem and where.

TEST(SceneIoSog, TruncatedArchive) {
    const std::string whole = write_sog(HandSog(3));
    std::string bytes = read_file(whole);
    const std::string path = tmp_path("truncated.sog");
    write_file(path, bytes.substr(0, bytes.size() / 2));
    expect_error([&] { catgs::read_sog(path); }, path, {"not a readable zip archive", "zip central directory"});
}

TEST(SceneIoSog, MissingZipEntry) {
    HandSog sog(3);
    sog.textures.erase("quats.webp");
    const std::string path = write_sog(sog);
    expect_error([&] { catgs::read_sog(path); }, path,
                 {"zip entry 'quats.webp' is missing", "named by meta.json 'quats.files[0]'"});
}

TEST(SceneIoSog, MissingMetaJson) {
    HandSog sog(3);
    sog.raw["meta.json"] = "";
    auto entries = sog.entries();
    entries.erase("meta.json");
    const std::string path = tmp_path("nometa.sog");
    write_zip(path, entries);
    expect_error([&] { catgs::read_sog(path); }, path, {"zip entry 'meta.json' is missing"});
}

TEST(SceneIoSog, WebpOfTheWrongSize) {
    HandSog sog(3);
    sog.raw["scales.webp"] = HandSog::webp(std::vector<unsigned char>(4, 0), 1, 1);
    const std::string path = write_sog(sog);
    expect_error(
        [&] { catgs::read_sog(path); }, path,
        {"WebP of 1 x 1 texels is too small for the 3 Gaussians of meta.json 'count'", "zip entry 'scales.webp'"});
}

TEST(SceneIoSog, CountLargerThanTheTexturesHold) {
    HandSog sog(3);
    sog.meta["count"] = 1000;
    const std::string path = write_sog(sog);
    expect_error([&] { catgs::read_sog(path); }, path,
                 {"WebP of 2 x 2 texels is too small for the 1000 Gaussians", "zip entry 'means_l.webp'"});
}

TEST(SceneIoSog, CountNoFileCouldHold) {
    HandSog sog(3);
    sog.meta["count"] = 200'000'000;
    const std::string path = write_sog(sog);
    expect_error([&] { catgs::read_sog(path); }, path,
                 {"count 200000000 is more than 1024 Gaussians per byte", "meta.json 'count'"});
}

TEST(SceneIoSog, ZipBombIsRefusedBeforeInflating) {
    HandSog sog(3);
    // 16 MiB of zeros deflate to ~16 KiB; a WebP of 3 Gaussians' textures needs under 400 KB.
    sog.raw["quats.webp"] = std::string(std::size_t{16} << 20, '\0');
    const std::string path = write_sog(sog);
    EXPECT_LT(std::filesystem::file_size(path), std::uintmax_t{1} << 18);
    expect_error([&] { catgs::read_sog(path); }, path,
                 {"zip entry 'quats.webp' declares 16777216 uncompressed bytes, more than the",
                  "that meta.json 'quats.files[0]' can take", "(zip entry 'quats.webp')"});
}

TEST(SceneIoSog, NanAfterDequantisation) {
    HandSog sog(3);
    // A finite range of inf width: min + inf * 0 is NaN for the Gaussian at step 0.
    sog.meta["means"]["mins"] = {-1e308, 0, 0};
    sog.meta["means"]["maxs"] = {1e308, 1, 1};
    const std::string path = write_sog(sog);
    expect_error([&] { catgs::read_sog(path); }, path, {"non-finite value nan", "record 0, field 'x'"});
    catgs::LoadOptions drop;
    drop.drop_invalid = true;
    catgs::LoadReport report;
    EXPECT_THAT(error_of([&] { catgs::read_sog(path, drop, &report); }), HasSubstr("no Gaussians left"));
}

TEST(SceneIoSog, BadJson) {
    HandSog sog(3);
    sog.raw["meta.json"] = "{\"version\": 2, \"count\": ";
    const std::string path = write_sog(sog);
    expect_error([&] { catgs::read_sog(path); }, path,
                 {"meta.json is not valid JSON", "parse error", "meta.json, byte"});
}

TEST(SceneIoSog, WrongJsonTypesAndKeys) {
    struct Case {
        std::function<void(json&)> edit;
        std::vector<std::string> parts;
    };
    const std::vector<Case> cases = {
        {[](json& m) { m.erase("version"); }, {"no 'version'", "version 1 is not supported"}},
        {[](json& m) { m["version"] = 3; }, {"unsupported SOG version 3"}},
        {[](json& m) { m["count"] = -1; }, {"expected an unsigned integer", "meta.json 'count'"}},
        {[](json& m) { m["count"] = 0; }, {"no Gaussians", "meta.json 'count'"}},
        {[](json& m) { m["means"].erase("mins"); }, {"missing key", "meta.json 'means.mins'"}},
        {[](json& m) {
             m["means"]["maxs"] = {1, 2};
         },
         {"expected an array of 3 numbers", "meta.json 'means.maxs'"}},
        {[](json& m) { m["scales"]["codebook"][7] = "x"; }, {"expected a number", "meta.json 'scales.codebook[7]'"}},
        {[](json& m) { m["sh0"]["codebook"][0] = 1e300; }, {"codebook value overflows float", "sh0.codebook"}},
        {[](json& m) { m["quats"]["files"] = {1}; }, {"expected a file name", "meta.json 'quats.files[0]'"}},
        {[](json& m) {
             m["shN"] = {{"bands", 4}};
         },
         {"SH bands 4 is not 0..3", "meta.json 'shN.bands'"}},
    };
    for (std::size_t i = 0; i < cases.size(); ++i) {
        HandSog sog(3);
        cases[i].edit(sog.meta);
        const std::string path = write_sog(sog, "case" + std::to_string(i) + ".sog");
        SCOPED_TRACE(i);
        expect_error([&] { catgs::read_sog(path); }, path, cases[i].parts);
    }
}

TEST(SceneIoSog, BadTexelsNameTheTexel) {
    HandSog tag(3);
    tag.set("quats.webp", 2, {0, 0, 0, 17});
    expect_error([&] { catgs::read_sog(write_sog(tag, "tag.sog")); }, tmp_path("tag.sog"),
                 {"quaternion tag 17 is not 252..255", "zip entry 'quats.webp', texel 2"});
    HandSog label(3, 1);
    label.set("shN_labels.webp", 1, {7, 0, 0, 255});
    expect_error([&] { catgs::read_sog(write_sog(label, "label.sog")); }, tmp_path("label.sog"),
                 {"SH label 7 is beyond the 2-entry palette", "zip entry 'shN_labels.webp', texel 1"});
    HandSog codebook(3);
    codebook.meta["scales"]["codebook"] = {0.0, 1.0};
    codebook.set("scales.webp", 1, {0, 1, 2, 255});
    expect_error(
        [&] { catgs::read_sog(write_sog(codebook, "codebook.sog")); }, tmp_path("codebook.sog"),
        {"index 2 is beyond the 2-entry codebook meta.json 'scales.codebook'", "zip entry 'scales.webp', texel 1"});
}

TEST(SceneIoSog, UnbundledNamesMustStayInTheirFolder) {
    HandSog sog(3);
    sog.meta["means"]["files"] = {"../means_l.webp", "means_u.webp"};
    const std::string dir = tmp_path("escape");
    std::filesystem::create_directories(dir);
    write_file(dir + "/meta.json", sog.meta.dump());
    expect_error([&] { catgs::read_sog(dir + "/meta.json"); }, dir + "/meta.json",
                 {"texture name '../means_l.webp' is not a plain file name", "meta.json 'means.files[0]'"});
}

// A link beside the meta.json may lead anywhere in the scene root, not out of it: the server
// refuses such links as scenes (resolve_path) and sets LoadOptions::scene_root for the rest.
TEST(SceneIoSog, UnbundledTexturesMustResolveInsideTheSceneRoot) {
    namespace fs = std::filesystem;
    const fs::path root = tmp_path("root"), outside = tmp_path("outside");
    fs::remove_all(root);
    fs::remove_all(outside);
    const fs::path scene = root / "scene", shared = root / "shared";
    for (const fs::path& d : {scene, shared, outside}) fs::create_directories(d);
    for (const auto& [name, bytes] : HandSog(3).entries()) write_file((scene / name).string(), bytes);
    const std::string meta = (scene / "meta.json").string();
    auto link_from = [&](const fs::path& dir, const std::string& name) {
        fs::rename(scene / name, dir / name);
        fs::create_symlink(dir / name, scene / name);
    };
    catgs::LoadOptions confined = absolute();
    confined.scene_root = root.string();

    link_from(shared, "sh0.webp");  // elsewhere in the root: followed
    EXPECT_EQ(catgs::read_sog(meta, confined).count(), 3u);

    link_from(outside, "means_u.webp");
    expect_error([&] { catgs::read_sog(meta, confined); }, meta,
                 {"texture 'means_u.webp' resolves outside the scene root (a link?)", "meta.json 'means.files[1]'"});
    // Without a root (catgs-render, the tools) the user's own links are followed.
    EXPECT_EQ(catgs::read_sog(meta, absolute()).count(), 3u);
    // A missing texture still says it is missing.
    fs::remove(outside / "means_u.webp");
    expect_error([&] { catgs::read_sog(meta, confined); }, meta, {"cannot open", "means_u.webp"});
}

TEST(SceneIoSog, MaxRecordsIsCheckedBeforeAnyTexture) {
    HandSog sog(3);
    sog.textures.erase("means_l.webp");  // never reached
    const std::string path = write_sog(sog);
    catgs::LoadOptions options;
    options.max_records = 2;
    expect_error([&] { catgs::read_sog(path, options); }, path, {"3 records exceed the limit of 2"});
}

// ---------------------------------------------------------------------------------------
// Against splat-transform.

TEST(SceneIoSogOracle, LoadsExactlyWhatSplatTransformDecodesAtEveryShDegree) {
    CATGS_NEED_ORACLE();
    catgs::oracle::TempDir dir("sog_oracle");
    std::vector<catgs::Scene> originals;
    std::vector<catgs::oracle::Conversion> to_sog, to_ply;
    for (int degree = 0; degree <= catgs::kMaxShDegree; ++degree) {
        const std::string d = std::to_string(degree);
        originals.push_back(catgs::oracle::asymmetric_scene(degree, 300, 11 + static_cast<unsigned>(degree)));
        catgs::write_ply(originals.back(), dir.path("in" + d + ".ply"));
        // -g cpu: the SH palette's k-means runs on the CPU (no GPU in CI).
        to_sog.push_back({dir.path("in" + d + ".ply"), dir.path("out" + d + ".sog"), {"-g", "cpu"}});
        to_ply.push_back({dir.path("out" + d + ".sog"), dir.path("decoded" + d + ".ply"), {}});
    }
    ASSERT_TRUE(catgs::oracle::convert_all(to_sog));
    ASSERT_TRUE(catgs::oracle::convert_all(to_ply));
    for (int degree = 0; degree <= catgs::kMaxShDegree; ++degree) {
        SCOPED_TRACE(degree);
        const catgs::Scene& original = originals[static_cast<std::size_t>(degree)];
        const catgs::Scene loaded = catgs::read_sog(to_sog[static_cast<std::size_t>(degree)].out, absolute());
        const catgs::Scene reference = catgs::read_ply(to_ply[static_cast<std::size_t>(degree)].out, absolute());
        ASSERT_EQ(loaded.count(), original.count());
        EXPECT_EQ(loaded.sh_degree, degree);
        ASSERT_EQ(reference.count(), loaded.count());
        // The same floats: the reader rounds as splat-transform's decoder does.
        EXPECT_EQ(loaded.positions, reference.positions);
        EXPECT_EQ(loaded.scales, reference.scales);
        EXPECT_EQ(loaded.opacities, reference.opacities);
        EXPECT_EQ(loaded.sh, reference.sh);
        for (std::size_t i = 0; i < loaded.rotations.size(); ++i)
            ASSERT_NEAR(loaded.rotations[i], reference.rotations[i], 1e-6) << i;
        // The axes: the bounds of the original within the 16-bit quantisation.
        for (int a = 0; a < 3; ++a) {
            EXPECT_NEAR(loaded.bounds.min[a], original.bounds.min[a], 1e-3) << a;
            EXPECT_NEAR(loaded.bounds.max[a], original.bounds.max[a], 1e-3) << a;
        }
    }
}

TEST(SceneIoSogOracle, UnbundledOutputLoads) {
    CATGS_NEED_ORACLE();
    catgs::oracle::TempDir dir("sog_unbundled");
    const catgs::Scene original = catgs::oracle::asymmetric_scene(0, 200, 5);
    const std::string ply = dir.path("in.ply");
    catgs::write_ply(original, ply);
    ASSERT_TRUE(catgs::oracle::convert({ply, dir.path("meta.json"), {}}));
    ASSERT_TRUE(std::filesystem::exists(dir.path("means_l.webp")));
    const catgs::Scene loaded = catgs::load_scene(dir.path("meta.json"));
    EXPECT_EQ(loaded.count(), original.count());
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(loaded.bounds.max[a], original.bounds.max[a], 1e-3) << a;
}

}  // namespace
