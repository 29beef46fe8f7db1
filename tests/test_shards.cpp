// One frame of a scene shared by several renderers (sharded_renderer.hpp) on the CPU backend:
// the shard plan (a k-d tree of planes along the chunks), the shards' visibility order, the
// partial output, the composite against the unsharded render on random scenes and the
// built-in city, the exact case (no Gaussian straddles a plane) and bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <random>

#include "catgs/builtin_city.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "catgs/renderer.hpp"
#include "catgs/scene_ops.hpp"
#include "catgs/shard_plan.hpp"
#include "catgs/sharded_renderer.hpp"
#include "shard_scenes.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

// Small frames keep every test well under a second per render on one core.
constexpr int kWidth = 160, kHeight = 120;
constexpr double kFov = 60.0;

ShardedRenderer::RendererFactory cpu_shards() {
    return [](int) { return make_renderer("cpu", Precision::single, 1); };
}

/// Float max abs error and 8-bit PSNR of `image` against `reference`.
struct Difference {
    double max_abs = 0;
    double psnr = 0;
};
Difference difference(const ImageF& image, const ImageF& reference) {
    Difference d;
    EXPECT_EQ(image.rgb.size(), reference.rgb.size());
    for (std::size_t i = 0; i < std::min(image.rgb.size(), reference.rgb.size()); ++i)
        d.max_abs = std::max(d.max_abs, static_cast<double>(std::fabs(image.rgb[i] - reference.rgb[i])));
    d.psnr = std::min(compare(to_rgb8(image), to_rgb8(reference)).psnr, 100.0);
    return d;
}

Scene chunked_random_scene(std::uint64_t seed, std::size_t count) {
    test::RandomSceneParams p;
    p.count = count;
    Scene s = test::random_scene(seed, p);
    partition_into_chunks(s);
    return s;
}

/// The built-in city of the city tests (40k Gaussians), chunked as load_scene chunks it.
Scene chunked_city(std::uint64_t seed) {
    CityParams params;
    params.gaussians = 40000;
    params.seed = seed;
    Scene city = make_city(params);
    partition_into_chunks(city);
    return city;
}

std::vector<Camera> random_scene_cameras() {
    return test::random_scene_cameras(kWidth, kHeight, kFov);
}

/// The city from a survey altitude at an angle, from two opposite sides.
std::vector<Camera> city_cameras(const Scene& city) {
    const Bounds& b = city.bounds;
    const std::array<double, 3> centre{0.5 * (b.min[0] + b.max[0]), 0.5 * (b.min[1] + b.max[1]), b.min[2]};
    const double span = std::max(b.max[0] - b.min[0], b.max[1] - b.min[1]);
    std::vector<Camera> cameras;
    for (double side : {-1.0, 1.0}) {
        Camera c;
        c.intrinsics = intrinsics_from_fov(kWidth, kHeight, kFov);
        c.pose = look_at({centre[0] + side * 0.6 * span, centre[1] - side * 0.4 * span, centre[2] + 0.5 * span}, centre,
                         {0, 0, 1});
        cameras.push_back(c);
    }
    return cameras;
}

ImageF render_unsharded(const Scene& scene, const Camera& camera, const RenderOptions& options) {
    CpuRenderer<float> renderer(1);
    ImageF image;
    renderer.render(scene, camera, options, image);
    return image;
}

ImageF render_sharded(const Scene& scene, int shards, const Camera& camera, const RenderOptions& options) {
    ShardedRenderer sharded(scene, shards, cpu_shards(), 1);
    ImageF image;
    sharded.render(camera, options, image);
    return image;
}

// Every Gaussian in exactly one shard, in scene order, on its side of every plane above its
// leaf, and the shards within the balance the tolerance allows at each of the tree's levels.
// Sampled plans (a node choosing on 2000 of its Gaussians, as 10^8 scenes do on 2^20) hold a
// sampling error of a few percent more.
TEST(ShardPlan, CellsPartitionTheSceneAlongPlanes) {
    const Scene scene = chunked_random_scene(test::fresh_seed("shard plan"), 12000);
    struct PlanCase {
        int k;
        std::size_t samples;
    };
    const std::size_t all = kShardPlanSamples, some = 2000;
    for (const auto& [k, samples] : {PlanCase{1, all}, PlanCase{2, all}, PlanCase{3, all}, PlanCase{4, all},
                                     PlanCase{8, all}, PlanCase{4, some}, PlanCase{8, some}}) {
        const ShardPlan plan = plan_shards(scene, k, samples);
        const double sampling = samples < scene.count() ? 0.05 : 0.0;
        ASSERT_EQ(plan.shards(), k);
        std::vector<int> owner(scene.count(), -1);
        for (int s = 0; s < k; ++s) {
            const auto& m = plan.members[static_cast<std::size_t>(s)];
            EXPECT_TRUE(std::is_sorted(m.begin(), m.end())) << "shard " << s;
            for (std::uint32_t i : m) {
                EXPECT_EQ(owner[i], -1) << "Gaussian " << i << " in two shards";
                owner[i] = s;
            }
            // A shard's share of the even split, within the tolerance compounded over the levels
            // (each side of a node within the tolerance of its share).
            const double even = static_cast<double>(scene.count()) / k;
            const double levels = std::ceil(std::log2(k)), slack = kShardBalanceTolerance + sampling;
            EXPECT_GE(static_cast<double>(m.size()), std::pow(1 - slack, levels) * even - levels)
                << "k " << k << " shard " << s;
            EXPECT_LE(static_cast<double>(m.size()), std::pow(1 + slack, levels) * even + levels)
                << "k " << k << " shard " << s;
        }
        EXPECT_EQ(std::count(owner.begin(), owner.end(), -1), 0) << "k " << k;
        // Walking the tree by a Gaussian's mean reaches its own shard.
        for (std::size_t i = 0; i < scene.count(); ++i) {
            int node = 0;
            while (plan.nodes[static_cast<std::size_t>(node)].shard < 0) {
                const ShardNode& n = plan.nodes[static_cast<std::size_t>(node)];
                node = scene.positions[3 * i + static_cast<std::size_t>(n.axis)] < n.plane ? n.below : n.above;
            }
            ASSERT_EQ(plan.nodes[static_cast<std::size_t>(node)].shard, owner[i]) << "k " << k << " Gaussian " << i;
        }
        const Scene first = extract_shard(scene, plan.members[0]);
        EXPECT_NO_THROW(first.check_consistent("shard 0"));
        EXPECT_EQ(first.origin, scene.origin);
    }
}

// Two clusters either side of x = 0: a camera on each side sees its own cluster's shard first;
// every camera gets each shard once, its own cell's first.
TEST(ShardPlan, VisibilityOrderFollowsTheCameraSide) {
    test::RandomSceneParams p;
    p.count = 4096;
    p.extent = 1.0;
    Scene scene = test::random_scene(test::fresh_seed("visibility order"), p);
    for (std::size_t i = 0; i < scene.count(); ++i) scene.positions[3 * i] += i % 2 ? 10.0f : -10.0f;
    partition_into_chunks(scene);
    const ShardPlan two = plan_shards(scene, 2);
    ASSERT_EQ(two.nodes[0].axis, 0);
    EXPECT_GT(two.nodes[0].plane, -9.0);
    EXPECT_LT(two.nodes[0].plane, 9.0);
    EXPECT_EQ(shard_visibility_order(two, std::array<double, 3>{-30.0, 0.0, 7.0}), (std::vector<int>{0, 1}));
    EXPECT_EQ(shard_visibility_order(two, std::array<double, 3>{30.0, 0.0, 7.0}), (std::vector<int>{1, 0}));

    const ShardPlan four = plan_shards(scene, 4);
    for (std::size_t i = 0; i < scene.count(); i += 97) {
        const std::array<double, 3> eye{scene.origin[0] + scene.positions[3 * i],
                                        scene.origin[1] + scene.positions[3 * i + 1],
                                        scene.origin[2] + scene.positions[3 * i + 2]};
        const std::vector<int> order = shard_visibility_order(four, eye);
        std::vector<int> sorted = order;
        std::sort(sorted.begin(), sorted.end());
        ASSERT_EQ(sorted, (std::vector<int>{0, 1, 2, 3}));
        int own = -1;
        for (int s = 0; s < 4; ++s) {
            const auto& m = four.members[static_cast<std::size_t>(s)];
            if (std::binary_search(m.begin(), m.end(), static_cast<std::uint32_t>(i))) own = s;
        }
        EXPECT_EQ(order.front(), own) << "a camera at Gaussian " << i << " is in its cell";
    }
}

// One shard: its scene is the scene, its partial finished with the background is the image.
// Bit-identical in float (the composite adds 0 + 1 * R and multiplies 1 * A); the plain
// pipeline and split tiles both.
TEST(ShardedRenderer, OneShardIsBitIdentical) {
    const Scene scene = chunked_random_scene(test::fresh_seed("one shard"), 6000);
    RenderOptions split;
    split.catgs.split_k = 64;  // split most tiles, so the partial of merged tiles is checked too
    split.background = {0.2f, 0.5f, 0.9f};
    for (const RenderOptions& options : {RenderOptions{}, split})
        for (const Camera& camera : random_scene_cameras()) {
            const ImageF reference = render_unsharded(scene, camera, options);
            ShardedRenderer one(scene, 1, cpu_shards(), 1);
            ImageF sharded;
            const ShardedFrameStats stats = one.render(camera, options, sharded);
            if (options.catgs.split_k > 0) {
                EXPECT_GT(stats.shards[0].split_tasks, 0u) << "no tile was split";
            }
            ASSERT_EQ(sharded.rgb.size(), reference.rgb.size());
            EXPECT_EQ(std::memcmp(sharded.rgb.data(), reference.rgb.data(), reference.rgb.size() * sizeof(float)), 0);
        }
}

// Double precision: the partial is rounded to float, so one shard matches to float rounding
// (the finished pixel is rounded once in the unsharded frame, R and A each in the partial).
TEST(ShardedRenderer, OneShardInDoubleMatchesToFloatRounding) {
    const Scene scene = chunked_random_scene(test::fresh_seed("one shard double"), 3000);
    RenderOptions options;
    options.background = {0.2f, 0.5f, 0.9f};
    const Camera camera = test::forward_camera(kWidth, kHeight, kFov);
    CpuRenderer<double> unsharded(1);
    ImageF reference, image;
    unsharded.render(scene, camera, options, reference);
    ShardedRenderer one(
        scene, 1, [](int) { return make_renderer("cpu", Precision::double_, 1); }, 1);
    one.render(camera, options, image);
    EXPECT_LT(difference(image, reference).max_abs, 1e-6);
}

// Non-finite means and scales (hostile or broken input that reached a scene): the plan still
// gives every Gaussian one shard (an infinite extent straddles every plane), and the sharded
// frame stays finite and close to the unsharded one (measured: 41.7 dB at worst of 6 seeds).
TEST(ShardedRenderer, NonFiniteGaussiansArePlannedAndRendered) {
    Scene scene = test::random_scene(test::fresh_seed("non-finite shards"), {});
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    for (std::size_t i = 0; i < scene.count(); i += 97) scene.positions[3 * i + i % 3] = i % 2 ? nan : inf;
    for (std::size_t i = 5; i < scene.count(); i += 89) scene.scales[3 * i] = inf;
    partition_into_chunks(scene);
    ASSERT_GE(scene.chunks.size(), 2u);
    const ShardPlan plan = plan_shards(scene, 2);
    EXPECT_EQ(plan.members[0].size() + plan.members[1].size(), scene.count());
    const Camera camera = test::forward_camera(kWidth, kHeight, kFov);
    const Difference d =
        difference(render_sharded(scene, 2, camera, RenderOptions{}), render_unsharded(scene, camera, RenderOptions{}));
    std::cout << "[non-finite] PSNR " << d.psnr << " dB, max abs " << d.max_abs << "\n";
    EXPECT_TRUE(std::isfinite(d.max_abs));
    EXPECT_GT(d.psnr, 20.0);
}

// Shards rendered at once, one thread each, give the image they give one after another.
TEST(ShardedRenderer, ConcurrentShardsGiveTheSameImage) {
    const Scene scene = chunked_random_scene(test::fresh_seed("concurrent shards"), 5000);
    const Camera camera = random_scene_cameras()[1];
    ShardedRenderer sequential(scene, 4, cpu_shards(), 1), concurrent(scene, 4, cpu_shards(), 1);
    concurrent.set_concurrent(true);
    ImageF a, b;
    sequential.render(camera, RenderOptions{}, a);
    const ShardedFrameStats stats = concurrent.render(camera, RenderOptions{}, b);
    EXPECT_EQ(stats.shards.size(), 4u);
    EXPECT_EQ(a.rgb, b.rgb);
}

// The partial is the image before the background: R + A * background reproduces render.
TEST(ShardedRenderer, PartialIsTheFrameBeforeItsBackground) {
    const Scene scene = chunked_random_scene(test::fresh_seed("partial"), 3000);
    const Camera camera = test::forward_camera(kWidth, kHeight, kFov);
    RenderOptions options;
    options.background = {0.3f, 0.6f, 0.1f};
    CpuRenderer<float> renderer(1);
    PartialImage partial;
    ImageF image;
    renderer.render_partial(scene, camera, options, partial);
    renderer.render(scene, camera, options, image);
    ASSERT_EQ(partial.width, kWidth);
    ASSERT_EQ(partial.height, kHeight);
    std::size_t covered = 0;
    for (std::size_t p = 0; p < partial.transmittance.size(); ++p) {
        covered += partial.transmittance[p] < 0.5f;
        for (int c = 0; c < 3; ++c)
            ASSERT_EQ(image.rgb[3 * p + c], partial.colour[3 * p + c] +
                                                partial.transmittance[p] * options.background[static_cast<size_t>(c)]);
    }
    EXPECT_GT(covered, partial.transmittance.size() / 10) << "the scene must cover part of the frame";
}

// Separated clusters (shard_scenes.hpp): no Gaussian straddles a plane, so k shards composite
// to the unsharded frame up to float rounding.
TEST(ShardedRenderer, NoStraddlersMatchesTheUnshardedFrame) {
    const Scene scene = test::separated_clusters(test::fresh_seed("separated clusters"));
    const Camera oblique = test::oblique_cluster_camera(kWidth, kHeight, kFov);
    RenderOptions options;
    options.background = {0.1f, 0.2f, 0.3f};
    for (int k : {2, 4, 8}) {
        EXPECT_EQ(plan_shards(scene, k).straddling, 0u) << "k " << k;
        for (const Camera& camera : {test::forward_camera(kWidth, kHeight, kFov), oblique}) {
            const Difference d =
                difference(render_sharded(scene, k, camera, options), render_unsharded(scene, camera, options));
            std::cout << "[separated] k " << k << ": PSNR " << d.psnr << " dB, max abs " << d.max_abs << "\n";
            // Measured over 10 seeds (60 frames): at most 4.8e-7, the float rounding of
            // C_front + A_front * C_back against the running blend.
            EXPECT_LT(d.max_abs, 1e-5) << "k " << k;
        }
    }
}

/// The worst PSNR and max abs error of k shards over `cameras`, against the unsharded frame.
struct ShardedError {
    double worst_psnr = 100, max_abs = 0;
};
std::map<int, ShardedError> sharded_errors(const Scene& scene, const std::vector<Camera>& cameras,
                                           const RenderOptions& options, const std::string& what) {
    std::map<int, ShardedError> errors;
    std::map<int, std::unique_ptr<ShardedRenderer>> sharded;
    for (int k : {2, 4, 8}) sharded[k] = std::make_unique<ShardedRenderer>(scene, k, cpu_shards(), 1);
    for (const Camera& camera : cameras) {
        const ImageF reference = render_unsharded(scene, camera, options);
        for (auto& [k, renderer] : sharded) {
            ImageF image;
            renderer->render(camera, options, image);
            const Difference d = difference(image, reference);
            std::cout << "[" << what << "] k " << k << " straddling " << renderer->plan().straddling << " of "
                      << scene.count() << ": PSNR " << d.psnr << " dB, max abs " << d.max_abs << "\n";
            errors[k].worst_psnr = std::min(errors[k].worst_psnr, d.psnr);
            errors[k].max_abs = std::max(errors[k].max_abs, d.max_abs);
        }
    }
    return errors;
}

// Random scenes: Gaussians everywhere, up to 1.2 m across in a 9 m box, so that at k = 8 some
// 44% of them straddle a plane: the worst case of the straddlers' error. Bounds: the worst frame
// of 60 seeds measured (PSNR k 2: 45.3 dB, k 4: 28.3, k 8: 25.2; max abs 0.55), less a margin
// for fresh seeds, above what the composite in reversed order gave (2 seeds: k 2 16.1-21.9 dB,
// k 4 16.1-20.6, k 8 16.1-19.2). max abs does not tell those apart (0.59-0.82 reversed): it is
// only bounded.
TEST(ShardedRenderer, RandomScenesStayCloseToTheUnshardedFrame) {
    const std::map<int, double> min_psnr{{2, 36.0}, {4, 24.0}, {8, 22.0}};
    for (int seed = 0; seed < 2; ++seed) {
        const Scene scene = chunked_random_scene(test::fresh_seed("random scene sharded"), 10000);
        for (const auto& [k, e] : sharded_errors(scene, random_scene_cameras(), RenderOptions{}, "random")) {
            EXPECT_GT(e.worst_psnr, min_psnr.at(k)) << "k " << k;
            EXPECT_LT(e.max_abs, 0.9) << "k " << k;
        }
    }
}

// The built-in city (40k Gaussians) from a survey altitude at an angle, on two sides. Its
// Gaussians are small against the shards (at most 2%, 7% and 13% straddle at k = 2, 4, 8).
// Bounds: the worst frame of 28 seeds measured (PSNR k 2: 47.1 dB, k 4: 42.6, k 8: 39.0; max
// abs 0.40), less a margin for fresh seeds, far above the reversed composite (17.3-22.2 dB).
// k = 1 is the unsharded frame, bit for bit.
TEST(ShardedRenderer, BuiltinCityStaysCloseToTheUnshardedFrame) {
    Scene city = chunked_city(test::fresh_seed("city sharded"));
    const std::vector<Camera> cameras = city_cameras(city);
    RenderOptions options;
    options.background = {0.5f, 0.7f, 0.9f};
    const std::map<int, double> min_psnr{{2, 40.0}, {4, 35.0}, {8, 32.0}};
    for (const auto& [k, e] : sharded_errors(city, cameras, options, "city")) {
        EXPECT_GT(e.worst_psnr, min_psnr.at(k)) << "k " << k;
        EXPECT_LT(e.max_abs, 0.7) << "k " << k;
    }
    const Difference one =
        difference(render_sharded(city, 1, cameras[0], options), render_unsharded(city, cameras[0], options));
    EXPECT_EQ(one.max_abs, 0.0);
}

// The city with the straddlers of its 8-shard plan made transparent, rendered with that plan:
// what remains once no Gaussian crosses a plane is the stop rule. A back shard starts its blend
// at T = 1, so it blends on past the point where the unsharded blend, whose T is the front
// shards' times its own, stopped (T (1 - alpha) < 1e-4). What it adds there is at most that T,
// below 1e-4 / (1 - kMaxAlpha) = 1e-2 (colours and background in [0, 1]). Measured over 28 seeds
// (56 frames): at most 3.8e-3 (PSNR 74.9 dB and up), against 0.40 with the straddlers.
TEST(ShardedRenderer, BuiltinCityWithoutStraddlersIsExactUpToTheStopRule) {
    Scene city = chunked_city(test::fresh_seed("city without straddlers"));
    const int k = 8;
    ShardPlan plan = plan_shards(city, k);
    std::size_t removed = 0;
    for (std::size_t i = 0; i < city.count(); ++i) {
        for (const ShardNode& n : plan.nodes) {
            if (n.shard >= 0) continue;  // a leaf: no plane (axis -1)
            if (straddles_plane(city, i, n.axis, n.plane) && city.opacities[i] > 0) {
                city.opacities[i] = 0;
                ++removed;
            }
        }
    }
    EXPECT_GT(removed, 0u);
    RenderOptions options;
    options.background = {0.5f, 0.7f, 0.9f};
    ShardedRenderer sharded(city, std::move(plan), cpu_shards(), 1);
    for (const Camera& camera : city_cameras(city)) {
        ImageF image;
        sharded.render(camera, options, image);
        const Difference d = difference(image, render_unsharded(city, camera, options));
        std::cout << "[city without straddlers] PSNR " << d.psnr << " dB, max abs " << d.max_abs << "\n";
        EXPECT_LT(d.max_abs, 1e-2);
    }
}

/// A backend without partial output: what the default Renderer::render_partial answers.
class NoPartialRenderer final : public Renderer {
public:
    void set_scene(std::shared_ptr<const Scene>) override {}
    FrameStats render(const Camera&, const RenderOptions&, ImageF&, const FrameHints*) override { return {}; }
    void reset_cache() override {}
    std::string name() const override { return "test/none"; }
};

using test::error_of;

TEST(ShardedRenderer, BadInputIsNamed) {
    const Scene scene = chunked_random_scene(test::fresh_seed("shard bad input"), 3000);
    const int chunks = static_cast<int>(scene.chunks.size());
    ASSERT_GE(chunks, 3);
    EXPECT_EQ(error_of([&] { plan_shards(scene, 0); }), "shard plan: 0 shards: expected 1..64");
    EXPECT_EQ(error_of([&] { plan_shards(scene, -2); }), "shard plan: -2 shards: expected 1..64");
    EXPECT_EQ(error_of([&] { plan_shards(scene, 65); }), "shard plan: 65 shards: expected 1..64");
    EXPECT_EQ(error_of([&] { plan_shards(scene, chunks + 1); }),
              "shard plan: " + std::to_string(chunks + 1) + " shards but the scene has " + std::to_string(chunks) +
                  " chunks (3000 Gaussians): a shard is cut along chunks, at most one shard per chunk "
                  "(partition_into_chunks makes one per 1024 Gaussians)");
    EXPECT_NO_THROW(plan_shards(scene, chunks));
    EXPECT_EQ(error_of([&] {
                  ShardedRenderer(scene, chunks + 2, cpu_shards());
              }).rfind("shard plan: " + std::to_string(chunks + 2) + " shards but", 0),
              0u);
    Scene unchunked = scene;
    unchunked.chunks.clear();
    EXPECT_NO_THROW(plan_shards(unchunked, 1));
    EXPECT_NE(error_of([&] { plan_shards(unchunked, 2); }).find("the scene has 1 chunk (3000 Gaussians)"),
              std::string::npos);

    EXPECT_EQ(error_of([&] {
                  extract_shard(scene, {4, 2});
              }),
              "extract_shard: member 1 is Gaussian 2: members must be ascending and below the scene's 3000 Gaussians");
    EXPECT_EQ(error_of([&] { extract_shard(scene, {3000}); }),
              "extract_shard: member 0 is Gaussian 3000: members must be ascending and below the scene's 3000 "
              "Gaussians");

    PartialImage a, b;
    a.resize(4, 3);
    b.resize(3, 4);
    ImageF out;
    EXPECT_EQ(error_of([&] {
                  composite_partials({}, {0, 0, 0}, out);
              }),
              "composite_partials: no partial images to composite");
    EXPECT_EQ(error_of([&] {
                  composite_partials({&a, &b}, {0, 0, 0}, out);
              }),
              "composite_partials: partial 1 is 3x4 with 12 transmittances, expected the first partial's 4x3 with "
              "one value per pixel");

    ShardPlan twice = plan_shards(scene, 2);
    const std::uint32_t shared = twice.members[0].back();
    twice.members[1].insert(twice.members[1].begin(), shared);
    EXPECT_EQ(error_of([&] { ShardedRenderer(scene, twice, cpu_shards()); }),
              "sharded renderer: shard 1 holds Gaussian " + std::to_string(shared) + ", which an earlier shard holds");
    ShardPlan short_one = plan_shards(scene, 2);
    short_one.members[0].pop_back();
    EXPECT_EQ(error_of([&] { ShardedRenderer(scene, short_one, cpu_shards()); }),
              "sharded renderer: the plan's shards hold 2999 of the scene's 3000 Gaussians: not a plan of this scene");

    NoPartialRenderer none;
    PartialImage partial;
    EXPECT_EQ(error_of([&] { none.render_partial(test::forward_camera(8, 8, 60), RenderOptions{}, partial); }),
              "render_partial: not supported by backend test/none");
    EXPECT_EQ(error_of([&] {
                  ShardedRenderer(scene, 2, [](int) {
                      return std::make_unique<NoPartialRenderer>();
                  }).render(test::forward_camera(8, 8, 60), RenderOptions{}, out);
              }),
              "render_partial: not supported by backend test/none");
    EXPECT_EQ(error_of([&] { ShardedRenderer(scene, 2, [](int) { return std::unique_ptr<Renderer>(); }); }),
              "sharded renderer: the factory made no renderer for shard 0");
}

}  // namespace
}  // namespace catgs
