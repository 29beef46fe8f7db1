// The CPU backend and reference renderer. It runs the same stages as the GPU (stage.hpp):
//   chunk_cull -> preprocess -> keys (scan folded in) -> sort -> ranges -> split -> rasterize -> merge
// each a member of that name with its own buffer, using the host-device math in stages/.
// With the CaT-GS cache on, a key frame preprocesses every Gaussian against the window's W
// poses (the union of its footprints) and the following frames of the window only re-project
// the cached Gaussians before rasterizing the cached lists (cache.hpp). With the occlusion cut
// on, a plain float frame leaves out the Gaussians behind where the last frame's tiles turned
// opaque, and is drawn again without the cut where a tile did not (stages/occlusion.hpp).
// Precision is a template parameter (float and double are instantiated). Deterministic:
// keys are emitted in Gaussian order from a prefix-sum layout and sorted stably, so equal
// depths in a tile keep Gaussian-index order; the result is independent of thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "catgs/cache.hpp"
#include "catgs/camera.hpp"
#include "catgs/image.hpp"
#include "catgs/occlusion_tracker.hpp"
#include "catgs/partial_image.hpp"
#include "catgs/render_options.hpp"
#include "catgs/scene.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/tiles.hpp"

namespace catgs {

/// [begin, end) into the sorted pair arrays. 64-bit: pair counts can pass 2^32.
struct TileRange {
    std::uint64_t begin = 0, end = 0;
};

/// A rasterizer task: sub-task `index` of `tile` (index 0 for every tile; 1.. for the extra
/// sub-tasks of split tiles, the CaT-GS label).
struct TileTask {
    std::uint32_t tile = 0, index = 0;
};

/// What one CpuRenderer may hold.
struct CpuLimits {
    /// Tile-Gaussian pairs one pass of keys, sort and rasterize may hold (0: auto, a share of
    /// the host's memory, CpuRenderer::pair_budget). A frame with more is rendered in bands of
    /// tile rows (FrameStats::bands), as the GPU renders its own.
    std::uint64_t max_pairs = 0;
};

template <typename T>
class CpuRenderer {
public:
    /// threads <= 0 uses every hardware thread.
    explicit CpuRenderer(int threads = 0, CpuLimits limits = {});

    /// Renders one frame into `out` (resized to the camera's image). Throws catgs::Error on
    /// invalid intrinsics. `hints` may carry the client's flight plan or velocity.
    FrameStats render(const Scene& scene, const Camera& camera, const RenderOptions& options, ImageF& out,
                      const FrameHints* hints = nullptr);

    /// The same frame without its background: the (R, A) per pixel that render would finish
    /// with C = R + A * background, and where the blend stopped (partial_image.hpp).
    FrameStats render_partial(const Scene& scene, const Camera& camera, const RenderOptions& options, PartialImage& out,
                              const FrameHints* hints = nullptr);

    /// Forgets the inter-frame cache, the pose history and the recorded occlusion cut (a new
    /// stream or a new scene).
    void reset_cache();

    /// The pairs one pass may hold: CpuLimits::max_pairs, or with 0 kAutoPairMemoryShare of the
    /// host's physical memory at kBytesPerPair (sort buffers and a window's kept pairs included).
    std::uint64_t pair_budget() const;

    // Stage outputs of the last frame, for tests and tools.
    const std::vector<Projected<T>>& projected() const { return projected_; }
    const std::vector<std::uint32_t>& tiles_touched() const { return tiles_touched_; }
    const std::vector<std::uint64_t>& sorted_keys() const { return keys_; }
    const std::vector<std::uint32_t>& sorted_values() const { return values_; }
    const std::vector<TileRange>& tile_ranges() const { return ranges_; }
    const std::vector<TileTask>& tasks() const { return tasks_; }
    /// The frame planner: what its cost models have learned.
    const FramePlanner& planner() const { return planner_; }
    /// Test-only: the (R, A) that sub-task `index` of split tile `tile` left at the tile's
    /// kTileSize x kTileSize pixels (row-major within the tile; pixels past the image edge are
    /// unspecified), before merge. nullptr when the tile was not split or index is past its
    /// last sub-task.
    const Partial<T>* partial(std::uint32_t tile, std::uint32_t index) const;

private:
    struct Window {
        std::vector<View<T>> views;  // pose 0 is the actual (key) pose
        T guard = T(0);
        T guard_translation = T(0);  // envelope radius in metres (speculation)
        T near_plane = T(0);         // lowered by the translation guard for speculation
    };
    /// Where a frame's pixels go: the finished image, or the partial (exactly one is set).
    struct FrameOutput {
        ImageF* image = nullptr;
        PartialImage* partial = nullptr;
    };
    FrameStats render_frame(const Scene& scene, const Camera& camera, const RenderOptions& options,
                            const FrameOutput& out, const FrameHints* hints);
    Window key_window(const Scene& scene, const FramePlanner::Plan& plan, const RenderOptions& options) const;
    /// One pass over the frame, its stage times added to `stats`; returns whether it was banded.
    bool draw(const Scene& scene, const View<T>& view, const Window& window, const FramePlanner::Plan& plan,
              const RenderOptions& options, const FrameOutput& out, FrameStats& stats);
    void chunk_cull(const Scene& scene, const Window& window, bool cull_chunks);
    void preprocess(const Scene& scene, const View<T>& actual, const Window& window, Culling culling);
    void reproject(const Scene& scene, const View<T>& actual);
    void keys(const Scene& scene, const Window& window, Culling culling);
    void rekey(const View<T>& view, Culling culling);
    void sort(const View<T>& view);
    void ranges(const View<T>& view, Culling culling);
    std::uint32_t split(const CatgsOptions& options);
    /// `split_options`: the plan's (FramePlanner::Plan::split_options).
    void sort_and_schedule(const View<T>& view, const RenderOptions& options, const CatgsOptions& split_options,
                           FrameStats& stats);
    void rasterize(const View<T>& view, const RenderOptions& options, const FrameOutput& out);
    void merge(const View<T>& view, const RenderOptions& options, const FrameOutput& out);
    void draw_tasks(const View<T>& view, const RenderOptions& options, const FrameOutput& out, FrameStats& stats);
    KeyFrameSummary summarize(const Scene& scene, const Window& window, Culling culling) const;

    /// Over the pair budget (cpu_renderer_bands.cpp): the tile rows split so that each band's
    /// pairs fit, then keys -> sort -> ranges -> split -> rasterize -> merge per band.
    bool needs_bands(Culling culling) const;
    std::vector<TileRows> plan_bands(const Scene& scene, const Window& window, Culling culling) const;
    void render_bands(const Scene& scene, const View<T>& view, const Window& window, const RenderOptions& options,
                      const CatgsOptions& split_options, const FrameOutput& out, FrameStats& stats);
    bool banded() const { return band_.begin > 0 || band_.end < tiles_y_; }

    /// The frame drawn (cpu_renderer_occlusion.cpp): with the occlusion cut where it takes it,
    /// and again without it where a tile missed; returns whether the last pass was banded.
    bool draw_frame(const Scene& scene, const Camera& camera, const View<T>& view, const Window& window,
                    const FramePlanner::Plan& plan, const RenderOptions& options, const FrameOutput& out,
                    FrameStats& stats);
    /// The occlusion cut (stages/occlusion.hpp): whether this frame records its tile cuts and
    /// takes the cut (then the pyramid's cells are set); once a frame.
    void plan_occlusion(const Camera& camera, const View<T>& view, const RenderOptions& options,
                        const FramePlanner::Plan& plan, const FrameOutput& out);
    bool cutting() const { return !occlusion_cells_.empty(); }
    /// Whether preprocess leaves out a Gaussian of the single pose `pose` (a cutting frame).
    bool occluded_at(const Projected<T>& pose, Culling culling, const View<T>& view) const;
    /// Rasterize's end of a whole tile that every pixel stopped by sort depth `stop_depth`
    /// (+infinity: not all): its record, and whether it missed the cut.
    bool tile_stopped(std::uint32_t tile, float stop_depth);
    void occlusion_rendered(const Camera& camera, bool took_cut, bool missed);

    /// Projects Gaussian i against every pose of the window into `poses`; returns the mask of
    /// poses where it is visible. Shared by the count and the emit pass.
    std::uint32_t project_window(const Scene& scene, std::size_t i, const Window& window, Projected<T>* poses) const;

    int threads_;
    CpuLimits limits_;
    FramePlanner planner_;
    int tiles_y_ = 0;                                        // the frame's tile rows
    TileRows band_;                                          // keys, split: the rows of this pass
    std::uint64_t split_tasks_ = 0;                          // split: extra sub-tasks of this pass
    std::uint64_t longest_list_ = 0;                         // split: the most pairs one tile list of the band holds
    std::uint32_t split_k_ = 0;                              // k of the current task list
    std::vector<std::pair<std::size_t, std::size_t>> runs_;  // chunk_cull: [begin, end) of Gaussians to preprocess
    std::uint64_t chunks_culled_ = 0;                        // chunk_cull: chunks the key frame skipped
    double window_min_depth_ = 0;                            // preprocess: nearest depth at any pose of the window
    double uncached_bound_px_ = 0;              // preprocess: footprint bound of uncached Gaussians near the image
    std::uint64_t rendered_pairs_ = 0;          // ranges: pairs the tiles' lists hold
    std::vector<Projected<T>> projected_;       // preprocess: at the actual pose; opacity 0 = culled
    std::vector<std::uint32_t> tiles_touched_;  // preprocess: union tile count, 0 = not cached
    std::vector<float> sort_depth_;             // preprocess: depth the keys sort by
    std::vector<std::uint64_t> offsets_;        // keys: exclusive scan of tiles_touched_
    std::vector<std::uint64_t> keys_;           // keys, then sorted
    std::vector<std::uint32_t> values_;         // Gaussian index per key
    std::vector<std::uint64_t> emitted_keys_;   // keys: a key frame's pairs in emission order (rekey)
    std::vector<std::uint32_t> emitted_values_;
    std::vector<std::uint64_t> sort_keys_tmp_;  // sort: ping-pong buffers
    std::vector<std::uint32_t> sort_values_tmp_;
    std::vector<TileRange> ranges_;          // tile ranges
    std::vector<TileTask> tasks_;            // split: tiles, then extra sub-tasks
    std::vector<std::uint32_t> split_slot_;  // split: first partial slot of a split tile, or kNoSlot
    std::vector<Partial<T>> partials_;       // rasterize: per slot, 256 pixels of (R, A)
    OcclusionTracker occlusion_;
    bool record_occlusion_ = false;       // rasterize: this frame records its tile cuts
    OcclusionPyramid occlusion_pyramid_;  // preprocess: the cut's pyramid, when cutting
    std::vector<float> occlusion_cells_;  // preprocess: its cells (empty: no cut this pass)
    std::vector<float> occlusion_last_;   // the last recording frame's tile cuts
    std::vector<float> occlusion_now_;    // rasterize: this frame's
    std::uint64_t occluded_ = 0;          // preprocess: Gaussians the cut left out
    std::uint64_t occluded_pairs_ = 0;    // preprocess: the pairs they would have had
    std::uint64_t occlusion_misses_ = 0;  // rasterize: tiles that did not stop in front of the cut
};

extern template class CpuRenderer<float>;
extern template class CpuRenderer<double>;

}  // namespace catgs
