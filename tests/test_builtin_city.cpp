#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>
#include <unordered_map>
#include <vector>

#include "catgs/builtin_city.hpp"
#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/math.hpp"

namespace {

using catgs::CityParams;
using catgs::Scene;

Scene city(std::uint64_t gaussians, std::uint64_t seed = 1) {
    return catgs::make_city(CityParams{gaussians, seed});
}

template <typename T>
bool bit_identical(const std::vector<T>& a, const std::vector<T>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

void expect_bit_identical(const Scene& a, const Scene& b) {
    EXPECT_TRUE(bit_identical(a.positions, b.positions));
    EXPECT_TRUE(bit_identical(a.scales, b.scales));
    EXPECT_TRUE(bit_identical(a.rotations, b.rotations));
    EXPECT_TRUE(bit_identical(a.opacities, b.opacities));
    EXPECT_TRUE(bit_identical(a.sh, b.sh));
    EXPECT_EQ(a.sh_degree, b.sh_degree);
}

catgs::Mat3<double> rotation_of(const Scene& s, std::size_t i) {
    const float* q = &s.rotations[4 * i];
    return catgs::quat_to_matrix<double>(q[0], q[1], q[2], q[3]);
}

// Colour as graphdeco evaluates it (before the clamp at zero), written out independently of
// the generator's lobe code. dir is camera -> Gaussian, unit length.
std::array<double, 3> sh_colour(const Scene& s, std::size_t i, double x, double y, double z) {
    const double xx = x * x, yy = y * y, zz = z * z;
    const double basis[16] = {0.28209479177387814,
                              -0.4886025119029199 * y,
                              0.4886025119029199 * z,
                              -0.4886025119029199 * x,
                              1.0925484305920792 * x * y,
                              -1.0925484305920792 * y * z,
                              0.31539156525252005 * (2 * zz - xx - yy),
                              -1.0925484305920792 * x * z,
                              0.5462742152960396 * (xx - yy),
                              -0.5900435899266435 * y * (3 * xx - yy),
                              2.890611442640554 * x * y * z,
                              -0.4570457994644658 * y * (4 * zz - xx - yy),
                              0.3731763325901154 * z * (2 * zz - 3 * xx - 3 * yy),
                              -0.4570457994644658 * x * (4 * zz - xx - yy),
                              1.445305721320277 * z * (xx - yy),
                              -0.5900435899266435 * x * (xx - 3 * yy)};
    std::array<double, 3> rgb{0.5, 0.5, 0.5};
    const float* sh = &s.sh[s.sh_floats_per_gaussian() * i];
    for (int k = 0; k < 16; ++k)
        for (int c = 0; c < 3; ++c) rgb[c] += basis[k] * sh[3 * k + c];
    return rgb;
}

TEST(BuiltinCity, ExactCountForSeveralSizes) {
    for (std::uint64_t n : {10'000ull, 100'000ull, 330'007ull}) {
        const Scene s = city(n);
        EXPECT_EQ(s.count(), n);
        EXPECT_EQ(s.sh_degree, 3);
        EXPECT_NO_THROW(s.check_consistent("city"));
        EXPECT_EQ(s.origin, (std::array<double, 3>{0, 0, 0}));
    }
}

TEST(BuiltinCity, BitIdenticalAcrossRunsAndThreadCounts) {
    const CityParams params{200'003, 5};  // several chunks, the last one partial
    const Scene a = catgs::make_city(params);
    const Scene b = catgs::make_city(params);
    const Scene one = catgs::detail::make_city_with_threads(params, {}, 1);
    const Scene three = catgs::detail::make_city_with_threads(params, {}, 3);
    expect_bit_identical(a, b);
    expect_bit_identical(a, one);
    expect_bit_identical(a, three);
}

TEST(BuiltinCity, AllValuesValid) {
    const Scene s = city(100'000, 3);
    for (std::size_t i = 0; i < s.count(); ++i) {
        for (int a = 0; a < 3; ++a) {
            ASSERT_TRUE(std::isfinite(s.positions[3 * i + a])) << i;
            ASSERT_TRUE(std::isfinite(s.scales[3 * i + a]) && s.scales[3 * i + a] > 0) << i;
        }
        const float* q = &s.rotations[4 * i];
        ASSERT_NEAR(std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), 1.0, 1e-6) << i;
        ASSERT_GT(s.opacities[i], 1.0f / 255.0f) << i;
        ASSERT_LT(s.opacities[i], 1.0f) << i;
        for (std::size_t k = 0; k < s.sh_floats_per_gaussian(); ++k)
            ASSERT_TRUE(std::isfinite(s.sh[s.sh_floats_per_gaussian() * i + k])) << i;
    }
}

TEST(BuiltinCity, SplatsAreFlatAndGroundSplatsLieInTheGround) {
    const Scene s = city(50'000);
    std::size_t ground = 0, translucent = 0;
    for (std::size_t i = 0; i < s.count(); ++i) {
        const float* sc = &s.scales[3 * i];
        const float largest = std::max({sc[0], sc[1], sc[2]}), smallest = std::min({sc[0], sc[1], sc[2]});
        ASSERT_GE(largest / smallest, 4.0f) << i;  // leaf clumps are the least flat
        if (s.opacities[i] < 0.75f) ++translucent;
        if (s.positions[3 * i + 2] != 0.0f) continue;
        ++ground;
        // The thin axis (scale 2, column 2 of R) is the ground's normal.
        EXPECT_GE(largest / sc[2], 10.0f) << i;
        EXPECT_GT(std::abs(rotation_of(s, i).m[2][2]), 0.999) << i;
    }
    // 40% of the budget is ground; 15% is trees, whose canopies are semi-transparent.
    EXPECT_NEAR(static_cast<double>(ground) / s.count(), 0.40, 0.005);
    EXPECT_GT(static_cast<double>(translucent) / s.count(), 0.10);
}

// Looking straight down at the ground, the ground splats alone leave no background visible:
// the transmittance through them (the top-view marginals of the 3D Gaussians, as an
// orthographic renderer would blend them) stays low everywhere in a 20 x 20 m patch.
TEST(BuiltinCity, GroundIsCoveredWithoutHoles) {
    for (std::uint64_t n : {10'000ull, 1'000'000ull}) {
        const Scene s = city(n);
        constexpr double kPatch0 = -40, kPatch1 = -20, kCell = 4;
        struct Flat {
            double x, y, a, b, c, opacity;  // inverse 2D covariance [[a, b], [b, c]]
        };
        std::unordered_map<long long, std::vector<Flat>> grid;
        const auto key = [](double x, double y) {
            return static_cast<long long>(std::floor(x / kCell)) * 100000 +
                   static_cast<long long>(std::floor(y / kCell));
        };
        for (std::size_t i = 0; i < s.count(); ++i) {
            const double x = s.positions[3 * i], y = s.positions[3 * i + 1];
            if (s.positions[3 * i + 2] != 0.0f || x < kPatch0 - 10 || x > kPatch1 + 10 || y < kPatch0 - 10 ||
                y > kPatch1 + 10)
                continue;
            const auto r = rotation_of(s, i);
            double cov[2][2] = {};
            for (int p = 0; p < 2; ++p)
                for (int q = 0; q < 2; ++q)
                    for (int k = 0; k < 3; ++k)
                        cov[p][q] += r.m[p][k] * r.m[q][k] * s.scales[3 * i + k] * s.scales[3 * i + k];
            const double det = cov[0][0] * cov[1][1] - cov[0][1] * cov[0][1];
            grid[key(x, y)].push_back({x, y, cov[1][1] / det, -cov[0][1] / det, cov[0][0] / det, s.opacities[i]});
        }
        double worst = 0;
        for (double px = kPatch0; px <= kPatch1; px += 0.1)
            for (double py = kPatch0; py <= kPatch1; py += 0.1) {
                double transmittance = 1;
                for (int dx = -2; dx <= 2; ++dx)
                    for (int dy = -2; dy <= 2; ++dy) {
                        const auto it = grid.find(key(px + dx * kCell, py + dy * kCell));
                        if (it == grid.end()) continue;
                        for (const Flat& g : it->second) {
                            const double ex = px - g.x, ey = py - g.y;
                            const double power = 0.5 * (g.a * ex * ex + 2 * g.b * ex * ey + g.c * ey * ey);
                            transmittance *= 1 - std::min(catgs::kMaxAlpha, g.opacity * std::exp(-power));
                        }
                    }
                worst = std::max(worst, transmittance);
            }
        EXPECT_LT(worst, 0.05) << n << " Gaussians";
    }
}

TEST(BuiltinCity, ShDegreeThreeWithViewDependentColour) {
    const Scene s = city(100'000);
    ASSERT_EQ(s.sh_degree, 3);
    const std::size_t stride = s.sh_floats_per_gaussian();
    double largest = 0;
    std::size_t with_rest = 0, strongly_glossy = 0;
    double spread_sum = 0;
    // Directions around the sphere: the renderer's camera -> Gaussian direction.
    std::vector<std::array<double, 3>> dirs;
    for (int i = 0; i < 64; ++i) {
        const double z = 1 - (2 * i + 1) / 64.0, ring = std::sqrt(1 - z * z), phi = 2.399963229728653 * i;
        dirs.push_back({ring * std::cos(phi), ring * std::sin(phi), z});
    }
    for (std::size_t i = 0; i < s.count(); ++i) {
        bool nonzero = false;
        for (std::size_t k = 3; k < stride; ++k) {
            largest = std::max(largest, static_cast<double>(std::abs(s.sh[stride * i + k])));
            nonzero = nonzero || s.sh[stride * i + k] != 0.0f;
        }
        with_rest += nonzero;
        if (i % 7 != 0) continue;  // colour evaluation on a sample keeps the test fast
        double lo = 1e9, hi = -1e9;
        for (const auto& d : dirs) {
            const auto rgb = sh_colour(s, i, d[0], d[1], d[2]);
            for (double v : rgb) {
                ASSERT_GT(v, -0.05) << i;  // a sensible range: no channel far out of [0, 1]
                ASSERT_LT(v, 1.15) << i;
            }
            lo = std::min(lo, rgb[1]);
            hi = std::max(hi, rgb[1]);
        }
        spread_sum += hi - lo;
        strongly_glossy += hi - lo > 0.1;
    }
    EXPECT_EQ(with_rest, s.count());
    EXPECT_GT(largest, 0.05);  // a few percent ...
    EXPECT_LT(largest, 0.25);  // ... to ~0.2
    EXPECT_GT(spread_sum / (s.count() / 7.0), 0.02);
    EXPECT_GT(strongly_glossy, 100u);  // windows and solar panels
}

TEST(BuiltinCity, BoundsArePlausible) {
    for (std::uint64_t seed : {1u, 2u, 3u}) {
        const Scene s = city(100'000, seed);
        EXPECT_NEAR(s.bounds.min[2], 0.0, 0.5) << seed;
        EXPECT_GE(s.bounds.max[2], 60.0) << seed;  // the tallest tower is 60 m
        EXPECT_LE(s.bounds.max[2], 66.0) << seed;  // plus roof units
        for (int a = 0; a < 2; ++a) {
            EXPECT_LT(s.bounds.min[a], -95.0) << seed;
            EXPECT_GT(s.bounds.max[a], 95.0) << seed;
            EXPECT_GT(s.bounds.min[a], -105.0) << seed;
            EXPECT_LT(s.bounds.max[a], 105.0) << seed;
        }
    }
}

TEST(BuiltinCity, DifferentSeedsGiveDifferentLayouts) {
    const Scene a = city(100'000, 1), b = city(100'000, 2);
    ASSERT_EQ(a.count(), b.count());
    // Not just different jitter: a different layout moves most Gaussians by metres.
    std::size_t moved = 0;
    for (std::size_t i = 0; i < a.count(); ++i) {
        double d2 = 0;
        for (int k = 0; k < 3; ++k) d2 += std::pow(a.positions[3 * i + k] - b.positions[3 * i + k], 2);
        moved += d2 > 1.0;
    }
    EXPECT_GT(static_cast<double>(moved) / a.count(), 0.3);
}

TEST(BuiltinCity, ReportsProgressFromTheCallingThread) {
    std::vector<double> fractions;
    std::string label;
    catgs::make_city(CityParams{300'000, 1}, [&](double f, const std::string& l) {
        fractions.push_back(f);
        label = l;
    });
    ASSERT_GE(fractions.size(), 2u);
    EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
    EXPECT_EQ(fractions.back(), 1.0);
    EXPECT_EQ(label, "generating builtin city");
}

TEST(BuiltinCity, RejectsCountsOutOfRange) {
    EXPECT_THROW(city(9'999), catgs::Error);
    EXPECT_THROW(city(20'000'001), catgs::Error);
}

TEST(CitySpec, ParsesValidSpecs) {
    CityParams p = catgs::parse_city_spec("builtin:city");
    EXPECT_EQ(p.gaussians, 1'000'000u);
    EXPECT_EQ(p.seed, 1u);
    p = catgs::parse_city_spec("builtin:city?gaussians=20000&seed=7");
    EXPECT_EQ(p.gaussians, 20'000u);
    EXPECT_EQ(p.seed, 7u);
    p = catgs::parse_city_spec("builtin:city?seed=18446744073709551615&gaussians=10000");
    EXPECT_EQ(p.gaussians, 10'000u);
    EXPECT_EQ(p.seed, 18446744073709551615ull);
    EXPECT_EQ(catgs::parse_city_spec("builtin:city?gaussians=2e6").gaussians, 2'000'000u);
    EXPECT_EQ(catgs::parse_city_spec("builtin:city?gaussians=1.5e6").gaussians, 1'500'000u);
    EXPECT_EQ(catgs::parse_city_spec("builtin:city?gaussians=20000000").gaussians, 20'000'000u);
}

TEST(CitySpec, ErrorsNameTheProblem) {
    const std::vector<std::pair<std::string, std::vector<std::string>>> cases{
        {"builtin:forest", {"builtin:forest: unknown generator 'forest' (available: city)"}},
        {"builtin:forest?gaussians=5", {"unknown generator 'forest'"}},
        {"city", {"city: not a builtin spec"}},
        {"builtin:", {"missing a name"}},
        {"builtin:city?colour=red", {"unknown key 'colour'", "available: gaussians, seed"}},
        {"builtin:city?gaussians", {"'gaussians' is missing '='"}},
        {"builtin:city?gaussians=12x", {"value '12x' of 'gaussians' is not a non-negative integer"}},
        {"builtin:city?gaussians=1.5", {"'1.5'", "not a non-negative integer"}},
        {"builtin:city?seed=-3", {"'-3'", "not a non-negative integer"}},
        {"builtin:city?gaussians=1e300", {"not a non-negative integer"}},
        {"builtin:city?gaussians=9999", {"gaussians 9999 is outside [10000, 20000000]"}},
        {"builtin:city?gaussians=20000001", {"outside [10000, 20000000]"}},
        {"builtin:city?seed=1&seed=2", {"duplicate key 'seed'"}},
        {"builtin:city?", {"empty parameter"}},
        {"builtin:city?seed=1&", {"empty parameter"}},
        {"builtin:city?seed=", {"key 'seed' has an empty value"}},
    };
    for (const auto& [spec, expected] : cases) {
        try {
            catgs::parse_city_spec(spec);
            ADD_FAILURE() << spec << " was accepted";
        } catch (const catgs::Error& e) {
            const std::string message = e.what();
            EXPECT_EQ(message.rfind(spec + ": ", 0), 0u) << message;
            for (const auto& part : expected) EXPECT_NE(message.find(part), std::string::npos) << message;
        }
    }
}

}  // namespace
