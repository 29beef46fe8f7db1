// The state of one CudaRenderer (its Impl) and of the frame being rendered (Frame), shared
// by cuda_renderer.cu, which runs the passes, and the files that hold some of them:
// stage_readback.cu, frame_occlusion.cu and frame_bands.cu.
#pragma once

#include <cuda_runtime_api.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "catgs/cache.hpp"
#include "catgs/host_copier.hpp"
#include "catgs/occlusion_tracker.hpp"
#include "catgs/render_options.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "copy_out.cuh"
#include "cuda_renderer.hpp"
#include "frame_buffers.hpp"
#include "kernel_common.cuh"
#include "scan.cuh"
#include "sort.cuh"
#include "stage_events.hpp"

namespace catgs::cuda {

/// What the passes of one frame share: its plan and what follows from it.
template <typename T>
struct Frame {
    const RenderOptions* options = nullptr;
    FramePlanner::Plan plan;
    CacheMode cache = CacheMode::off;  // the mode this frame renders with (plan.cache)
    View<T> view;                      // the actual pose
    DeviceSceneView scene{};
    std::uint64_t tiles = 0;
    std::size_t pixels = 0;
    int tile_bits = 0;
    TileKeyWidth tile_width = TileKeyWidth::bits32;
    bool shared_list = false;  // exact culling: one list serves every tile
    bool splitting = false;
    bool split_auto = false;          // k from the frame's lists (splitting only)
    std::uint32_t fixed_split_k = 0;  // the plan's k (FramePlanner::Plan::split_options); 0: auto or none
    bool speculative = false;
    /// The window's near plane (FramePlanner::Plan::window_near_plane); when lowered, the actual
    /// pose is projected again with the real one.
    double near = 0;
    bool reproject_actual = false;
    T guard = T(0), guard_translation = T(0);
    /// The extra-task and slot bounds of the task list (k is at least the floor when automatic).
    std::uint64_t k_min = 1;
    Vec3<T> background{};
    T tail = T(0);

    std::uint64_t total = 0;  // the frame's pairs
    std::vector<TileRows> bands;
    bool split_used = false;
    bool heavy_used = false;  // the split stage listed the heavy lists (runs_first)

    /// The occlusion cut (stages/occlusion.hpp): applied to this frame's lists (a plain
    /// single-pose frame after a recorded one), and whether rasterize records the tile cuts.
    bool occlusion = false;
    OcclusionMotion occlusion_motion{};
    bool record_occlusion = false;
};

/// What read_back_stages needs to know of the frame whose lists the device holds.
struct LastFrame {
    bool rendered = false;
    std::uint64_t pairs = 0, tiles = 0, max_extra = 0;
    bool shared_list = false, split_used = false, heavy_used = false, banded = false;
    TaskCounters tasks{};
};

/// The host images one frame fills; any may be null, not all.
struct HostOutputs {
    ImageRGB8* rgb8 = nullptr;
    ImageF* rgb = nullptr;
    PartialImage* partial = nullptr;
    /// A partial left in the pixel buffers for a compositor (render_partial_on_device): drawn
    /// as `partial` is, copied nowhere.
    DevicePartialImage* device_partial = nullptr;

    bool any_partial() const { return partial || device_partial; }
};

/// Threads beside the caller that take a large image out of the pinned staging (copy_out): one
/// thread copies ~12 GB/s, below the link's ~40 GB/s, so at 4K the host held the image ~1.5 ms
/// after the GPU's last copy; with three helpers the caller's median wait on garden low 4K fell
/// from 4.3-4.5 to 2.9-3.0 ms (GPU frame 2.02 ms; H100, session 38). Images below
/// kSpreadCopyBytes are copied by the caller alone: at 1080p (6.2 MB) the spread copy moved the
/// median by -0.2 to +0.1 ms and raised the mean by up to 0.4 ms on one path (the helpers'
/// wake-ups), so it starts at 16 MiB: a 4K frame (24.9 MB) is spread, 2560x1440 (11 MB) not.
inline constexpr int kHostCopyHelpers = 3;
inline constexpr std::size_t kSpreadCopyBytes = std::size_t{16} << 20;

template <typename T>
struct CudaRenderer<T>::Impl {
    cudaStream_t stream = nullptr;
    bool own_stream = false;
    CudaLimits limits;
    std::shared_ptr<const DeviceScene> scene;
    StageEvents events;
    FramePlanner planner;
    // The planner plans cached frames only after key_rendered, for lists the device holds.
    std::uint64_t cached_pairs = 0;  // pairs of the cached lists
    bool cached_split = false;       // the cached task list has split tiles
    bool cached_heavy = false;       // and its heavy lists
    /// The k bound its extra sub-tasks were counted with (Frame::k_min): a cached frame's own
    /// plan does not choose k (SplitChooser), and the key frame's may have moved along the
    /// ladder, so rasterize must launch the extra tasks of the list's k, or split tiles whose
    /// sub-tasks never run are never merged (and their copy band never completes).
    std::uint64_t cached_k_min = 1;
    ChunkSpace key_space{};  // the key frame's compacted index space (cached frames reuse it)
    std::uint64_t key_chunks_culled = 0;
    FrameBuffers<T> buffers;
    HostStaging<T> host;
    HostCopier host_copier{kHostCopyHelpers};  // copy_out's takes of large images
    LastFrame last;                            // read_back_stages
    OcclusionTracker occlusion;
    CopyStreams copy;
    bool copy_waits = stream_memory_waits_available();  // false once the driver refused one
    int copied_copy_bands = 0;                          // of this frame, enqueued on the copy stream

    bool copy_waits_on_counts() const { return limits.overlap_copy && copy_waits; }
    /// Tile rows a copy band holds: the image's rows over kMaxCopyBands, at least one.
    static int rows_per_copy_band(const Frame<T>& f) {
        return std::max(1, (f.view.tiles_y + kMaxCopyBands - 1) / kMaxCopyBands);
    }

    FrameCounters* frame_counters() { return &buffers.window.counters.data()->frame; }
    TaskCounters* task_counters() { return &buffers.window.counters.data()->tasks; }

    /// Most pairs one pass may hold (CudaLimits::max_pairs, derived at the first frame when 0).
    std::uint64_t pair_budget();

    FrameStats render(const Camera& camera, const RenderOptions& options, const HostOutputs& out,
                      const FrameHints* hints);
    Frame<T> plan_frame(const Camera& camera, const RenderOptions& options, const FrameHints* hints);
    /// Whether the frame takes the occlusion cut and records its tile cuts (frame_occlusion.cu).
    void plan_occlusion(Frame<T>& f, const Camera& camera, const HostOutputs& out);
    /// One pass of the whole frame into `out`: lists, pixels and copies; returns its stats.
    FrameStats draw(Frame<T>& f, const HostOutputs& out);
    /// After a frame: the next one's cut from this one's records, or the back-off after a miss.
    void occlusion_rendered(const Frame<T>& f, const Camera& camera, bool missed);
    void begin_frame(const Frame<T>& f, const HostOutputs& out);
    /// Where this frame's kernels write, for `out`.
    PixelOutputs device_outputs(const Frame<T>& f, const HostOutputs& out);
    /// Whether the heavy lists write their pixels to host memory (PixelOutputs::heavy_rgb8):
    /// an 8-bit image alone, copied while it is drawn, in one pass (the list is per pass).
    bool heavy_pixels_to_host(const Frame<T>& f, const HostOutputs& out) {
        return limits.heavy_pixels_to_host && copy_waits_on_counts() && out.rgb8 && !out.rgb && !out.any_partial() &&
               f.bands.size() == 1 && heavy_room() > 0;
    }
    CopyOutArgs copy_out_args(const Frame<T>& f, const HostOutputs& out);
    // A key frame's lists.
    void chunk_cull(Frame<T>& f);
    void preprocess(Frame<T>& f);
    void scan(Frame<T>& f);
    void plan_bands(Frame<T>& f, std::uint64_t budget);
    std::uint64_t count_band(const Frame<T>& f, TileRows rows);
    void keys(const Frame<T>& f, TileRows rows, std::uint64_t pairs);
    void add_list_times(Event pass_start);
    void add_key_times();
    // A cached frame's lists.
    void reproject(Frame<T>& f);
    void rekey(const Frame<T>& f);
    void add_cached_list_times();
    // Both.
    void sort(const Frame<T>& f, std::uint64_t pairs);
    /// Sets f.split_used and f.heavy_used.
    void ranges_and_split(Frame<T>& f, std::uint64_t pairs);
    void rasterize(const Frame<T>& f, TileRows rows, std::uint64_t pairs, const PixelOutputs& out);
    void add_pass_times(const Frame<T>& f, Event pass_start);
    void add_raster_times();
    void copy_drawn_rows(const Frame<T>& f, int rows_end, const HostOutputs& out);
    void end_copies();
    /// `device`: where the kernels wrote (device_outputs).
    void copy_out(const Frame<T>& f, const HostOutputs& out, const PixelOutputs& device);
    void take_heavy_pixels(const Frame<T>& f, ImageRGB8& image);
    void key_rendered(const Frame<T>& f, const FrameCounters& c);
    FrameStats frame_stats(const Frame<T>& f) const;

    std::uint64_t two_pixel_tasks = 0;  // resident_tasks, asked once
    RasterLayout raster_layout();
    std::uint64_t max_extra_tasks(const Frame<T>& f, std::uint64_t pairs) const {
        return f.split_used ? pairs / f.k_min + 1 : 0;
    }
    /// Room for the heavy lists: what the GPU holds at once in the wider layout, so that all
    /// start in rasterize's first wave; 0 when CudaLimits::heavy_list_factor turns them off.
    std::uint64_t heavy_room();
    /// Depth order: the scan of the counts depth_order ranked; reads the total back only when
    /// `read_total` (cached frames know theirs).
    std::uint64_t scan_ranked_counts(std::uint64_t slots, bool read_total) {
        DepthOrderBuffers& o = buffers.depth;
        return cuda::scan(ScanArgs{buffers.gaussians.touched.data(), o.order(), o.ranked_offsets.data(), slots,
                                   &buffers.gaussians.scan_temp, read_total ? host.total.data() : nullptr},
                          stream);
    }
    /// The slots with pairs in depth order by `depth` (sort.cuh), then their offsets. A key
    /// frame selects the slots with pairs and reads back their count with the pair total that
    /// preprocess summed (one read-back, before the sort: the scan then runs on unread); a
    /// cached frame re-sorts that same selection (`select` false: nothing is read back, and
    /// the total it returns is 0: the frame knows its own).
    std::uint64_t order_by_depth(const float* depth, bool select) {
        ListTotals* totals = &frame_counters()->lists;
        const std::uint64_t ranked =
            cuda::depth_order(DepthOrderArgs{key_space, buffers.gaussians.touched.data(), depth, &buffers.depth,
                                             !select, select ? totals : nullptr, select ? host.lists.data() : nullptr},
                              stream);
        events.record(Event::depth_order, stream);
        scan_ranked_counts(ranked, false);
        events.record(Event::scan, stream);
        return select ? host.lists.data()->pairs : 0;
    }
    DeviceSceneView scene_view() const {
        const DeviceScene& s = *scene;
        return DeviceSceneView{s.positions(), s.scales(),    s.rotations(), s.opacities(),
                               s.sh(),        s.sh_degree(), s.count()};
    }
};

}  // namespace catgs::cuda
