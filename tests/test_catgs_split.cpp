// CaT-GS tile task splitting on the CPU backend: sub-task ranges (the paper's Algorithm 1),
// the task list, the image it leaves unchanged, the raised tail threshold, the automatic k,
// and the parsers of k and angles the tools and catgs-client share.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>

#include "catgs/cache.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/split_choice.hpp"
#include "catgs/stages/split.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

ImageRGB8 render_once(const Scene& scene, const Camera& camera, const RenderOptions& options,
                      FrameStats* stats = nullptr) {
    CpuRenderer<float> renderer;
    ImageF out;
    FrameStats s = renderer.render(scene, camera, options, out);
    if (stats) *stats = s;
    return to_rgb8(out);
}

Scene dense_scene(const std::string& what, std::size_t count = 6000) {
    test::RandomSceneParams p;
    p.count = count;
    p.extent = 2.0;  // packed in front of the camera: long tile lists
    return test::random_scene(test::fresh_seed(what), p);
}

TEST(CatgsSplit, SubtaskRangesFollowAlgorithmOne) {
    std::uint64_t b = 0, e = 0;
    EXPECT_EQ(split_count(100, 0), 0u);
    EXPECT_EQ(split_count(100, 100), 0u);
    EXPECT_EQ(split_count(250, 100), 2u);
    subtask_range(1000, 1250, 100, 0, b, e);  // first keeps the remainder: 250 - 2 * 100
    EXPECT_EQ(b, 1000u);
    EXPECT_EQ(e, 1050u);
    subtask_range(1000, 1250, 100, 1, b, e);
    EXPECT_EQ(b, 1050u);
    EXPECT_EQ(e, 1150u);
    subtask_range(1000, 1250, 100, 2, b, e);
    EXPECT_EQ(b, 1150u);
    EXPECT_EQ(e, 1250u);
    subtask_range(0, 300, 100, 0, b, e);  // exact multiple: an empty first sub-task
    EXPECT_EQ(e - b, 0u);
}

// The GPU's task order starts a list first from kHeavyListFactor x the mean non-empty list on,
// never an empty one, and nothing at factor 0 (row order).
TEST(CatgsSplit, HeavyListsStartAtTheFactorTimesTheMean) {
    // 10 non-empty lists of 1000 pairs in all: a mean of 100.
    EXPECT_TRUE(runs_first(400, 1000, 10, kHeavyListFactor));
    EXPECT_FALSE(runs_first(399, 1000, 10, kHeavyListFactor));
    EXPECT_TRUE(runs_first(150, 1000, 10, 1.5));
    EXPECT_FALSE(runs_first(149, 1000, 10, 1.5));
    EXPECT_FALSE(runs_first(0, 0, 0, kHeavyListFactor));
    EXPECT_FALSE(runs_first(1000000, 1000, 10, 0.0));
    // Past 32 bits of pairs the product must not wrap: 3e9 pairs over 1e5 lists, a mean of 3e4.
    EXPECT_TRUE(runs_first(120000, 3000000000ull, 100000, kHeavyListFactor));
    EXPECT_FALSE(runs_first(119999, 3000000000ull, 100000, kHeavyListFactor));
}

TEST(CatgsSplit, TasksAreTilesPlusLabelledExtras) {
    const Scene scene = dense_scene("split tasks");
    const Camera cam = test::forward_camera(96, 64, 60.0);
    RenderOptions o;
    o.catgs.split_k = 32;
    CpuRenderer<float> renderer;
    ImageF out;
    const FrameStats s = renderer.render(scene, cam, o, out);
    std::uint64_t extra = 0;
    for (const TileRange& r : renderer.tile_ranges()) extra += split_count(r.end - r.begin, 32);
    ASSERT_GT(extra, 0u);
    EXPECT_EQ(s.split_tasks, extra);
    EXPECT_EQ(s.tasks, renderer.tile_ranges().size() + extra);
    // Extra tasks carry (tile, split index) labels 1..split_num, in order per tile.
    std::vector<std::uint32_t> next(renderer.tile_ranges().size(), 1);
    for (std::size_t i = renderer.tile_ranges().size(); i < renderer.tasks().size(); ++i) {
        const TileTask t = renderer.tasks()[i];
        EXPECT_EQ(t.index, next[t.tile]++);
    }
}

// With the tail threshold left at 1e-4, splitting regroups the float sums and moves the early
// stop: the unsplit blend stops before the Gaussian that would take T below 1e-4 (graphdeco's
// rule), which can leave out up to T alpha < 0.01 of a pixel's light (2.5 levels for colour 1,
// more for SH colours above 1); a later sub-task cannot know the T in front of it and blends
// that Gaussian, and the merge adds it. On this scene of colours in [0, 1] that is at most
// 2.55 levels, 3 after rounding (kSplitMaxLevels), as the stress suite bounds it
// (kSplitFewLevels in test_stress.cpp); most seeds stay within one level, about 3% of them
// reach 2 (one pixel whose stop moved), so one level was no bound.
constexpr int kSplitMaxLevels = 3;
TEST(CatgsSplit, SplittingDoesNotChangeTheImage) {
    const Scene scene = dense_scene("split equivalence");
    const Camera cam = test::forward_camera(96, 64, 60.0);
    for (Culling mode : {Culling::opacity_aware, Culling::exact}) {
        RenderOptions base;
        base.culling = mode;
        base.background = {0.2f, 0.1f, 0.4f};
        const ImageRGB8 unsplit = render_once(scene, cam, base);
        for (std::uint32_t k : {7u, 32u, 100u}) {
            RenderOptions split = base;
            split.catgs.split_k = k;
            FrameStats s;
            const ImageError e = compare(render_once(scene, cam, split, &s), unsplit);
            EXPECT_GT(s.split_tasks, 0u);
            EXPECT_LE(e.max_abs, kSplitMaxLevels) << culling_name(mode) << " k=" << k << " psnr " << e.psnr;
            EXPECT_GE(e.psnr, 60.0) << culling_name(mode) << " k=" << k;
        }
    }
}

TEST(CatgsSplit, RaisedTailThresholdAddsBoundedError) {
    const Scene scene = dense_scene("tail threshold");
    const Camera cam = test::forward_camera(96, 64, 60.0);
    const ImageRGB8 unsplit = render_once(scene, cam, RenderOptions{});
    RenderOptions o;
    o.catgs.split_k = 16;
    o.catgs.split_tail_transmittance = 1e-2;
    const ImageError e = compare(render_once(scene, cam, o), unsplit);
    std::cout << "[tail threshold 1e-2, k=16] psnr " << e.psnr << " dB, max " << e.max_abs << " levels" << std::endl;
    // Each later sub-task stops at T < 1e-2 of its own slice: at most 1e-2 of light lost per
    // sub-task, scaled by the transmittance in front of it.
    EXPECT_GE(e.psnr, 35.0);
}

// The k and angle parsers the tools' flags and catgs-client share take the whole text or nothing.
TEST(CatgsOptionsText, SplitKAndDegreesParseWholeValuesInRange) {
    EXPECT_EQ(parse_split_k("1"), 1u);
    EXPECT_EQ(parse_split_k("16777216"), kMaxSplitK);
    for (const char* bad : {"0", "-5", "16777217", "12abc", "", "1e3", "99999999999999999999"})
        EXPECT_FALSE(parse_split_k(bad).has_value()) << bad;
    EXPECT_EQ(parse_degrees("0"), 0.0);
    EXPECT_EQ(parse_degrees("180"), 180.0);
    EXPECT_EQ(parse_degrees("0.05"), 0.05);
    for (const char* bad : {"-1", "180.5", "nan", "inf", "1e400", "5deg", ""})
        EXPECT_FALSE(parse_degrees(bad).has_value()) << bad;
}

TEST(CatgsSplit, AutomaticKFollowsTheListLengths) {
    const Scene scene = dense_scene("auto k", 20000);
    const Camera cam = test::forward_camera(128, 96, 60.0);
    RenderOptions o;
    o.catgs.split_auto = true;
    CpuRenderer<float> renderer;
    ImageF out;
    const FrameStats s = renderer.render(scene, cam, o, out);
    std::uint64_t nonempty = 0;
    for (const TileRange& r : renderer.tile_ranges()) nonempty += r.end > r.begin;
    const double mean = static_cast<double>(s.pairs) / static_cast<double>(nonempty);
    EXPECT_GE(s.split_k, kAutoSplitFloor);
    EXPECT_GE(s.split_k, static_cast<std::uint32_t>(kAutoSplitFactor * mean));
    EXPECT_LE(s.split_k, static_cast<std::uint32_t>(kAutoSplitFactor * mean) + kAutoSplitFloor);
}

// --- Choosing per path whether to split (SplitChooser) ----------------------------------

FrameStats measured(double rasterize_ms, double merge_ms, std::uint64_t pairs) {
    FrameStats s;
    s.pairs = pairs;
    s.stage_ms[Stage::rasterize] = rasterize_ms;
    s.stage_ms[Stage::merge] = merge_ms;
    return s;
}

/// Frames that choose whether to split from measured time, at a k that dense_scene's lists pass.
RenderOptions timed_render_options() {
    RenderOptions o;
    o.catgs.split_k = 32;
    o.catgs.window_cost = WindowCost::time;
    return o;
}

CatgsOptions timed_split_options() {
    CatgsOptions o;
    o.split_k = 8192;
    o.window_cost = WindowCost::time;
    return o;
}

/// Runs `frames` list-building frames where a split frame costs `split_ms` and a whole one
/// `whole_ms` per million pairs (merge included); returns how many split.
int split_frames(SplitChooser& chooser, const CatgsOptions& o, int frames, double split_ms, double whole_ms) {
    int split = 0;
    for (int i = 0; i < frames; ++i) {
        const bool s = chooser.choose(o);
        split += s;
        chooser.learn(s, s ? measured(split_ms * 0.9, split_ms * 0.1, 1000000) : measured(whole_ms, 0, 1000000));
    }
    return split;
}

// Split first, whole second, then the cheaper side on all but one frame in kSplitProbeEvery
// (kSplitClearProbeEvery once the other side is clearly dearer), following the costs when they
// change sides; the merge counts against splitting.
TEST(SplitChooser, TakesTheSideWithTheLowerMeasuredRasterizeCostAndProbesTheOther) {
    const CatgsOptions o = timed_split_options();
    SplitChooser chooser;
    EXPECT_TRUE(chooser.choose(o));
    chooser.learn(true, measured(2.7, 0.3, 1000000));  // 3.0 ms per million pairs
    EXPECT_FALSE(chooser.choose(o));
    chooser.learn(false, measured(2.0, 0, 1000000));
    EXPECT_NEAR(chooser.split_cost().value(), 3.0, 1e-12);
    EXPECT_NEAR(chooser.whole_cost().value(), 2.0, 1e-12);
    const int frames = 20 * kSplitClearProbeEvery;
    // Whole wins by 50%: after the two first frames, one probe in kSplitClearProbeEvery splits.
    EXPECT_EQ(split_frames(chooser, o, frames, 3.0, 2.0), frames / kSplitClearProbeEvery);
    // Whole wins by 10%: one in kSplitProbeEvery.
    SplitChooser close;
    EXPECT_EQ(split_frames(close, o, frames + 2, 2.2, 2.0), 1 + frames / kSplitProbeEvery);
    // The content changes: splitting pays now (a 1080p garden); the next probe finds it, and
    // from then on whole frames are the probes.
    const int split = split_frames(chooser, o, frames, 1.0, 2.0);
    EXPECT_GE(split, frames - kSplitClearProbeEvery - frames / kSplitProbeEvery);
    EXPECT_LE(split, frames - frames / kSplitClearProbeEvery + 1);
    // Per pair: a frame with twice the pairs and twice the time costs the same.
    SplitChooser per_pair;
    per_pair.choose(o);
    per_pair.learn(true, measured(4.0, 0, 2000000));
    per_pair.choose(o);
    per_pair.learn(false, measured(2.5, 0, 1000000));
    EXPECT_TRUE(per_pair.choose(o));
}

// What splitting costs in copy_out counts against it: split frames that draw as fast as whole
// ones but leave more of their copy exposed lose.
TEST(SplitChooser, ExposedCopyTimeCountsAgainstTheSideThatCausesIt) {
    const CatgsOptions o = timed_split_options();
    SplitChooser chooser;
    FrameStats split = measured(1.7, 0.05, 1000000), whole = measured(1.75, 0, 1000000);
    split.stage_ms[Stage::copy_out] = 0.33;
    whole.stage_ms[Stage::copy_out] = 0.04;
    ASSERT_TRUE(chooser.choose(o));
    chooser.learn(true, split);
    ASSERT_FALSE(chooser.choose(o));
    chooser.learn(false, whole);
    EXPECT_NEAR(chooser.split_cost().value(), 2.08, 1e-12);
    EXPECT_NEAR(chooser.whole_cost().value(), 1.79, 1e-12);
    int splits = 0;
    for (int i = 0; i < 4 * kSplitProbeEvery; ++i) {
        const bool s = chooser.choose(o);
        splits += s;
        chooser.learn(s, s ? split : whole);
    }
    EXPECT_EQ(splits, 4) << "only the probes, one in kSplitProbeEvery, split";
}

// A choice explores on its side's first frame and on probes, and only then; through the
// planner, such a frame's cost is not learned by the window cost model: at 4K the first frame
// splits and costs more than plain frames will, and learned as plain's cost it made losing
// windows look cheap (the kit's garden low path, session 9).
TEST(SplitChooser, ExploringFramesAreNotLearnedByTheWindowCostModel) {
    const CatgsOptions o = timed_split_options();
    SplitChooser chooser;
    EXPECT_TRUE(chooser.choose(o));
    EXPECT_TRUE(chooser.exploring());
    chooser.learn(true, measured(3.0, 0, 1000000));
    EXPECT_FALSE(chooser.choose(o));
    EXPECT_TRUE(chooser.exploring());
    chooser.learn(false, measured(2.0, 0, 1000000));
    int explored = 0, probes = 0;
    for (int i = 0; i < 4 * kSplitClearProbeEvery; ++i) {
        const bool s = chooser.choose(o);
        explored += chooser.exploring();
        probes += s;  // whole wins: every split is a probe
        chooser.learn(s, s ? measured(3.0, 0, 1000000) : measured(2.0, 0, 1000000));
    }
    EXPECT_EQ(explored, probes);
    EXPECT_EQ(probes, 4);

    const Scene scene = dense_scene("split exploring frames");
    const Camera cam = test::forward_camera(96, 64, 60.0);
    const RenderOptions ro = timed_render_options();
    CpuRenderer<float> renderer(1);
    ImageF image;
    renderer.render(scene, cam, ro, image);  // split, first of its side
    renderer.render(scene, cam, ro, image);  // whole, first of its side
    EXPECT_FALSE(renderer.planner().cost_model().plain_cost().has_value());
    renderer.render(scene, cam, ro, image);  // the cheaper side, learned
    EXPECT_TRUE(renderer.planner().cost_model().plain_cost().has_value());
}

// Without timings in the plan (window_cost work or off) every frame splits as the options say,
// so the frames do not depend on the machine; with nothing to split, nothing splits.
TEST(SplitChooser, SplitsAsTheOptionsSayWithoutTimingsAndNeverWithoutK) {
    for (WindowCost cost : {WindowCost::work, WindowCost::off}) {
        CatgsOptions o = timed_split_options();
        o.window_cost = cost;
        SplitChooser chooser;
        EXPECT_EQ(split_frames(chooser, o, 40, 5.0, 1.0), 40) << window_cost_name(cost);
    }
    CatgsOptions none = timed_split_options();
    none.split_k = 0;
    SplitChooser chooser;
    EXPECT_EQ(split_frames(chooser, none, 10, 1.0, 5.0), 0);
}

// On the CPU backend, through the planner: a frame the chooser keeps whole has no extra
// tasks where the same frame split has, and draws the image splitting draws (within
// kSplitMaxLevels: CatgsSplit.SplittingDoesNotChangeTheImage says why).
TEST(SplitChooser, AFrameKeptWholeByThePlannerHasNoSubtasks) {
    const Scene scene = dense_scene("split chooser frames");
    const Camera cam = test::forward_camera(96, 64, 60.0);
    const RenderOptions o = timed_render_options();  // cache off: every frame is a plain key frame
    CpuRenderer<float> renderer(1);
    ImageF first, second;
    const FrameStats a = renderer.render(scene, cam, o, first);
    const FrameStats b = renderer.render(scene, cam, o, second);
    EXPECT_GT(a.split_tasks, 0u);  // unmeasured: split first
    EXPECT_EQ(b.split_tasks, 0u);  // then whole, to measure it
    EXPECT_EQ(b.split_k, 0u);
    const ImageError e = compare(to_rgb8(first), to_rgb8(second));
    EXPECT_LE(e.max_abs, kSplitMaxLevels);
    EXPECT_GE(e.psnr, 60.0);
    EXPECT_TRUE(renderer.planner().split_chooser().split_cost().known());
    EXPECT_TRUE(renderer.planner().split_chooser().whole_cost().known());
}

// --- The ladder of k (SplitChooser: which k, while splitting pays) -------------------------

/// Runs `frames` list-building frames where splitting at k costs cost(k) and a whole frame
/// `whole_ms` per million pairs; returns the k of each frame (0: whole).
template <typename Cost>
std::vector<std::uint32_t> ladder_frames(SplitChooser& chooser, const CatgsOptions& o, int frames, Cost cost,
                                         double whole_ms) {
    std::vector<std::uint32_t> ks;
    for (int i = 0; i < frames; ++i) {
        const bool s = chooser.choose(o);
        const std::uint32_t k = s ? chooser.k() : 0;
        ks.push_back(k);
        chooser.learn(s, measured(s ? cost(k) : whole_ms, 0, 1000000));
    }
    return ks;
}

/// Cheapest at `best`, dearer by `per_step` for each doubling or halving away from it.
auto valley(std::uint32_t best, double per_step) {
    return [best, per_step](std::uint32_t k) { return 1.0 + per_step * std::fabs(std::log2(double(k) / best)); };
}

// From the options' k the chooser walks, one probed rung at a time, to the cheapest rung, down
// or up, never past the ladder's ends (k/8 .. 4k), and then spends all but its probes there.
TEST(SplitLadder, WalksToTheCheapestKWithinTheLadder) {
    const CatgsOptions o = timed_split_options();  // k = 8192
    for (const std::uint32_t best : {1024u, 2048u, 8192u, 32768u}) {
        SplitChooser chooser;
        const std::vector<std::uint32_t> ks =
            ladder_frames(chooser, o, 40 * kSplitRungProbeEvery, valley(best, 0.03), 3.0);
        EXPECT_EQ(chooser.chosen_k(), best);
        int at_best = 0, late = 0;
        for (std::size_t i = 0; i < ks.size(); ++i) {
            if (ks[i] == 0) continue;  // whole probes
            EXPECT_GE(ks[i], o.split_k >> kSplitLadderBelow) << "frame " << i;
            EXPECT_LE(ks[i], o.split_k << kSplitLadderAbove) << "frame " << i;
            if (i >= ks.size() / 2) {
                ++late;
                at_best += ks[i] == best;
            }
        }
        // The second half: one rung probe in kSplitRungProbeEvery split frames at most.
        EXPECT_GE(at_best, late - late / kSplitRungProbeEvery - 1) << "best " << best;
    }
}

// A rung clearly dearer than the chosen one is tried once, then only every
// kSplitClearProbeEvery decisions; a close one every other rung probe.
TEST(SplitLadder, ClearlyDearerRungsAreProbedSeldom) {
    const CatgsOptions o = timed_split_options();
    const int frames = 20 * kSplitClearProbeEvery;
    const auto off_rung = [&](double neighbour_cost) {
        SplitChooser chooser;
        const auto cost = [&](std::uint32_t k) { return k == o.split_k ? 1.0 : neighbour_cost; };
        int off = 0;
        for (std::uint32_t k : ladder_frames(chooser, o, frames, cost, 3.0)) off += k != 0 && k != o.split_k;
        EXPECT_EQ(chooser.chosen_k(), o.split_k);
        return off;
    };
    const int dear = off_rung(1.5), close = off_rung(1.0 + 0.5 * (kSplitRungClearMargin - 1.0));
    EXPECT_GE(dear, 2 * (frames / kSplitClearProbeEvery - 2));
    EXPECT_LE(dear, 2 * (frames / kSplitClearProbeEvery + 1));
    EXPECT_GE(close, frames / kSplitRungProbeEvery - 2);
    EXPECT_LE(close, frames / kSplitRungProbeEvery + 1);
}

// No ladder where whole frames are cheaper (only the chosen rung is probed, as before), with
// split_auto (the frame derives k: k() is 0), or without timings (the options' k).
TEST(SplitLadder, StaysOffTheLadderWhereItCannotPay) {
    const CatgsOptions o = timed_split_options();
    SplitChooser whole_wins;
    for (std::uint32_t k : ladder_frames(whole_wins, o, 8 * kSplitClearProbeEvery, valley(1024, 0.03), 0.5))
        EXPECT_TRUE(k == 0 || k == o.split_k) << k;

    CatgsOptions automatic = o;
    automatic.split_k = 0;
    automatic.split_auto = true;
    SplitChooser auto_k;
    for (std::uint32_t k : ladder_frames(auto_k, automatic, 4 * kSplitClearProbeEvery, valley(1024, 0.03), 3.0))
        EXPECT_EQ(k, 0u);

    CatgsOptions work = o;
    work.window_cost = WindowCost::work;
    SplitChooser fixed;
    for (std::uint32_t k : ladder_frames(fixed, work, 4 * kSplitRungProbeEvery, valley(1024, 0.03), 3.0))
        EXPECT_EQ(k, o.split_k);
}

// New options (another k, or auto) start a new ladder from their own k.
TEST(SplitLadder, NewOptionsStartANewLadder) {
    CatgsOptions o = timed_split_options();
    SplitChooser chooser;
    ladder_frames(chooser, o, 40 * kSplitRungProbeEvery, valley(1024, 0.03), 3.0);
    ASSERT_EQ(chooser.chosen_k(), 1024u);
    o.split_k = 100;
    EXPECT_TRUE(chooser.choose(o));
    EXPECT_EQ(chooser.k(), 100u);
    EXPECT_FALSE(chooser.split_cost().known());
}

// What a plan hands the backends: no splitting unless it splits, else its k (or the options'
// when it has none); split_auto keeps deriving k.
TEST(SplitLadder, PlanSplitOptionsCarryThePlansK) {
    CatgsOptions o = timed_split_options();
    FramePlanner::Plan plan;
    plan.split = false;
    plan.split_k = 2048;
    CatgsOptions s = plan.split_options(o);
    EXPECT_EQ(s.split_k, 0u);
    EXPECT_FALSE(s.split_auto);
    plan.split = true;
    EXPECT_EQ(plan.split_options(o).split_k, 2048u);
    plan.split_k = 0;
    EXPECT_EQ(plan.split_options(o).split_k, 8192u);
    o.split_k = 0;
    o.split_auto = true;
    plan.split_k = 2048;
    s = plan.split_options(o);
    EXPECT_TRUE(s.split_auto);
    EXPECT_EQ(s.split_k, 0u);
}

// On the CPU backend, through the planner: every frame that splits reports the k its plan
// chose, a rung of the ladder around the options' k.
TEST(SplitLadder, FramesReportThePlansK) {
    const Scene scene = dense_scene("split ladder frames");
    const Camera cam = test::forward_camera(96, 64, 60.0);
    const RenderOptions ro = timed_render_options();
    CpuRenderer<float> renderer(1);
    ImageF image;
    for (int i = 0; i < 3 * kSplitRungProbeEvery; ++i) {
        const FrameStats stats = renderer.render(scene, cam, ro, image);
        if (stats.split_k == 0) continue;
        EXPECT_EQ(stats.split_k, renderer.planner().split_chooser().k()) << "frame " << i;
        EXPECT_GE(stats.split_k, ro.catgs.split_k >> kSplitLadderBelow);
        EXPECT_LE(stats.split_k, ro.catgs.split_k << kSplitLadderAbove);
    }
}

// A cached frame draws its key frame's task list at the k it was split at, whatever k its own
// options or plan name (the CUDA backend's twin: CudaCatgsTest.CachedFramesDrawTheKeyFrames-
// SplitWhateverTheirOwnK, where the launch once followed the frame's own k and hung).
TEST(SplitLadder, CachedFramesKeepTheirKeyFramesK) {
    const Scene scene = dense_scene("cached frames keep k");
    Camera cam = test::forward_camera(96, 64, 60.0);
    RenderOptions o = test::cached_list_options(7);
    CpuRenderer<float> renderer(1);
    ImageF key_image, image;
    const FrameStats key = renderer.render(scene, cam, o, key_image);
    ASSERT_TRUE(key.key_frame);
    ASSERT_GT(key.split_tasks, 0u);
    o.catgs.split_k = 4096;
    for (int i = 1; i < 3; ++i) {
        cam.timestamp = i / 30.0;
        const FrameStats cached = renderer.render(scene, cam, o, image);
        EXPECT_FALSE(cached.key_frame) << "frame " << i;
        EXPECT_EQ(cached.split_k, 7u) << "frame " << i;
        EXPECT_EQ(cached.split_tasks, key.split_tasks) << "frame " << i;
        EXPECT_EQ(compare(to_rgb8(image), to_rgb8(key_image)).max_abs, 0) << "frame " << i;
    }
}

}  // namespace
}  // namespace catgs
