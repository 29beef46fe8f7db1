// The CaT-GS speculative inter-frame cache on the CPU backend: speculation against the
// stripe artifacts, the accuracy bar over UAV paths, depth-order reuse and its gate, the
// envelope that ends a window, flight-plan hints and pose prediction.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <deque>
#include <limits>
#include <map>

#include "catgs/builtin_city.hpp"
#include "catgs/cache.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/stages/keys.hpp"
#include "catgs/trajectory.hpp"
#include "catgs_paths.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

struct PathResult {
    double mean_psnr = 0, worst_psnr = 1e9;
    std::uint64_t missing = 0;
    int cached_frames = 0, key_frames = 0;
};

PathResult run_path(const Scene& scene, const std::vector<Camera>& cameras, const RenderOptions& options) {
    CpuRenderer<float> cached_renderer, full_renderer;
    RenderOptions full_options;
    full_options.culling = options.culling;
    PathResult r;
    double sum = 0;
    for (const Camera& cam : cameras) {
        ImageF a, b;
        const FrameStats s = cached_renderer.render(scene, cam, options, a);
        full_renderer.render(scene, cam, full_options, b);
        const ImageError e = compare(to_rgb8(a), to_rgb8(b));
        const double psnr = std::min(e.psnr, 100.0);
        sum += psnr;
        r.worst_psnr = std::min(r.worst_psnr, psnr);
        if (s.key_frame) {
            ++r.key_frames;
        } else {
            ++r.cached_frames;
            r.missing += test::missing_pairs(cached_renderer, full_renderer);
        }
    }
    r.mean_psnr = sum / static_cast<double>(cameras.size());
    return r;
}

Scene small_city(const std::string& what) {
    CityParams p;
    p.gaussians = 60000;
    p.seed = test::fresh_seed(what);
    return make_city(p);
}

/// The image of the path tests: small enough to render every frame of a path twice.
Intrinsics path_intrinsics() {
    return intrinsics_from_fov(320, 180, 70.0);
}

/// The speculative cache over a fixed window of 4 frames.
RenderOptions fixed_window_cache() {
    RenderOptions o;
    o.catgs.cache = CacheMode::speculative;
    o.catgs.window = 4;
    o.catgs.adaptive_window = false;
    return o;
}

// Without speculation, reused lists miss Gaussians that moved into new tiles: the stripe
// artifacts of the paper's Figure 7. Speculation over the window removes them.
TEST(CatgsCache, SpeculationRemovesTheStripeArtifacts) {
    const Scene city = small_city("stripes");
    const auto [bad, good] = test::run_stripes_path(city, path_intrinsics(), run_path);
    std::cout << "[unspeculated] missing pairs " << bad.missing << ", psnr mean " << bad.mean_psnr << " worst "
              << bad.worst_psnr << "; [speculative] missing " << good.missing << ", mean " << good.mean_psnr
              << " worst " << good.worst_psnr << ", cached frames " << good.cached_frames << std::endl;
    EXPECT_GT(bad.missing, 100u);
    EXPECT_LT(bad.worst_psnr, test::kStripedWorstPsnr);
    EXPECT_EQ(good.missing, 0u);
    EXPECT_GT(good.cached_frames, 8);
    EXPECT_GE(good.worst_psnr, test::kWorstPsnrBar);
}

/// 30 frames at 30 fps over the centre of `b`, frame i at pose(i, cx, cy).
template <typename PoseAt>
std::vector<Camera> scripted_path(const Bounds& b, const Intrinsics& k, PoseAt pose) {
    std::vector<Camera> out;
    const double cx = 0.5 * (b.min[0] + b.max[0]), cy = 0.5 * (b.min[1] + b.max[1]);
    for (int i = 0; i < 30; ++i) {
        Camera c;
        c.intrinsics = k;
        c.pose = pose(i, cx, cy);
        c.timestamp = i / 30.0;
        out.push_back(c);
    }
    return out;
}

std::vector<Camera> altitude_change(const Bounds& b, const Intrinsics& k) {
    return scripted_path(b, k, [](int i, double cx, double cy) {
        const double z = 40.0 + 2.0 * i;  // climbing 60 m/s at 30 fps
        return look_at({cx - 30 + 0.4 * i, cy - 60, z}, {cx, cy, 0}, {0, 0, 1});
    });
}

std::vector<Camera> fast_turn(const Bounds& b, const Intrinsics& k) {
    return scripted_path(b, k, [](int i, double cx, double cy) {
        const double yaw = 0.06 * i;  // 1.8 rad/s yaw while hovering at 50 m
        return look_at({cx, cy, 50}, {cx + 40 * std::cos(yaw), cy + 40 * std::sin(yaw), 0}, {0, 0, 1});
    });
}

// The accuracy bar over several UAV paths: cached and split frames against the per-frame
// full pipeline, PSNR >= 45 dB on average and >= 40 dB on the worst frame, and no tile with
// a missing Gaussian.
TEST(CatgsCache, AccuracyBarOverUavPaths) {
    const Scene city = small_city("accuracy bar");
    const Intrinsics k = path_intrinsics();
    const std::vector<test::CameraPath> paths = {
        {"survey", make_trajectory("builtin:survey?frames=40&altitude=70&speed=10", city.bounds, k)},
        {"orbit", make_trajectory("builtin:orbit?frames=40&altitude=60&speed=12", city.bounds, k)},
        {"hover", make_trajectory("builtin:hover?frames=40&altitude=60", city.bounds, k)},
        {"fast turn", fast_turn(city.bounds, k)},
        {"altitude change", altitude_change(city.bounds, k)},
    };
    int cached = 0;
    test::for_each_accuracy_bar_run(paths, [&](const test::CameraPath& p, const test::CacheRun& run) {
        const std::string name = p.name + run.label;
        const PathResult r = run_path(city, p.cameras, run.options);
        std::cout << "[" << name << "] psnr mean " << r.mean_psnr << " worst " << r.worst_psnr << ", key "
                  << r.key_frames << " cached " << r.cached_frames << ", missing " << r.missing << std::endl;
        EXPECT_GE(r.mean_psnr, test::kMeanPsnrBar) << name;
        EXPECT_GE(r.worst_psnr, test::kWorstPsnrBar) << name;
        EXPECT_EQ(r.missing, 0u) << name;
        cached += r.cached_frames;
    });
    EXPECT_GT(cached, 150);  // the bar is met by caching, not by rendering every frame fully
}

// Reusing the key frame's depth order (the paper's cache) against re-sorting cached lists by
// the current depth: on a rotating path coplanar layers swap order. Measured and reported;
// the re-sort must remove the difference.
TEST(CatgsCache, DepthOrderReuseErrorIsMeasuredAndResortRemovesIt) {
    const Scene city = small_city("depth order reuse");
    const auto cameras =
        make_trajectory("builtin:orbit?frames=24&altitude=60&speed=12", city.bounds, path_intrinsics());
    RenderOptions reuse = fixed_window_cache();
    reuse.catgs.resort_cached = false;
    RenderOptions resort = reuse;
    resort.catgs.resort_cached = true;
    const PathResult a = run_path(city, cameras, reuse);
    const PathResult b = run_path(city, cameras, resort);
    std::cout << "[orbit W=4] depth order reused: psnr mean " << a.mean_psnr << " worst " << a.worst_psnr
              << "; re-sorted: mean " << b.mean_psnr << " worst " << b.worst_psnr << std::endl;
    EXPECT_EQ(a.missing, 0u);
    EXPECT_EQ(b.missing, 0u);
    EXPECT_GT(b.cached_frames, 12);
    EXPECT_GE(b.worst_psnr, 60.0);
    EXPECT_LT(a.worst_psnr, b.worst_psnr);
}

/// How far (in ulps of the full pipeline's float sort keys) the cached renderer's tile lists
/// step back in depth, over the Gaussians the full pipeline lists in each tile: at most 1 when
/// they order every tile as the full pipeline does, except pairs whose keys lie within one ulp
/// (there rounding, not geometry, sets the full pipeline's own order).
std::uint32_t order_violation_ulps(const CpuRenderer<float>& cached, const CpuRenderer<float>& full) {
    std::uint32_t worst = 0;
    const auto& cr = cached.tile_ranges();
    const auto& fr = full.tile_ranges();
    for (std::size_t t = 0; t < fr.size(); ++t) {
        std::map<std::uint32_t, std::uint32_t> depth_bits;  // Gaussian -> its key's depth bits
        for (std::uint64_t j = fr[t].begin; j < fr[t].end; ++j)
            depth_bits[full.sorted_values()[j]] = static_cast<std::uint32_t>(full.sorted_keys()[j]);
        std::uint32_t deepest = 0;
        for (std::uint64_t j = cr[t].begin; j < cr[t].end; ++j) {
            const auto it = depth_bits.find(cached.sorted_values()[j]);
            if (it == depth_bits.end()) continue;
            if (it->second < deepest) worst = std::max(worst, deepest - it->second);
            deepest = std::max(deepest, it->second);
        }
    }
    return worst;
}

/// The worst step back in depth of the cached renderer's tile lists, over the Gaussians the
/// full pipeline lists in each tile, in units of one float ulp at the key frame. A translation
/// shifts every true depth by the same amount, so two Gaussians the key frame ordered with equal
/// keys (less than one of its ulps apart) stay less than that apart: at most 1 when the cached
/// lists keep the key frame's order. In the current frame's own ulps that is 2 once the depths
/// have crossed below a power of two. A depth moved by at most `shift` (the camera's
/// displacement since the key frame), so the key frame's ulp is at most the ulp at the deeper
/// Gaussian's current depth plus `shift`.
double order_violation_key_ulps(const CpuRenderer<float>& cached, const CpuRenderer<float>& full, double shift) {
    double worst = 0;
    const auto& cr = cached.tile_ranges();
    const auto& fr = full.tile_ranges();
    for (std::size_t t = 0; t < fr.size(); ++t) {
        std::map<std::uint32_t, float> depth;  // Gaussian -> its depth key in the full pipeline
        for (std::uint64_t j = fr[t].begin; j < fr[t].end; ++j)
            depth[full.sorted_values()[j]] = depth_of_key(full.sorted_keys()[j]);
        float deepest = -1;
        for (std::uint64_t j = cr[t].begin; j < cr[t].end; ++j) {
            const auto it = depth.find(cached.sorted_values()[j]);
            if (it == depth.end()) continue;
            if (it->second < deepest) {
                const float key = static_cast<float>(deepest + shift);
                const double key_ulp = std::nextafter(key, std::numeric_limits<float>::infinity()) - key;
                worst = std::max(worst, (static_cast<double>(deepest) - it->second) / key_ulp);
            }
            deepest = std::max(deepest, it->second);
        }
    }
    return worst;
}

// The defaults reuse the key frame's depth order only while the camera translates: view depth
// is dot(forward, mean - centre), so a translation shifts every key by the same amount and
// keeps the order, except among keys within one float ulp. Once the camera turns, the window
// re-sorts, and keeps re-sorting even if it turns back (its lists no longer hold the key
// frame's order). Reusing the order through a turn (the paper's cache) breaks it.
TEST(CatgsCache, OrderIsReusedWhileTheCameraTranslatesAndResortedOnceItTurns) {
    const Scene city = small_city("order gate");
    const Intrinsics k = path_intrinsics();
    const Bounds& b = city.bounds;
    const double cx = 0.5 * (b.min[0] + b.max[0]), cy = 0.5 * (b.min[1] + b.max[1]);
    // The rotation of `r` with its camera centre moved to `centre` (t = -R c).
    auto placed = [](Pose r, const std::array<double, 3>& centre) {
        for (int i = 0; i < 3; ++i)
            r.translation[i] = -(r.rotation[3 * i] * centre[0] + r.rotation[3 * i + 1] * centre[1] +
                                 r.rotation[3 * i + 2] * centre[2]);
        return r;
    };
    // A straight pass at 10 m/s, constant heading and pitch: every frame has the key's rotation.
    std::vector<Camera> cameras;
    const Pose heading = look_at({0, 0, 0}, {0, 1, -1}, {0, 0, 1});
    for (int i = 0; i < 12; ++i) {
        Camera c;
        c.intrinsics = k;
        c.pose = placed(heading, {cx, cy - 40 + i / 3.0, 60});
        c.timestamp = i / 30.0;
        cameras.push_back(c);
    }
    RenderOptions o = default_pipeline_options();
    o.catgs.adaptive_window = false;
    o.catgs.window = 4;
    o.catgs.split_k = 64;
    CpuRenderer<float> renderer, full;
    double key_y = 0;  // the key frame's camera y: the pass moves along y only
    int reused = 0;
    for (int i = 0; i < static_cast<int>(cameras.size()); ++i) {
        const Camera& c = cameras[i];
        const double y = cy - 40 + i / 3.0;
        ImageF a, ref;
        const FrameStats s = renderer.render(city, c, o, a);
        full.render(city, c, RenderOptions{}, ref);
        reused += s.order_reused;
        EXPECT_EQ(s.order_reused, !s.key_frame);
        if (s.key_frame) key_y = y;
        EXPECT_LE(order_violation_key_ulps(renderer, full, std::abs(y - key_y)), 1.0) << "frame at t = " << c.timestamp;
        EXPECT_GE(compare(to_rgb8(a), to_rgb8(ref)).psnr, test::kWorstPsnrBar);
    }
    EXPECT_GE(reused, 8);

    // A turn of 0.5 deg a frame with the order reused at any angle: layers now swap by more
    // than rounding.
    RenderOptions paper = o;
    paper.catgs.reuse_order_max_angle = std::numeric_limits<double>::infinity();
    CpuRenderer<float> turning;
    std::uint32_t turned_worst = 0;
    int turned_reused = 0;
    for (int i = 0; i < 4; ++i) {
        Camera c = cameras[0];
        const double yaw = 0.5 * i * kPi / 180.0;
        c.pose = placed(look_at({0, 0, 0}, {std::sin(yaw), std::cos(yaw), -1}, {0, 0, 1}), {cx, cy - 40, 60});
        c.timestamp = i / 30.0;
        ImageF a, ref;
        turned_reused += turning.render(city, c, paper, a).order_reused;
        full.render(city, c, RenderOptions{}, ref);
        turned_worst = std::max(turned_worst, order_violation_ulps(turning, full));
    }
    EXPECT_GE(turned_reused, 2);  // frame 1 starts the window: the first one predicted no turn
    EXPECT_GT(turned_worst, 1000u);

    // The planner: translated frames reuse, a turn of 0.01 deg re-sorts, and so does the
    // next frame back at the key's rotation.
    FramePlanner planner;
    CatgsOptions gate = o.catgs;
    gate.window = 8;
    gate.guard_px = 64;
    auto at = [&](double dx, double yaw_deg, double t) {
        Camera c = cameras[0];
        const double yaw = yaw_deg * kPi / 180.0;
        c.pose = placed(look_at({0, 0, 0}, {std::sin(yaw), std::cos(yaw), -1}, {0, 0, 1}), {cx + dx, cy - 40, 60});
        c.timestamp = t;
        return c;
    };
    const FramePlanner::Plan key = planner.next(at(0, 0, 0), gate);
    ASSERT_TRUE(key.key);
    KeyFrameSummary summary;
    summary.min_depth = 50;
    summary.mean_inverse_depth = 1.0 / 80;
    planner.key_rendered(key, summary);
    const auto translated = planner.next(at(0.01, 0, 1 / 30.0), gate);
    ASSERT_FALSE(translated.key);
    EXPECT_FALSE(translated.resort);
    const auto turned = planner.next(at(0.02, 0.01, 2 / 30.0), gate);
    ASSERT_FALSE(turned.key);
    EXPECT_TRUE(turned.resort);
    const auto back = planner.next(at(0.03, 0, 3 / 30.0), gate);
    ASSERT_FALSE(back.key);
    EXPECT_TRUE(back.resort);
    // With re-sorting requested, every cached frame re-sorts.
    gate.resort_cached = true;
    planner.reset();
    planner.key_rendered(planner.next(at(0, 0, 0), gate), summary);
    EXPECT_TRUE(planner.next(at(0.01, 0, 1 / 30.0), gate).resort);
}

TEST(CatgsCache, HoverUsesLongWindowsAndLeavingTheEnvelopeStartsAKeyFrame) {
    const Scene city = small_city("envelope");
    const Intrinsics k = path_intrinsics();
    const auto hover = make_trajectory("builtin:hover?frames=40&altitude=60", city.bounds, k);
    RenderOptions o;
    o.catgs.cache = CacheMode::speculative;
    CpuRenderer<float> renderer;
    ImageF out;
    int cached = 0, max_window = 0;
    for (const Camera& c : hover) {
        const FrameStats s = renderer.render(city, c, o, out);
        cached += !s.key_frame;
        max_window = std::max(max_window, s.window);
    }
    EXPECT_GT(cached, 30);
    EXPECT_GE(max_window, 8);
    // Still at the same pose: run to the end of the current window (a key frame), then the
    // next frame comes from the cache; with a new resolution it is a key frame.
    Camera same = hover.back();
    auto next = [&](Camera& c) {
        c.timestamp += 1.0 / 30;
        return renderer.render(city, c, o, out);
    };
    int steps = 0;
    while (!next(same).key_frame) ASSERT_LE(++steps, kMaxWindow);
    EXPECT_FALSE(next(same).key_frame);
    Camera resized = same;
    resized.intrinsics = intrinsics_from_fov(320, 200, 70.0);
    resized.timestamp += 1.0 / 30;
    EXPECT_TRUE(renderer.render(city, resized, o, out).key_frame);
    // Back at the old resolution, the window restarts: cached again.
    same.timestamp = resized.timestamp + 1.0 / 30;
    renderer.render(city, same, o, out);
    same.timestamp += 1.0 / 30;
    EXPECT_FALSE(renderer.render(city, same, o, out).key_frame);
    // A jump of 20 m leaves the envelope: a key frame, whatever the window.
    Camera jumped = same;
    jumped.pose = look_at({20, -40, 80}, {0, 0, 0}, {0, 0, 1});
    jumped.timestamp += 1.0 / 30;
    EXPECT_TRUE(renderer.render(city, jumped, o, out).key_frame);
}

TEST(CatgsCache, FlightPlanHintsReplacePrediction) {
    const Scene city = small_city("flight plan");
    const auto cameras =
        make_trajectory("builtin:flythrough?frames=20&altitude=40&speed=20", city.bounds, path_intrinsics());
    const RenderOptions o = fixed_window_cache();
    CpuRenderer<float> renderer, full;
    ImageF a, b;
    int cached = 0;
    std::uint64_t missing = 0;
    for (std::size_t i = 0; i < cameras.size(); ++i) {
        FrameHints hints;
        hints.plan.assign(cameras.begin() + static_cast<std::ptrdiff_t>(i + 1),
                          cameras.begin() + static_cast<std::ptrdiff_t>(std::min(cameras.size(), i + 4)));
        const FrameStats s = renderer.render(city, cameras[i], o, a, &hints);
        full.render(city, cameras[i], RenderOptions{}, b);
        if (!s.key_frame) {
            ++cached;
            missing += test::missing_pairs(renderer, full);
        }
    }
    EXPECT_GE(cached, 10);  // the plan is exact: three of every four frames come from the cache
    EXPECT_EQ(missing, 0u);
}

TEST(CatgsCache, PredictionExtrapolatesConstantMotion) {
    std::deque<Camera> history;
    for (int i = 0; i < 3; ++i) {
        Camera c;
        c.intrinsics = intrinsics_from_fov(64, 64, 60.0);
        const double yaw = 0.05 * i;
        c.pose = look_at({2.0 * i, 0, 50}, {2.0 * i + 30 * std::cos(yaw), 30 * std::sin(yaw), 0}, {0, 0, 1});
        c.timestamp = 0.1 * i;
        history.push_back(c);
    }
    const auto future = predict_poses(history, 3);
    ASSERT_EQ(future.size(), 3u);
    for (int k = 0; k < 3; ++k) {
        const double yaw = 0.05 * (3 + k);
        const Pose truth =
            look_at({2.0 * (3 + k), 0, 50}, {2.0 * (3 + k) + 30 * std::cos(yaw), 30 * std::sin(yaw), 0}, {0, 0, 1});
        const auto c = camera_centre(future[k].pose);
        EXPECT_NEAR(c[0], 2.0 * (3 + k), 1e-9);
        EXPECT_NEAR(future[k].timestamp, 0.1 * (3 + k), 1e-12);
        EXPECT_LT(rotation_angle(future[k].pose, truth), 1e-6);  // a rigid turn about the vertical
    }
}

}  // namespace
}  // namespace catgs
