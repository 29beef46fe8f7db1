// The .splat reader: 32-byte records decoded by hand, and the files it refuses.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "catgs/error.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"
#include "scene_io_fixtures.hpp"

namespace {

using namespace catgs::scene_io_test;

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

}  // namespace
