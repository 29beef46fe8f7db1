// The occlusion cut (stages/occlusion.hpp) through the CPU backend: every frame's image is the
// one the full lists draw, bit for bit, whether the cut held, missed and drew the frame again,
// or stood aside (windows, splits, exact culling, partials, double); and it does leave
// Gaussians out of dense scenes. The CUDA backend's twin is tests/gpu/test_cuda_occlusion.cpp.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <iostream>
#include <string>
#include <utility>
#include <vector>

#include "catgs/cpu_renderer.hpp"
#include "occlusion_paths.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

constexpr int kWidth = 160, kHeight = 120;  // 10 x 8 tiles
using test::occlusion::kJumpFrame;

std::vector<Camera> occlusion_path() {
    return test::occlusion::path(kWidth, kHeight);
}

Scene dense_scene(const std::string& what) {
    return test::random_scene(test::fresh_seed(what), test::occlusion::dense_scene(60000));
}

using test::occlusion::PathCounts;

/// Renders `path` with the cut on and off, one renderer each, and asserts every frame equal.
template <typename T>
PathCounts compare_path(const Scene& scene, const std::vector<Camera>& path, RenderOptions options,
                        const std::string& what) {
    CpuRenderer<T> with, without;
    RenderOptions off = options;
    options.catgs.occlusion_cut = true;
    off.catgs.occlusion_cut = false;
    PathCounts counts;
    for (std::size_t f = 0; f < path.size(); ++f) {
        ImageF a_image, b_image;
        const FrameStats a = with.render(scene, path[f], options, a_image);
        const FrameStats b = without.render(scene, path[f], off, b_image);
        const std::string frame = what + ", frame " + std::to_string(f);
        EXPECT_EQ(a_image.rgb, b_image.rgb) << frame;
        test::occlusion::check_frame(a, b, frame, counts);
    }
    test::occlusion::report(counts, what);
    return counts;
}

TEST(CpuOcclusion, EveryFrameIsTheFullListsImageWhetherTheCutHeldOrMissed) {
    const Scene scene = dense_scene("cpu occlusion cut");
    const std::vector<Camera> path = occlusion_path();
    const PathCounts c = compare_path<float>(scene, path, RenderOptions{}, "float");
    EXPECT_GE(c.frames_cut, 4u) << "the glide's frames leave Gaussians out";
    ASSERT_EQ(c.stats.size(), path.size());
    // The first frame has no cut recorded yet; the glide's next frames take it and most hold. A
    // tile whose faint pixels only just reach the 1e-4 bound can stop past its margin and draw
    // its frame again (two such misses in the glide on about one scene in forty), so what must
    // hold is that the cut did hold on some of the glide, the path where it changes the lists.
    EXPECT_EQ(c.stats[0].occluded, 0u);
    int glide_held = 0;
    for (std::size_t f = 1; f < kJumpFrame; ++f) glide_held += c.stats[f].occluded > 0 && !c.stats[f].occlusion_redrawn;
    std::cout << "[occlusion] the cut held on " << glide_held << " of the glide's " << kJumpFrame - 1 << " frames"
              << std::endl;
    EXPECT_GE(glide_held, 1) << "the cut never held on the glide";
    // The jump past the edge misses, unless the frame before it missed and the back-off skips it.
    const FrameStats& jump = c.stats[kJumpFrame];
    if (!c.stats[kJumpFrame - 1].occlusion_redrawn) {
        EXPECT_TRUE(jump.occlusion_redrawn) << "the jump past the edge misses";
        EXPECT_GT(jump.occluded, 0u) << "the jump's cut pass left Gaussians out";
    }
    // Past the miss the tracker backs off a frame, and the wide turn takes no cut.
    EXPECT_EQ(c.stats[kJumpFrame + 1].occluded, 0u);
    EXPECT_FALSE(c.stats[kJumpFrame + 1].occlusion_redrawn);
}

// A renderer that forgets its cache forgets the recorded cut too: its next frame takes none.
TEST(CpuOcclusion, ResetCacheForgetsTheRecordedCut) {
    const Scene scene = dense_scene("cpu occlusion reset");
    const std::vector<Camera> path = occlusion_path();
    RenderOptions on;
    on.catgs.occlusion_cut = true;
    CpuRenderer<float> renderer;
    ImageF image;
    renderer.render(scene, path[0], on, image);
    EXPECT_GT(renderer.render(scene, path[1], on, image).occluded, 0u);
    renderer.reset_cache();
    EXPECT_EQ(renderer.render(scene, path[2], on, image).occluded, 0u);
    EXPECT_GT(renderer.render(scene, path[3], on, image).occluded, 0u);
}

/// What a frame at path[1] with `options` leaves out after a plain frame at path[0] recorded its
/// cut: the frame after a plain one has a cut to take, unless its options stand it aside.
std::uint64_t occluded_after_a_recorded_cut(const Scene& scene, const std::vector<Camera>& path,
                                            RenderOptions options) {
    RenderOptions plain;
    plain.catgs.occlusion_cut = options.catgs.occlusion_cut = true;
    CpuRenderer<float> renderer;
    ImageF image;
    renderer.render(scene, path[0], plain, image);
    return renderer.render(scene, path[1], options, image).occluded;
}

// Where the cut cannot be checked tile by tile it stands aside: split tiles (a sub-task's stop
// says nothing of its tile's) and windows of the cache (their lists serve other poses, also
// where the key frame holds the actual pose alone). The images stay the full lists' all the same.
TEST(CpuOcclusion, StandsAsideForSplitsAndWindows) {
    const Scene scene = dense_scene("cpu occlusion aside");
    const std::vector<Camera> path = occlusion_path();
    RenderOptions split;
    split.catgs.split_k = 64;
    RenderOptions window;
    window.catgs.cache = CacheMode::speculative;
    window.catgs.adaptive_window = false;
    window.catgs.window = 4;
    RenderOptions unspeculated = window;
    unspeculated.catgs.cache = CacheMode::unspeculated;
    ASSERT_GT(occluded_after_a_recorded_cut(scene, path, RenderOptions{}), 0u) << "a plain frame takes the cut";
    // Split sub-tasks each blend their slice from T = 1: a short glide keeps the test quick.
    const std::vector<Camera> glide(path.begin(), path.begin() + 4);
    for (const auto& [name, options] :
         {std::pair{"split", split}, std::pair{"window", window}, std::pair{"unspeculated", unspeculated}}) {
        const PathCounts c = compare_path<float>(scene, glide, options, name);
        EXPECT_EQ(c.occluded, 0u) << name;
        EXPECT_EQ(c.redrawn, 0u) << name;
        if (options.catgs.split_k > 0)
            for (const FrameStats& f : c.stats) EXPECT_GT(f.split_tasks, 0u) << name;
        else
            EXPECT_FALSE(c.stats.back().key_frame) << name << ": the window draws cached frames";
        EXPECT_EQ(occluded_after_a_recorded_cut(scene, path, options), 0u) << name;
    }
}

// Exact culling shares one list between every tile: it neither takes the cut nor records one.
TEST(CpuOcclusion, StandsAsideForExactCulling) {
    // Every pixel walks the one list of every Gaussian: fewer, larger Gaussians.
    test::RandomSceneParams p;
    p.count = 6000;
    p.extent = 3.0;
    p.depth_max = 20.0;
    p.log_scale_min = -2.0;
    p.log_scale_max = -0.5;
    const Scene scene = test::random_scene(test::fresh_seed("cpu occlusion exact"), p);
    const std::vector<Camera> path = occlusion_path();
    RenderOptions exact, boxes;
    exact.culling = Culling::exact;
    const std::vector<Camera> two(path.begin(), path.begin() + 2);
    EXPECT_EQ(compare_path<float>(scene, two, exact, "exact").occluded, 0u);
    ASSERT_GT(occluded_after_a_recorded_cut(scene, path, boxes), 0u) << "a plain frame takes the cut";
    EXPECT_EQ(occluded_after_a_recorded_cut(scene, path, exact), 0u);
    // An exact frame records nothing: the bounding-box frame after it has no cut to take.
    exact.catgs.occlusion_cut = boxes.catgs.occlusion_cut = true;
    CpuRenderer<float> renderer;
    ImageF image;
    renderer.render(scene, path[0], exact, image);
    EXPECT_EQ(renderer.render(scene, path[1], boxes, image).occluded, 0u);
}

// A partial frame (a shard's colour and transmittance) goes on past its own Gaussians' opacity,
// so it neither takes the cut nor records one; nor does double, the reference precision.
TEST(CpuOcclusion, PartialAndDoubleFramesTakeNoCut) {
    const Scene scene = dense_scene("cpu occlusion partial");
    const std::vector<Camera> path = occlusion_path();
    RenderOptions on, off;
    on.catgs.occlusion_cut = true;
    CpuRenderer<float> with, without;
    for (std::size_t f = 0; f < 3; ++f) {
        PartialImage a, b;
        const FrameStats stats = with.render_partial(scene, path[f], on, a);
        without.render_partial(scene, path[f], off, b);
        EXPECT_EQ(stats.occluded, 0u) << f;
        EXPECT_EQ(a.colour, b.colour) << f;
        EXPECT_EQ(a.transmittance, b.transmittance) << f;
        EXPECT_EQ(a.stopped, b.stopped) << f;
    }
    // A partial records nothing: the image after it has no cut to take; nor does a partial take
    // the cut an image recorded, though the image after the next takes it.
    ImageF image;
    EXPECT_EQ(with.render(scene, path[3], on, image).occluded, 0u);
    PartialImage partial;
    EXPECT_EQ(with.render_partial(scene, path[4], on, partial).occluded, 0u);
    with.render(scene, path[5], on, image);
    EXPECT_GT(with.render(scene, path[6], on, image).occluded, 0u);
    const std::vector<Camera> glide(path.begin(), path.begin() + 3);
    const PathCounts c = compare_path<double>(scene, glide, RenderOptions{}, "double");
    EXPECT_EQ(c.occluded, 0u);
}

}  // namespace
}  // namespace catgs
