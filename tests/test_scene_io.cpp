// Scene loading whatever the reader: invalid records dropped and counted (the validation
// every reader shares), load_scene's dispatch by extension and builtin: spec, progress, a
// real scene when present, and robustness: any byte string either loads or raises
// catgs::Error. The readers themselves: test_scene_io_ply.cpp, test_scene_io_bad_ply.cpp,
// test_scene_io_splat.cpp, test_scene_io_write.cpp; fixtures: scene_io_fixtures.hpp.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"
#include "scene_io_fixtures.hpp"

namespace {

using namespace catgs::scene_io_test;

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
