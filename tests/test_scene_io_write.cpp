// write_ply: exact round trips through both readers (also with UTM-sized origins), the
// graphdeco layout of what it writes, and its errors.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>

#include "catgs/common/files.hpp"
#include "catgs/error.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"
#include "scene_io_fixtures.hpp"

namespace {

using namespace catgs::scene_io_test;

// =======================================================================================
// write_ply.

/// Rounded to a multiple of 2^-20 so that origin +- extent is exact in double and the reader's
/// bounds centre reproduces the origin bit for bit.
double grid(double v) {
    return std::round(std::ldexp(v, 20)) / std::ldexp(1.0, 20);
}

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
    std::string bytes = catgs::read_file(path, "written PLY");
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

}  // namespace
