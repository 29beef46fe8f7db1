// The stage functions that the backends share, one test each against a double reference
// written apart from them: projection geometry (stages/project.hpp), sort keys
// (stages/keys.hpp), the merge of split tiles (stages/split.hpp) and the envelope bound
// (stages/footprint.hpp, stages/envelope.hpp); test_stage_tiles.cpp holds the tile stages.
// Double must match its reference to rounding; float must match double within a tolerance
// measured over fresh seeds (the worst seen is quoted next to each), or, for a decision (a
// tile in or out), agree except where the double value lies within that tolerance of the
// threshold. gpu/test_stage_math_device.cu runs the same functions on the device.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iostream>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "catgs/constants.hpp"
#include "catgs/stages/envelope.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/keys.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "stage_inputs.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

namespace stage = test::stage;

// --- Projection geometry ----------------------------------------------------------------

/// Independent of project_geometry: the EWA covariance J W Sigma W^T J^T + b I formed the
/// textbook way (Sigma = R S S^T R^T, then the two products), the mean by the pinhole model.
struct EwaReference {
    bool visible;
    double mean_x, mean_y, depth;
    double xx, xy, yy;
};

EwaReference ewa_reference(const GaussianRef& g, const Camera& camera) {
    const auto& r = camera.pose.rotation;
    const auto& t = camera.pose.translation;
    double pc[3];
    for (int i = 0; i < 3; ++i)
        pc[i] = r[3 * i] * g.position[0] + r[3 * i + 1] * g.position[1] + r[3 * i + 2] * g.position[2] + t[i];
    EwaReference out{};
    out.visible = pc[2] > kDefaultNearPlane;
    if (!out.visible) return out;
    const Intrinsics& k = camera.intrinsics;
    out.mean_x = k.fx * pc[0] / pc[2] + k.cx;
    out.mean_y = k.fy * pc[1] / pc[2] + k.cy;
    out.depth = pc[2];
    // The clamp of the Jacobian's direction (View::clamp_*): the image plus 0.15 per side.
    const double slack = kJacobianClampFactor - 1.0;
    const double lim_l = k.cx / k.fx + slack * 0.5 * k.width / k.fx,
                 lim_r = (k.width - k.cx) / k.fx + slack * 0.5 * k.width / k.fx;
    const double lim_t = k.cy / k.fy + slack * 0.5 * k.height / k.fy,
                 lim_b = (k.height - k.cy) / k.fy + slack * 0.5 * k.height / k.fy;
    const double tx = std::clamp(pc[0] / pc[2], -lim_l, lim_r), ty = std::clamp(pc[1] / pc[2], -lim_t, lim_b);
    const double j[2][3] = {{k.fx / pc[2], 0, -k.fx * tx / pc[2]}, {0, k.fy / pc[2], -k.fy * ty / pc[2]}};
    const Mat3<double> sigma = covariance_3d<double>(g.scale, g.rotation);
    double jw[2][3] = {};
    for (int a = 0; a < 2; ++a)
        for (int c = 0; c < 3; ++c)
            for (int m = 0; m < 3; ++m) jw[a][c] += j[a][m] * r[3 * m + c];
    double s2[2][2] = {};
    for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b)
            for (int c = 0; c < 3; ++c)
                for (int d = 0; d < 3; ++d) s2[a][b] += jw[a][c] * sigma.m[c][d] * jw[b][d];
    out.xx = s2[0][0] + kCovarianceBlur;
    out.xy = s2[0][1];
    out.yy = s2[1][1] + kCovarianceBlur;
    return out;
}

/// Cameras near the scene origin, as the renderer's camera-relative View makes every scene.
Camera camera_near_origin(std::mt19937_64& rng) {
    Camera c = stage::random_camera(rng);
    const std::array<double, 3> eye{stage::uniform(rng, -2, 2), stage::uniform(rng, -2, 2), stage::uniform(rng, -2, 2)};
    std::normal_distribution<double> n(0, 1);
    c.pose = look_at(eye, {eye[0] + n(rng), eye[1] + n(rng), eye[2] + n(rng)}, {0, 0, 1});
    return c;
}

TEST(StageProject, DoubleGeometryIsTheEwaCovarianceAndThePinholeMean) {
    const std::uint64_t seed = test::fresh_seed("stage project double");
    std::mt19937_64 rng(seed);
    int visible = 0;
    for (int trial = 0; trial < 40; ++trial) {
        const Camera camera = camera_near_origin(rng);
        const View<double> view = make_view<double>(camera, {0, 0, 0});
        const stage::GaussianArrays g = stage::random_gaussians(rng, 500, camera);
        for (std::size_t i = 0; i < g.count(); ++i) {
            const EwaReference ref = ewa_reference(g.ref(i), camera);
            Projected<double> p;
            const bool got = project_geometry(g.ref(i), view, p);
            ASSERT_EQ(got, ref.visible) << "gaussian " << i << " (CATGS_TEST_SEED=" << seed << ")";
            if (!got) continue;
            ++visible;
            const double scale = std::max(ref.xx, ref.yy);
            EXPECT_NEAR(p.mean.x, ref.mean_x, 1e-9 * (1 + std::fabs(ref.mean_x)));
            EXPECT_NEAR(p.mean.y, ref.mean_y, 1e-9 * (1 + std::fabs(ref.mean_y)));
            EXPECT_NEAR(p.depth, ref.depth, 1e-12 * (1 + ref.depth));
            EXPECT_EQ(p.key_depth, static_cast<float>(p.depth));
            EXPECT_NEAR(p.cov.x, ref.xx, 1e-9 * scale) << "gaussian " << i;
            EXPECT_NEAR(p.cov.y, ref.xy, 1e-9 * scale) << "gaussian " << i;
            EXPECT_NEAR(p.cov.z, ref.yy, 1e-9 * scale) << "gaussian " << i;
            // The conic inverts the covariance: conic * cov = I, relative to the largest term.
            const double c0 = p.conic.x * ref.xx + p.conic.y * ref.xy, c1 = p.conic.y * ref.xy + p.conic.z * ref.yy;
            const double off = p.conic.x * ref.xy + p.conic.y * ref.yy;
            const double cond = std::max(std::fabs(p.conic.x), std::fabs(p.conic.z)) * scale;
            EXPECT_NEAR(c0, 1.0, 1e-9 * cond) << "gaussian " << i;
            EXPECT_NEAR(c1, 1.0, 1e-9 * cond) << "gaussian " << i;
            EXPECT_NEAR(off, 0.0, 1e-9 * cond) << "gaussian " << i;
        }
    }
    EXPECT_GT(visible, 10000);
}

// Float against double, worst over 40 runs (630000 Gaussians) quoted. The mean is off by
// float's rounding of the view transform, which is eps (|p| + |t|) in camera space, divided by
// the depth (measured 1.0e-7 of that scale). The covariance, formed from M = J W R S, by ulps
// of the largest variance any orientation of the Gaussian could project to, (f s_max / z)^2:
// W's rounding turns a needle's long axis, whose end-on variance then moves by eps of that
// (measured 6.7e-6). The conic, whose entries are at most 1 / blur, absolutely (measured
// 5.7e-4): q = d^T conic d at an offset d is then off by less than |d|^2 times that, within
// the bound of StressBugs.FloatProjectsNearlyRankOneCovariances (1e-3 |d|^2 / blur). Float
// culls where double does, except within rounding of the near plane (about one seed in 40).
TEST(StageProject, FloatGeometryMatchesDoubleWithinMeasuredTolerance) {
    const std::uint64_t seed = test::fresh_seed("stage project float");
    std::mt19937_64 rng(seed);
    double worst_mean = 0, worst_cov = 0, worst_conic = 0;
    int compared = 0, near_plane_band = 0;
    for (int trial = 0; trial < 40; ++trial) {
        const Camera camera = camera_near_origin(rng);
        const View<double> vd = make_view<double>(camera, {0, 0, 0});
        const View<float> vf = make_view<float>(camera, {0, 0, 0});
        const stage::GaussianArrays g = stage::random_gaussians(rng, 500, camera);
        const std::array<double, 3> c = camera_centre(camera.pose);
        const double eye = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        for (std::size_t i = 0; i < g.count(); ++i) {
            Projected<double> pd;
            Projected<float> pf;
            const bool d = project_geometry(g.ref(i), vd, pd), f = project_geometry(g.ref(i), vf, pf);
            const double p =
                std::sqrt(g.positions[3 * i] * g.positions[3 * i] + g.positions[3 * i + 1] * g.positions[3 * i + 1] +
                          g.positions[3 * i + 2] * g.positions[3 * i + 2]);
            // Within float's rounding of the depth (pc = R p + t, eps (|p| + |t|) a term, three
            // terms) of the near plane either answer is right: seen once in ~40 fresh seeds, a
            // Gaussian at depth 0.2000000107 against the plane at 0.2.
            const double depth_rounding = 3 * std::numeric_limits<float>::epsilon() * (1 + p + eye);
            if (std::fabs(pd.depth - vd.near_plane) <= depth_rounding) {
                ++near_plane_band;
                continue;
            }
            ASSERT_EQ(f, d) << "gaussian " << i << " at depth " << pd.depth << " (CATGS_TEST_SEED=" << seed << ")";
            if (!d) continue;
            ++compared;
            // pc = R p + t rounds by eps (|p| + |t|), and the mean divides it by the depth.
            const double off_axis = std::fabs(pd.mean.x - vd.cx) + std::fabs(pd.mean.y - vd.cy);
            const double mean_scale = (std::max(vd.fx, vd.fy) + off_axis) * (1 + p + eye) / pd.depth +
                                      std::fabs(pd.mean.x) + std::fabs(pd.mean.y);
            const double mean_err =
                std::max(std::fabs(pf.mean.x - pd.mean.x), std::fabs(pf.mean.y - pd.mean.y)) / mean_scale;
            const double max_scale = std::max({g.scales[3 * i], g.scales[3 * i + 1], g.scales[3 * i + 2]});
            const double reach = std::max(vd.fx, vd.fy) * max_scale / pd.depth;
            const double cov_scale =
                std::max({std::fabs(pd.cov.x), std::fabs(pd.cov.z), reach * reach + kCovarianceBlur});
            const double cov_err = std::max({std::fabs(pf.cov.x - pd.cov.x), std::fabs(pf.cov.y - pd.cov.y),
                                             std::fabs(pf.cov.z - pd.cov.z)}) /
                                   cov_scale;
            const double conic_err = std::max({std::fabs(pf.conic.x - pd.conic.x), std::fabs(pf.conic.y - pd.conic.y),
                                               std::fabs(pf.conic.z - pd.conic.z)});
            worst_mean = std::max(worst_mean, mean_err);
            worst_cov = std::max(worst_cov, cov_err);
            worst_conic = std::max(worst_conic, conic_err);
            EXPECT_LT(mean_err, 1e-6) << "gaussian " << i << " (CATGS_TEST_SEED=" << seed << ")";
            EXPECT_LT(cov_err, 5e-5) << "gaussian " << i << " (CATGS_TEST_SEED=" << seed << ")";
            EXPECT_LT(conic_err, 1e-3 / kCovarianceBlur) << "gaussian " << i << " (CATGS_TEST_SEED=" << seed << ")";
            EXPECT_EQ(pf.key_depth, pd.key_depth) << "the sort depth is computed in double in every precision";
        }
    }
    std::cout << "[stage] project float vs double over " << compared << ": mean " << worst_mean << ", cov " << worst_cov
              << " (relative), conic " << worst_conic << " (absolute); " << near_plane_band
              << " within rounding of the near plane" << std::endl;
    EXPECT_GT(compared, 10000);
}

// --- Sort keys ---------------------------------------------------------------------------

// Keys sort as (tile, depth) pairs sort: the tile in the high bits, then positive float depths
// in their order, over the whole float range (denormals to the largest finite), ties kept in
// emission order by a stable sort.
TEST(StageKeys, KeysSortByTileThenDepth) {
    const std::uint64_t seed = test::fresh_seed("stage keys");
    std::mt19937_64 rng(seed);
    const std::vector<float> depths = stage::random_depths(rng, 20000);
    std::vector<std::uint32_t> tiles;
    std::vector<std::uint64_t> keys;
    for (float d : depths) {
        const double pick = stage::uniform(rng, 0, 1);
        const std::uint32_t tile = pick < 0.3    ? static_cast<std::uint32_t>(stage::uniform(rng, 0, 4))
                                   : pick < 0.35 ? 0xFFFFFFFFu
                                                 : static_cast<std::uint32_t>(stage::uniform(rng, 0, 4294967295.0));
        tiles.push_back(tile);
        keys.push_back(make_sort_key(tile, d));
        ASSERT_EQ(key_tile(keys.back()), tile);
        std::uint32_t bits, back;
        const float decoded = depth_of_key(keys.back());
        std::memcpy(&bits, &d, sizeof bits);
        std::memcpy(&back, &decoded, sizeof back);
        ASSERT_EQ(back, bits);
    }
    std::vector<std::size_t> by_key(depths.size()), by_pair(depths.size());
    std::iota(by_key.begin(), by_key.end(), 0);
    std::iota(by_pair.begin(), by_pair.end(), 0);
    std::stable_sort(by_key.begin(), by_key.end(), [&](std::size_t a, std::size_t b) { return keys[a] < keys[b]; });
    std::stable_sort(by_pair.begin(), by_pair.end(), [&](std::size_t a, std::size_t b) {
        if (tiles[a] != tiles[b]) return tiles[a] < tiles[b];
        return static_cast<double>(depths[a]) < static_cast<double>(depths[b]);
    });
    EXPECT_EQ(by_key, by_pair) << "(CATGS_TEST_SEED=" << seed << ")";
}

// --- Merge -------------------------------------------------------------------------------

/// A pixel's list: alphas 1/255 .. 0.99 and colours 0 .. 2, ending before the transmittance
/// falls below 2e-4, so that the merge's stop (T < 1e-4) does not cut the composite short.
struct PixelList {
    std::vector<double> alphas, colours;
};

PixelList random_list(std::mt19937_64& rng) {
    PixelList l;
    double t = 1;
    const int n = static_cast<int>(stage::uniform(rng, 1, 300));
    const double max_alpha = stage::uniform(rng, 0, 1) < 0.5 ? 0.1 : kMaxAlpha;
    for (int i = 0; i < n; ++i) {
        const double a = stage::uniform(rng, kMinAlpha, max_alpha);
        if (t * (1 - a) < 2e-4) break;
        t *= 1 - a;
        l.alphas.push_back(a);
        for (int c = 0; c < 3; ++c) l.colours.push_back(stage::uniform(rng, 0, 2));
    }
    return l;
}

/// The split tile's pixel: each sub-task of threshold k blends its slice from T = 1, and the
/// merge composites the partials front to back.
template <typename T>
MergeState<T> merged(const std::vector<T>& alphas, const std::vector<T>& colours, std::uint32_t k) {
    MergeState<T> m;
    const std::uint32_t parts = split_count(alphas.size(), k) + 1;
    for (std::uint32_t i = 0; i < parts; ++i) {
        std::uint64_t begin, end;
        subtask_range(0, alphas.size(), k, i, begin, end);
        merge_partial(m, stage::blend_slice(alphas, colours, begin, end));
    }
    return m;
}

// The merge of partial (R, A) equals blending the whole list in the same precision: to
// rounding in double (1e-12, measured 3e-15), within 1e-5 in float (measured 1.7e-6: the
// regrouped sums of up to 300 entries).
TEST(StageMerge, CompositeOfPartialsIsTheBlendOfTheWholeList) {
    const std::uint64_t seed = test::fresh_seed("stage merge");
    std::mt19937_64 rng(seed);
    double worst_double = 0, worst_float = 0;
    for (int i = 0; i < 3000; ++i) {
        const PixelList l = random_list(rng);
        const std::uint32_t k = static_cast<std::uint32_t>(stage::uniform(rng, 1, 64));
        const Partial<double> whole = stage::blend_slice(l.alphas, l.colours, 0, l.alphas.size());
        const MergeState<double> md = merged(l.alphas, l.colours, k);
        const std::vector<float> af(l.alphas.begin(), l.alphas.end()), cf(l.colours.begin(), l.colours.end());
        const MergeState<float> mf = merged(af, cf, k);
        const Partial<float> whole_f = stage::blend_slice(af, cf, 0, af.size());
        const double dd[4] = {md.colour.x - whole.colour.x, md.colour.y - whole.colour.y, md.colour.z - whole.colour.z,
                              md.transmittance - whole.transmittance};
        const double df[4] = {mf.colour.x - whole_f.colour.x, mf.colour.y - whole_f.colour.y,
                              mf.colour.z - whole_f.colour.z, mf.transmittance - whole_f.transmittance};
        for (int c = 0; c < 4; ++c) {
            worst_double = std::max(worst_double, std::fabs(dd[c]));
            worst_float = std::max(worst_float, std::fabs(df[c]));
        }
        ASSERT_LT(worst_double, 1e-12) << "list " << i << " of " << l.alphas.size() << ", k " << k
                                       << " (CATGS_TEST_SEED=" << seed << ")";
        ASSERT_LT(worst_float, 1e-5) << "list " << i << " of " << l.alphas.size() << ", k " << k
                                     << " (CATGS_TEST_SEED=" << seed << ")";
    }
    std::cout << "[stage] merge vs whole list: double " << worst_double << ", float " << worst_float << std::endl;
}

// Once the running transmittance is below 1e-4 the merge ignores later sub-tasks, as the
// unsplit blend stops.
TEST(StageMerge, StopsOnceTheTransmittanceIsBelowTheStop) {
    MergeState<double> m;
    merge_partial(m, Partial<double>{{0.5, 0.25, 0.125}, 0.5});
    EXPECT_FALSE(m.done);
    merge_partial(m, Partial<double>{{0.2, 0.2, 0.2}, 1e-4});
    EXPECT_TRUE(m.done);
    const MergeState<double> before = m;
    merge_partial(m, Partial<double>{{1, 1, 1}, 0.5});
    EXPECT_EQ(m.colour.x, before.colour.x);
    EXPECT_EQ(m.transmittance, before.transmittance);
    EXPECT_DOUBLE_EQ(before.colour.x, 0.5 + 0.5 * 0.2);
    EXPECT_DOUBLE_EQ(before.transmittance, 0.5e-4);
}

// --- The envelope bound ------------------------------------------------------------------

// footprint_bound_px bounds the footprint's half-extent over every orientation of the
// Gaussian at its depth: on the optical axis by itself (the projected 3D size does not vanish
// for a needle seen end-on), off axis by sqrt(1 + t^2) of itself, t the clamped tangent of the
// direction (the Jacobian's off-axis stretch, which cached_extent_bound_px covers by taking the
// current extent too).
TEST(StageEnvelope, FootprintBoundHoldsForEveryOrientation) {
    const std::uint64_t seed = test::fresh_seed("stage footprint bound");
    std::mt19937_64 rng(seed);
    int on_axis = 0;
    for (int trial = 0; trial < 40; ++trial) {
        const Camera camera = stage::random_camera(rng);
        const View<double> view = make_view<double>(camera, {0, 0, 0});
        const stage::GaussianArrays g = stage::random_gaussians(rng, 400, camera);
        for (std::size_t i = 0; i < g.count(); ++i) {
            Projected<double> p;
            if (!project_geometry(g.ref(i), view, p)) continue;
            const double max_scale = std::max({g.scales[3 * i], g.scales[3 * i + 1], g.scales[3 * i + 2]});
            const double focal = std::max(view.fx, view.fy);
            const double tx = std::clamp((p.mean.x - view.cx) / view.fx, -view.clamp_left, view.clamp_right);
            const double ty = std::clamp((p.mean.y - view.cy) / view.fy, -view.clamp_top, view.clamp_bottom);
            for (Culling mode : {Culling::bbox3sigma, Culling::opacity_aware}) {
                const double b = footprint_bound_px(p, mode, max_scale, focal);
                const Vec2<double> e = footprint_extent(p, mode);
                if (mode == Culling::opacity_aware) {
                    // Both scale the projected sigma by sqrt(level); the extent's sigma carries the
                    // Jacobian's row norm (f / z) sqrt(1 + t^2), the bound's f / z alone.
                    EXPECT_LE(e.x, b * std::sqrt(1 + tx * tx) * (1 + 1e-9))
                        << "gaussian " << i << " (CATGS_TEST_SEED=" << seed << ")";
                    EXPECT_LE(e.y, b * std::sqrt(1 + ty * ty) * (1 + 1e-9))
                        << "gaussian " << i << " (CATGS_TEST_SEED=" << seed << ")";
                }
                EXPECT_GE(b, (mode == Culling::bbox3sigma ? 3.0 : std::sqrt(std::max(0.0, opacity_level(p.opacity)))) *
                                 std::sqrt(kCovarianceBlur) * (1 - 1e-12));
            }
            // The same Gaussian on the optical axis at the same depth, in 8 random orientations.
            for (int r = 0; r < 8; ++r) {
                std::normal_distribution<double> n(0, 1);
                double q[4], norm = 0;
                for (double& c : q) {
                    c = n(rng);
                    norm += c * c;
                }
                float rotation[4], position[3];
                for (int a = 0; a < 4; ++a) rotation[a] = static_cast<float>(q[a] / std::sqrt(norm));
                const std::array<double, 3> c = camera_centre(camera.pose);
                for (int a = 0; a < 3; ++a)
                    position[a] = static_cast<float>(c[a] + camera.pose.rotation[6 + a] * p.depth);
                const GaussianRef turned{position, &g.scales[3 * i], rotation, g.opacities[i], nullptr, 0};
                Projected<double> pt;
                if (!project_geometry(turned, view, pt)) continue;
                ++on_axis;
                for (Culling mode : {Culling::bbox3sigma, Culling::opacity_aware}) {
                    const double b = footprint_bound_px(pt, mode, max_scale, focal);
                    if (mode == Culling::bbox3sigma) {
                        // graphdeco's radius rounds 3 sigma up to a whole pixel.
                        const double sigma = std::sqrt(std::max(pt.cov.x, pt.cov.z));
                        EXPECT_LE(3 * sigma, b * (1 + 1e-6)) << "gaussian " << i << " (CATGS_TEST_SEED=" << seed << ")";
                    } else {
                        const Vec2<double> e = footprint_extent(pt, mode);
                        EXPECT_LE(std::max(e.x, e.y), b * (1 + 1e-6))
                            << "gaussian " << i << " (CATGS_TEST_SEED=" << seed << ")";
                    }
                }
            }
        }
    }
    EXPECT_GT(on_axis, 10000);
}

// uncached_can_enter: always for a mean inside the image, then with bound = footprint_bound_px;
// beyond the clamp region exactly when a sphere of the footprint's 3D reach, grown by the
// translation guard, reaches past the image's side planes widened by the pixel guard (here
// from the camera-space point, as a plane distance); float decides as double except within
// 1e-4 (relative to the reach) of the decision.
TEST(StageEnvelope, UncachedCanEnterWithinReachOfTheImage) {
    const std::uint64_t seed = test::fresh_seed("stage uncached can enter");
    std::mt19937_64 rng(seed);
    int entering = 0, staying = 0, band = 0, beyond_entering = 0;
    double widest_flip = 0;
    for (int i = 0; i < 20000; ++i) {
        const Camera camera = stage::random_camera(rng);
        const View<double> vd = make_view<double>(camera, {0, 0, 0});
        const View<float> vf = make_view<float>(camera, {0, 0, 0});
        const Projected<float> pf = stage::random_projected<float>(rng, vd.width, vd.height);
        const Projected<double> pd = stage::widened(pf);
        const float guard = static_cast<float>(stage::uniform(rng, 0, 4)),
                    move = static_cast<float>(stage::uniform(rng, 0, 0.5));
        const float max_scale = static_cast<float>(stage::log_uniform(rng, 1e-4, 10));
        for (Culling mode : {Culling::bbox3sigma, Culling::opacity_aware}) {
            double bd = -1;
            float bf = -1;
            const bool d = uncached_can_enter(pd, mode, vd, double(guard), double(move), double(max_scale), bd);
            const bool f = uncached_can_enter(pf, mode, vf, guard, move, max_scale, bf);
            const bool inside = pd.mean.x >= 0 && pd.mean.x <= vd.width && pd.mean.y >= 0 && pd.mean.y <= vd.height;
            if (!in_clamp_region(vd, pd.mean)) {
                const double z = pd.depth, x = (pd.mean.x - vd.cx) * z / vd.fx, y = (pd.mean.y - vd.cy) * z / vd.fy;
                const double level = std::max(0.0, opacity_level(pd.opacity));
                const double sigmas = mode == Culling::bbox3sigma ? kBBoxSigmas : std::sqrt(level);
                const double sphere =
                    sigmas * (double(max_scale) + std::sqrt(kCovarianceBlur) * z / std::min(vd.fx, vd.fy)) + move;
                // The planes x = a z through the widened image sides, as (normal . p) / |normal|.
                const double g = guard, right = (vd.width + g - vd.cx) / vd.fx, left = (vd.cx + g) / vd.fx;
                const double bottom = (vd.height + g - vd.cy) / vd.fy, top = (vd.cy + g) / vd.fy;
                const double past =
                    std::max({(x - right * z) / std::hypot(1.0, right), (-x - left * z) / std::hypot(1.0, left),
                              (y - bottom * z) / std::hypot(1.0, bottom), (-y - top * z) / std::hypot(1.0, top)});
                if (std::fabs(past - sphere) < 1e-4 * (1 + sphere)) {
                    ++band;
                    continue;
                }
                EXPECT_EQ(d, past <= sphere) << "case " << i << " (CATGS_TEST_SEED=" << seed << ")";
                EXPECT_EQ(f, d) << "case " << i << " (CATGS_TEST_SEED=" << seed << ")";
                if (d) {
                    ++beyond_entering;
                    EXPECT_EQ(bd, footprint_bound_px(pd, mode, double(max_scale), std::max(vd.fx, vd.fy)));
                }
                (d ? entering : staying) += 1;
                continue;
            }
            if (inside) {
                EXPECT_TRUE(d) << "case " << i << " (CATGS_TEST_SEED=" << seed << ")";
            }
            if (d) {
                EXPECT_EQ(bd, footprint_bound_px(pd, mode, double(max_scale), std::max(vd.fx, vd.fy)));
            }
            (d ? entering : staying) += 1;
            // The decision's margin: how far the mean is outside the image, against the reach.
            const double focal = std::max(vd.fx, vd.fy), b = footprint_bound_px(pd, mode, double(max_scale), focal);
            const double t = max_clamp_tangent(vd);
            const double reach =
                guard * (1 + b / focal) + focal * (1 + t * t) * move / pd.depth + b * (1 + move / pd.depth);
            const double away = std::max({-pd.mean.x, pd.mean.x - vd.width, -pd.mean.y, pd.mean.y - vd.height});
            const double lo = -kClampRegionMargin, hi = 1 + kClampRegionMargin;
            const double region =
                std::min({std::fabs(pd.mean.x - lo * vd.width), std::fabs(pd.mean.x - hi * vd.width),
                          std::fabs(pd.mean.y - lo * vd.height), std::fabs(pd.mean.y - hi * vd.height)});
            if (f != d) widest_flip = std::max(widest_flip, std::min(std::fabs(away - reach) / (1 + reach), region));
            if (std::fabs(away - reach) < 1e-4 * (1 + reach) || region < 1e-3) {
                ++band;
                continue;
            }
            EXPECT_EQ(d, away <= reach) << "case " << i << " (CATGS_TEST_SEED=" << seed << ")";
            EXPECT_EQ(f, d) << "case " << i << " (CATGS_TEST_SEED=" << seed << ")";
        }
    }
    std::cout << "[stage] uncached_can_enter: " << entering << " can enter (" << beyond_entering
              << " from beyond the clamp region), " << staying << " cannot, " << band
              << " at the decision's edge; float differs at most " << widest_flip << " from it" << std::endl;
    EXPECT_GT(entering, 1000);
    EXPECT_GT(beyond_entering, 0);
    EXPECT_GT(staying, 1000);
}

// behind_near_can_enter is sound: a mean at or behind a window pose's near plane that some
// camera within the translation guard sees in front of that near plane, inside the clamp
// region's frustum widened by the footprint's reach, is always reported; and it is not
// reported for every mean behind the plane.
TEST(StageEnvelope, BehindTheNearPlaneCanEnterOnlyNearTheCamera) {
    const std::uint64_t seed = test::fresh_seed("stage behind near");
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal(0, 1);
    int seen = 0, refused = 0;
    for (int i = 0; i < 20000; ++i) {
        const Camera camera = stage::random_camera(rng);
        const View<double> v = make_view<double>(camera, {0, 0, 0}, stage::uniform(rng, 1e-3, 0.2));
        const double guard = stage::uniform(rng, 0, 0.5), reach = stage::log_uniform(rng, 1e-4, 0.3);
        const double spread = stage::log_uniform(rng, 0.01, 3);
        const Vec3<double> pc{stage::uniform(rng, -spread, spread), stage::uniform(rng, -spread, spread),
                              stage::uniform(rng, -spread, v.near_plane)};
        // World = R^T (pc - t), in float as a scene holds it.
        const Vec3<double> q{pc.x - v.translation.x, pc.y - v.translation.y, pc.z - v.translation.z};
        float world[3];
        for (int a = 0; a < 3; ++a)
            world[a] =
                static_cast<float>(v.rotation.m[0][a] * q.x + v.rotation.m[1][a] * q.y + v.rotation.m[2][a] * q.z);
        const Vec3<double> back = v.rotation * Vec3<double>{world[0], world[1], world[2]} + v.translation;
        if (!(back.z <= v.near_plane)) continue;  // float rounding moved it in front: not this test's case
        const bool can = behind_near_can_enter(world, v, 1.0, guard, reach);
        const double tx = std::max(v.clamp_left, v.clamp_right), ty = std::max(v.clamp_top, v.clamp_bottom);
        bool visible = false;
        for (int j = 0; j < 8 && !visible; ++j) {  // cameras moved by up to the guard, backwards
            Vec3<double> d{normal(rng), normal(rng), normal(rng)};
            const double len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
            const double step = guard * std::cbrt(stage::uniform(rng, 0, 1));
            d = {d.x / len * step, d.y / len * step, -std::fabs(d.z) / len * step};
            const Vec3<double> p{back.x - d.x, back.y - d.y, back.z - d.z};
            visible = p.z > v.near_plane && std::fabs(p.x) <= tx * p.z + reach && std::fabs(p.y) <= ty * p.z + reach;
        }
        if (visible) {
            ++seen;
            EXPECT_TRUE(can) << "case " << i << " (CATGS_TEST_SEED=" << seed << ")";
        }
        if (!can) ++refused;
    }
    std::cout << "[stage] behind_near_can_enter: " << seen << " seen from a moved camera, " << refused << " refused"
              << std::endl;
    EXPECT_GT(seen, 100);
    EXPECT_GT(refused, 1000);
    // A large Gaussian (a 30 m scale's reach) whose mean is 10 m behind the camera cannot pass a
    // near plane within a 0.25 m step: refused, however far its footprint reaches. Just behind
    // the camera, it is reported.
    const View<double> ahead = make_view<double>(test::forward_camera(64, 48, 70.0), {0, 0, 0}, 1e-3);
    const float behind[3] = {0.0f, 0.0f, -10.0f}, just_behind[3] = {0.0f, 0.0f, -0.1f};
    EXPECT_FALSE(behind_near_can_enter(behind, ahead, 1.0, 0.25, 100.0));
    EXPECT_TRUE(behind_near_can_enter(just_behind, ahead, 1.0, 0.25, 0.01));
}

}  // namespace
}  // namespace catgs
