// Options and per-frame statistics shared by every backend.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "catgs/cache.hpp"
#include "catgs/constants.hpp"
#include "catgs/stages/tiles.hpp"

namespace catgs {

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

/// Parses "exact", "bbox3sigma", "opacity-aware"; throws catgs::Error listing them otherwise.
Culling parse_culling(const std::string& name);
const char* culling_name(Culling culling);

/// Wall time per stage (milliseconds) and work counts of one frame.
struct FrameStats {
    std::uint64_t visible = 0;  ///< Gaussians that passed preprocess
    std::uint64_t pairs = 0;    ///< tile-Gaussian pairs emitted (render length)
    std::uint64_t chunks = 0;   ///< the scene's chunks (1 per kChunkGaussians; 0 if unpartitioned)
    std::uint64_t chunks_culled = 0;  ///< chunks a key frame skipped whole (cached frames: the key's)
    std::uint64_t arena_bytes = 0;  ///< device memory held by the renderer's arenas (GPU)
    int bands = 1;              ///< horizontal bands the frame was rendered in (GPU overflow path)
    bool key_frame = true;      ///< false: drawn from the inter-frame cache
    int window = 1;             ///< W of the window this frame belongs to
    std::uint64_t tasks = 0;    ///< rasterizer tasks: tiles plus extra split sub-tasks
    std::uint64_t split_tasks = 0;  ///< extra sub-tasks from splitting
    std::uint32_t split_k = 0;  ///< the k used this frame (0: no splitting)
    /// keys_ms covers the emit pass, scan_ms the prefix sum of tile counts (the CPU backend
    /// folds its scan into keys_ms), copy_ms the copy of the image to the host (GPU).
    /// split_ms covers building the task list, merge_ms the merge of split sub-tasks.
    double preprocess_ms = 0, scan_ms = 0, keys_ms = 0, sort_ms = 0, ranges_ms = 0, split_ms = 0, rasterize_ms = 0,
           merge_ms = 0, copy_ms = 0, total_ms = 0;
};

}  // namespace catgs
