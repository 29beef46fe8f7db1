// Options and per-frame statistics shared by every backend.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "catgs/cache.hpp"
#include "catgs/constants.hpp"
#include "catgs/stage.hpp"
#include "catgs/stages/culling.hpp"

namespace catgs {

/// A value-initialised RenderOptions is the plain per-frame pipeline (opacity-aware culling with
/// chunks, no split, no cache): the pipeline tests compare against. The tools and the server
/// start from default_pipeline_options() instead.
struct RenderOptions {
    Culling culling = Culling::opacity_aware;
    std::array<float, 3> background{0.0f, 0.0f, 0.0f};
    double near_plane = kDefaultNearPlane;
    /// Skip the scene's chunks (Scene::chunks) that no pose of the frame can see, without
    /// touching their Gaussians (stages/chunks.hpp). Exact culling, the reference, never skips.
    bool chunk_culling = true;
    /// CaT-GS: tile task splitting, the speculative inter-frame cache and its window.
    CatgsOptions catgs;
};

/// Tile lists longer than this are split by default: the k that the H200 sweep of the issue
/// scenes found fastest with the cache below: on the 6M city at 1080p it costs 0.01 ms against
/// no split (1.05 ms), where k = 2048 or 4096 cost 0.1 ms; on the garden 3x3 it takes 2.16 ms
/// against 2.55 unsplit (2048: 2.12). With measured costs (WindowCost::time) it is where
/// SplitChooser's ladder of k starts.
inline constexpr std::uint32_t kDefaultSplitK = 8192;
/// The largest k accepted: k is stored with the task counters in 32 bits, and no tile list of a
/// frame within the pair budget comes near it.
inline constexpr std::uint32_t kMaxSplitK = 1u << 24;
/// The default guard band: 1 px cuts the cached pairs by 12% against 2 px (city 5.2M against
/// 5.9M) at the same number of key frames, since W, not the envelope, ends the windows there.
inline constexpr double kDefaultGuardPx = 1.0;

/// By default a cached frame reuses the key frame's depth order only when its orientation is
/// the key frame's up to rounding: a translation keeps every depth order, so such frames are
/// the per-frame pipeline's, while any turn swaps exactly coplanar layers of the city. Measured
/// on the 60k test city at 320x180 (W = 4): 0.05 deg let a hover's yaw drift swap layers by up
/// to 25 levels (worst PSNR 58.8 dB against 65.0 re-sorted), and reusing at any angle (the
/// paper's cache) fell below the accuracy bar on an orbit (worst frame 37.7 dB, 120 levels).
inline constexpr double kDefaultReuseOrderMaxAngle = 1e-6;  // radians

/// The pipeline catgs-render, catgs-bench and the server run unless told otherwise: the fastest
/// configuration on the H200 that meets the accuracy bar (PSNR >= 45 dB mean and >= 40 dB on
/// the worst frame against the per-frame pipeline, no tile missing a Gaussian; docs/results/)
/// on every test path: the CaT-GS speculative cache with the adaptive window, W chosen from the
/// measured frame times within the motion bound and plain frames where no window pays
/// (window_cost.hpp); its frames reuse the key frame's depth order while the camera only
/// translates and re-sort once it turns (kDefaultReuseOrderMaxAngle); split k = kDefaultSplitK;
/// guard kDefaultGuardPx.
inline RenderOptions default_pipeline_options() {
    RenderOptions o;
    o.catgs.cache = CacheMode::speculative;
    o.catgs.adaptive_window = true;
    o.catgs.window_cost = WindowCost::time;
    o.catgs.resort_cached = false;
    o.catgs.reuse_order_max_angle = kDefaultReuseOrderMaxAngle;
    o.catgs.split_k = kDefaultSplitK;
    o.catgs.guard_px = kDefaultGuardPx;
    return o;
}

/// The whole of `text` as a split k in 1..kMaxSplitK; nullopt otherwise (flag parsers of the
/// tools and the client word their own errors).
std::optional<std::uint32_t> parse_split_k(const std::string& text);
/// The whole of `text` as an angle in 0..180 degrees; nullopt otherwise.
std::optional<double> parse_degrees(const std::string& text);

/// Wall time per stage (milliseconds) and work counts of one frame.
struct FrameStats {
    std::uint64_t visible = 0;        ///< Gaussians that passed preprocess
    std::uint64_t pairs = 0;          ///< tile-Gaussian pairs emitted (render length)
    std::uint64_t chunks = 0;         ///< the scene's chunks (1 per kChunkGaussians; 0 if unpartitioned)
    std::uint64_t chunks_culled = 0;  ///< chunks a key frame skipped whole (cached frames: the key's)
    std::uint64_t arena_bytes = 0;    ///< device memory held by the renderer's arenas (GPU)
    int bands = 1;                    ///< horizontal bands the frame was rendered in (over the pair budget)
    bool key_frame = true;            ///< false: drawn from the inter-frame cache
    int window = 1;                   ///< W of the window this frame belongs to
    bool order_reused = false;        ///< cached frame drawn in the key frame's depth order (not re-sorted)
    std::uint64_t tasks = 0;          ///< rasterizer tasks: tiles plus extra split sub-tasks
    std::uint64_t split_tasks = 0;    ///< extra sub-tasks from splitting
    std::uint32_t split_k = 0;        ///< the k used this frame (0: no splitting)
    /// The most pairs one tile's list holds (exact culling: the one shared list).
    std::uint64_t longest_list = 0;
    /// Occlusion cut (CatgsOptions::occlusion_cut): Gaussians left out of the lists behind the
    /// predicted cut, the pairs they would have had, and whether a tile missed so that the frame
    /// was drawn a second time without it (its stage times are both passes').
    std::uint64_t occluded = 0;
    std::uint64_t occluded_pairs = 0;
    bool occlusion_redrawn = false;
    /// Wall time of each stage (stage.hpp). The CPU backend folds scan into keys and has no
    /// copy_out; encode is the server's.
    StageTimes stage_ms;
    /// The whole frame: the sum of the stages on the GPU (CUDA events), wall time on the CPU.
    double total_ms = 0;
};

}  // namespace catgs
