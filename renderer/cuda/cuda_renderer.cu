// CudaRenderer: the frame's passes in order, over the stage launchers (one file per stage:
// chunk_cull.cu, preprocess.cu, scan.cu, keys.cu, sort.cu, ranges.cu, split.cu, rasterize.cu
// with merge.cuh, copy_out.cu), the frame's buffers (frame_buffers.hpp) and the stage events
// (stage_events.hpp).
#include "cuda_renderer.hpp"

#include <cuda_runtime_api.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "catgs/stages/keys.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "chunk_cull.cuh"
#include "copy_out.cuh"
#include "cuda_check.hpp"
#include "frame_buffers.hpp"
#include "keys.cuh"
#include "preprocess.cuh"
#include "ranges.cuh"
#include "rasterize.cuh"
#include "renderer_state.cuh"
#include "scan.cuh"
#include "sort.cuh"
#include "split.cuh"
#include "stage_events.hpp"

namespace catgs::cuda {
namespace {

/// Bytes of device memory one tile-Gaussian pair needs: key + value, twice (sort buffers),
/// and the emitted key a window keeps.
constexpr std::uint64_t kBytesPerPair = 2 * (sizeof(std::uint64_t) + sizeof(std::uint32_t)) + sizeof(std::uint64_t);
/// Share of free device memory the automatic pair budget may take (the rest stays for the
/// scene, other renderers and CUB's temporary storage).
constexpr double kAutoPairMemoryShare = 0.25;

}  // namespace

bool device_available(std::string* reason) {
    int count = 0;
    const cudaError_t status = cudaGetDeviceCount(&count);
    if (status != cudaSuccess || count == 0) {
        if (reason) *reason = status != cudaSuccess ? cudaGetErrorString(status) : "no CUDA device";
        cudaGetLastError();  // clear the error state for later calls
        return false;
    }
    return true;
}

template <typename T>
std::uint64_t CudaRenderer<T>::Impl::pair_budget() {
    if (limits.max_pairs == 0) {
        std::size_t free_bytes = 0, total_bytes = 0;
        CATGS_CUDA_CHECK(cudaMemGetInfo(&free_bytes, &total_bytes));
        limits.max_pairs = std::max<std::uint64_t>(
            1, static_cast<std::uint64_t>(kAutoPairMemoryShare * static_cast<double>(free_bytes) / kBytesPerPair));
    }
    return limits.max_pairs;
}

template <typename T>
CudaRenderer<T>::CudaRenderer(cudaStream_t stream, CudaLimits limits) : impl_(std::make_unique<Impl>()) {
    impl_->limits = limits;
    if (stream) {
        impl_->stream = stream;
    } else {
        CATGS_CUDA_CHECK(cudaStreamCreateWithFlags(&impl_->stream, cudaStreamNonBlocking));
        impl_->own_stream = true;
    }
    impl_->host.total.reserve(1);
    impl_->host.lists.reserve(1);
    impl_->host.counters.reserve(1);
    impl_->host.views.reserve(kMaxWindow);
    impl_->buffers.window.counters.reserve(1, impl_->stream);
    impl_->buffers.window.views.reserve(kMaxWindow, impl_->stream);
}

template <typename T>
CudaRenderer<T>::~CudaRenderer() {
    if (!impl_) return;
    cudaStreamSynchronize(impl_->stream);
    if (impl_->own_stream) cudaStreamDestroy(impl_->stream);
}

template <typename T>
void CudaRenderer<T>::set_scene(std::shared_ptr<const DeviceScene> scene) {
    impl_->scene = std::move(scene);
    reset_cache();
}

template <typename T>
void CudaRenderer<T>::reset_cache() {
    impl_->planner.reset();
    impl_->occlusion.reset();
}

template <typename T>
void CudaRenderer<T>::set_limits(CudaLimits limits) {
    impl_->limits = limits;
}

template <typename T>
cudaStream_t CudaRenderer<T>::stream() const {
    return impl_->stream;
}

template <typename T>
bool CudaRenderer<T>::copies_while_drawing() const {
    return impl_->copy_waits_on_counts();
}

template <typename T>
FrameStats CudaRenderer<T>::render(const Camera& camera, const RenderOptions& options, ImageRGB8* rgb8,
                                   ImageF* rgb_float, const FrameHints* hints) {
    return impl_->render(camera, options, HostOutputs{rgb8, rgb_float, nullptr, nullptr}, hints);
}

template <typename T>
FrameStats CudaRenderer<T>::render_partial(const Camera& camera, const RenderOptions& options, PartialImage& out,
                                           const FrameHints* hints) {
    return impl_->render(camera, options, HostOutputs{nullptr, nullptr, &out, nullptr}, hints);
}

template <typename T>
FrameStats CudaRenderer<T>::render_partial_on_device(const Camera& camera, const RenderOptions& options,
                                                     DevicePartialImage& out, const FrameHints* hints) {
    return impl_->render(camera, options, HostOutputs{nullptr, nullptr, nullptr, &out}, hints);
}

// Key frame: chunk_cull -> preprocess -> scan -> keys -> sort -> ranges -> split, in bands of
// tile rows when the pairs pass the budget; cached frame: reproject (-> keys -> sort -> ranges
// -> split when it re-sorts); then rasterize -> merge per band, each band's drawn rows copied
// out on the copy stream while the next are drawn.
template <typename T>
FrameStats CudaRenderer<T>::Impl::render(const Camera& camera, const RenderOptions& options, const HostOutputs& out,
                                         const FrameHints* hints) {
    if (!scene) throw Error("cuda renderer: no scene set");
    validate(camera.intrinsics, "camera '" + camera.name + "'");
    Frame<T> f = plan_frame(camera, options, hints);
    // A partial frame stops before the background: with zero, C + T * background is C.
    if (out.any_partial()) f.background = Vec3<T>{T(0), T(0), T(0)};
    plan_occlusion(f, camera, out);
    const Frame<T> planned = f;
    FrameStats stats = draw(f, out);
    const bool missed = f.occlusion && host.counters.data()->tasks.occlusion_misses > 0;
    if (missed) {
        // A tile did not turn opaque in front of the cut: the frame again with every Gaussian,
        // timed as both passes, since both were spent on it.
        const FrameStats cut_pass = stats;
        f = planned;
        f.occlusion = false;
        stats = draw(f, out);
        for (std::size_t s = 0; s < kStageCount; ++s) stats.stage_ms.ms[s] += cut_pass.stage_ms.ms[s];
        stats.total_ms = stats.stage_ms.sum();
        stats.occluded = cut_pass.occluded;
        stats.occluded_pairs = cut_pass.occluded_pairs;
        stats.occlusion_redrawn = true;
    }
    occlusion_rendered(f, camera, missed);
    if (f.plan.key) key_rendered(f, host.counters.data()->frame);
    last = LastFrame{true,
                     f.total,
                     f.tiles,
                     max_extra_tasks(f, f.total),
                     f.shared_list,
                     f.split_used,
                     f.heavy_used,
                     f.bands.size() > 1,
                     host.counters.data()->tasks};
    planner.frame_rendered(f.plan, stats);
    return stats;
}

template <typename T>
FrameStats CudaRenderer<T>::Impl::draw(Frame<T>& f, const HostOutputs& out) {
    begin_frame(f, out);
    if (f.plan.key) {
        chunk_cull(f);
        preprocess(f);
        scan(f);
    } else {
        reproject(f);
        f.total = cached_pairs;
        if (f.plan.resort) {
            rekey(f);
            sort(f, f.total);
            ranges_and_split(f, f.total);
            cached_split = f.split_used;
            cached_heavy = f.heavy_used;
            cached_k_min = f.k_min;
        } else {
            // The key frame's lists and order as they are; the marks keep the stage times at 0.
            for (Event e : {Event::depth_order, Event::scan, Event::keys, Event::sort, Event::ranges, Event::split})
                events.record(e, stream);
        }
        f.split_used = cached_split;
        f.heavy_used = cached_heavy;
        f.k_min = cached_k_min;
    }
    const PixelOutputs device = device_outputs(f, out);
    const Event pass_start = f.bands.size() > 1 ? Event::band_scan : Event::scan;
    for (const TileRows& rows : f.bands) {
        const bool last_band = &rows == &f.bands.back();
        std::uint64_t pairs = f.total;
        if (f.plan.key) {
            if (f.bands.size() > 1) pairs = count_band(f, rows);
            keys(f, rows, pairs);
            sort(f, pairs);
            ranges_and_split(f, pairs);
        }
        rasterize(f, rows, pairs, device);
        // Enqueued before the host waits on this band, so that its copies overlap what follows.
        copy_drawn_rows(f, rows.end, out);
        if (last_band) end_copies();
        // The next band marks its stages again, so a band's times are read once it is drawn;
        // the last band's only after copy_out, so that the host takes each band of the image
        // as its copy ends rather than after the last tile (reading them waits for rasterize).
        if (!last_band) add_pass_times(f, pass_start);
    }
    copy_out(f, out, device);
    add_pass_times(f, pass_start);
    if (f.plan.key)
        add_key_times();
    else
        add_cached_list_times();
    return frame_stats(f);
}

template <typename T>
Frame<T> CudaRenderer<T>::Impl::plan_frame(const Camera& camera, const RenderOptions& options,
                                           const FrameHints* hints) {
    Frame<T> f;
    f.options = &options;
    const CatgsOptions& catgs = options.catgs;
    f.plan = planner.next(camera, catgs, hints);
    f.cache = f.plan.cache(catgs);
    f.view = make_view<T>(camera, scene->origin(), options.near_plane);
    f.scene = scene_view();
    f.tiles = static_cast<std::uint64_t>(f.view.tiles_x) * f.view.tiles_y;
    f.pixels = static_cast<std::size_t>(f.view.width) * f.view.height;
    f.tile_bits = sort_key_tile_bits(f.tiles);
    f.tile_width = tile_key_width(f.tiles);
    f.shared_list = options.culling == Culling::exact;
    const CatgsOptions split = f.plan.split_options(catgs);
    f.splitting = split.split_auto || split.split_k > 0;
    f.split_auto = split.split_auto;
    f.fixed_split_k = split.split_auto ? 0 : split.split_k;
    f.speculative = f.cache == CacheMode::speculative;
    f.near = f.plan.window_near_plane(catgs, options.near_plane);
    f.reproject_actual = f.near != options.near_plane;
    f.guard = f.speculative ? static_cast<T>(catgs.guard_px) : T(0);
    f.guard_translation = f.speculative ? static_cast<T>(catgs.guard_translation) : T(0);
    f.k_min = split.split_auto ? kAutoSplitFloor : std::max<std::uint32_t>(split.split_k, 1);
    f.background = Vec3<T>{static_cast<T>(options.background[0]), static_cast<T>(options.background[1]),
                           static_cast<T>(options.background[2])};
    f.tail = static_cast<T>(catgs.split_tail_transmittance);
    f.bands = {{0, f.view.tiles_y}};
    return f;
}

/// The arenas for this frame's per-Gaussian, per-slot (chunk-compacted), per-tile and per-pixel
/// buffers, the frame counters reset, and the frame's first mark.
template <typename T>
void CudaRenderer<T>::Impl::begin_frame(const Frame<T>& f, const HostOutputs& out) {
    const cudaStream_t s = stream;
    const std::uint64_t max_slots = static_cast<std::uint64_t>(scene->chunk_count()) * kChunkGaussians;
    GaussianBuffers<T>& g = buffers.gaussians;
    g.projected.reserve(scene->count(), s);
    g.visible.reserve(max_slots + 1, s);
    g.touched.reserve(max_slots + 1, s);
    g.sort_depth.reserve(max_slots, s);
    TileBuffers& t = buffers.tiles;
    t.range_begin.reserve(f.tiles, s);
    t.range_end.reserve(f.tiles, s);
    t.split_slot.reserve(f.tiles, s);
    // Grown empty; afterwards each merge leaves its tile's ticket at zero (merge.cuh).
    if (t.merge_tickets.reserve(f.tiles, s))
        CATGS_CUDA_CHECK(cudaMemsetAsync(t.merge_tickets.data(), 0, t.merge_tickets.bytes(), s));
    OcclusionBuffers& o = buffers.occlusion;
    if (f.record_occlusion)
        for (DeviceArray<float>& r : o.recorded) r.reserve(f.tiles, s);  // the last frame's, if any, stay
    if (f.occlusion) o.pyramid.reserve(occlusion_pyramid(f.view.tiles_x, f.view.tiles_y).cells, s);
    PixelBuffers<T>& p = buffers.pixels;
    if (out.rgb8) p.image_rgb8.reserve(3 * f.pixels, s);
    if (out.rgb || out.any_partial()) p.image_float.reserve(3 * f.pixels, s);
    if (out.any_partial()) {
        p.image_transmittance.reserve(f.pixels, s);
        p.image_stopped.reserve(f.pixels, s);
    }

    // A frame that threw after enqueuing copies left waits on the copy streams; they must see
    // their counts before this frame resets them (free when the copies are done: a band's
    // stream ends with its `copied` mark).
    for (cudaEvent_t copied : copy.copied) CATGS_CUDA_CHECK(cudaStreamWaitEvent(s, copied, 0));
    CATGS_CUDA_CHECK(cudaMemsetAsync(frame_counters(), 0, sizeof(FrameCounters), s));
    CATGS_CUDA_CHECK(cudaMemsetAsync(copy.tiles_drawn, 0, kMaxCopyBands * sizeof(unsigned int), s));
    // ranges resets the other task counters per band (and a cached frame keeps its key frame's).
    CATGS_CUDA_CHECK(cudaMemsetAsync(&task_counters()->longest_list, 0, sizeof(TaskCounters::longest_list), s));
    CATGS_CUDA_CHECK(cudaMemsetAsync(&task_counters()->occlusion_misses, 0, sizeof(TaskCounters::occlusion_misses), s));
    const unsigned int far_bits = 0x7f800000u;  // +inf: the atomicMin start of the nearest depth
    CATGS_CUDA_CHECK(
        cudaMemcpyAsync(&frame_counters()->min_depth_bits, &far_bits, sizeof(far_bits), cudaMemcpyHostToDevice, s));
    reserve_copy_out(copy_out_args(f, out), f.pixels);
    // Here, since a pinned allocation synchronises the device; a frame planned in one pass
    // may only leave it unused (device_outputs asks again once its bands are known).
    if (heavy_pixels_to_host(f, out)) {
        host.heavy_rgb8.reserve(heavy_room() * 3 * kTilePixels);
        host.heavy_tiles.reserve(heavy_room());
    }
    copied_copy_bands = 0;
    CATGS_CUDA_CHECK(cudaEventRecord(copy.ready, s));  // the tile counts are 0 from here
    events.clear();
    events.record(Event::start, s);
}

/// The window's poses up to the device (projected with the near plane lowered by the
/// translation guard, footprints dilated by the pixel guard: cache.hpp), then the chunks some
/// pose may see; exact culling keeps them all. Their count stays on the device until the
/// depth order's read-back (scan): preprocess and the select are bounded by it there.
template <typename T>
void CudaRenderer<T>::Impl::chunk_cull(Frame<T>& f) {
    const DeviceScene& sc = *scene;
    const RenderOptions& options = *f.options;
    const int w = static_cast<int>(f.plan.poses.size());
    for (int k = 0; k < w; ++k) host.views.data()[k] = make_view<T>(f.plan.poses[k], sc.origin(), f.near);
    const std::uint32_t chunk_count = sc.chunk_count();
    key_space = ChunkSpace{sc.chunks(), sc.all_chunks(), static_cast<std::uint64_t>(chunk_count) * kChunkGaussians};
    key_chunks_culled = 0;
    if (options.chunk_culling && options.culling != Culling::exact && sc.partitioned() && chunk_count > 0) {
        // The kernel reads the poses from the mapped staging itself and leaves them on the device.
        unsigned long long* live = &frame_counters()->lists.live_chunks;
        cuda::chunk_cull(ChunkCullArgs<T>{sc.chunks(), chunk_count, host.views.data()[0], host.views.device(),
                                          buffers.window.views.data(), w, f.guard, f.guard_translation, &buffers.chunks,
                                          live, &frame_counters()->chunk_cull_blocks},
                         stream);
        key_space.selected = buffers.chunks.selected.data();
        key_space.live_chunks = live;
    } else {
        CATGS_CUDA_CHECK(cudaMemcpyAsync(buffers.window.views.data(), host.views.data(), w * sizeof(View<T>),
                                         cudaMemcpyHostToDevice, stream));
    }
    events.record(Event::chunk_cull, stream);
}

template <typename T>
void CudaRenderer<T>::Impl::preprocess(Frame<T>& f) {
    GaussianBuffers<T>& g = buffers.gaussians;
    OcclusionCut cut;
    if (f.occlusion) {
        OcclusionBuffers& o = buffers.occlusion;
        cut = OcclusionCut{o.pyramid.data(), occlusion_pyramid(f.view.tiles_x, f.view.tiles_y)};
        predict_occlusion(o.last_records(), cut.pyramid, f.occlusion_motion, o.pyramid.data(), stream);
    }
    cuda::preprocess(
        PreprocessArgs<T>{f.scene, key_space, buffers.window.views.data(), static_cast<int>(f.plan.poses.size()),
                          f.view, f.reproject_actual, f.options->culling, f.guard, f.guard_translation,
                          f.cache != CacheMode::off, g.projected.data(), g.touched.data(), g.sort_depth.data(),
                          frame_counters(), cut},
        stream);
    events.record(Event::preprocess, stream);
}

/// The Gaussians in depth order (sort's first part) and the scan of their counts in that
/// order; a frame over the pair budget is planned in bands instead, each emitted in that order.
/// Its times are read once the frame is drawn (add_key_times): the host does not wait here.
template <typename T>
void CudaRenderer<T>::Impl::scan(Frame<T>& f) {
    f.total = order_by_depth(buffers.gaussians.sort_depth.data(), true);
    if (key_space.live_chunks) {
        // The later stages, and the cached frames, walk the kept chunks' slots only.
        const std::uint64_t live = host.lists.data()->live_chunks;
        key_space.slots = live * kChunkGaussians;
        key_space.live_chunks = nullptr;
        key_chunks_culled = scene->chunk_count() - static_cast<std::uint32_t>(live);
    }
    const std::uint64_t budget = pair_budget();
    if (f.total > budget) plan_bands(f, budget);
}

/// A key frame's stages before its bands, once the last band is drawn.
template <typename T>
void CudaRenderer<T>::Impl::add_key_times() {
    events.add(Stage::chunk_cull, Event::start, Event::chunk_cull);
    events.add(Stage::preprocess, Event::chunk_cull, Event::preprocess);
    events.add(Stage::sort, Event::preprocess, Event::depth_order);
    events.add(Stage::scan, Event::depth_order, Event::scan);
}

template <typename T>
void CudaRenderer<T>::Impl::keys(const Frame<T>& f, TileRows rows, std::uint64_t pairs) {
    const cudaStream_t s = stream;
    PairBuffers& p = buffers.pairs;
    p.current = 0;
    p.width = f.tile_width;
    if (pairs > 0) {
        for (int k = 0; k < 2; ++k) {
            p.tiles[k].reserve(pairs, p.width, s);
            p.values[k].reserve(pairs, s);
        }
        GaussianBuffers<T>& g = buffers.gaussians;
        const bool banded = f.bands.size() > 1;
        // Cached frames that re-sort regroup the pairs in emission order (rekey). With the depth
        // order reused they never read them, and the copy (4 bytes a pair, 6M pairs on the city)
        // would only lengthen key frames; a banded frame starts no window.
        const bool keep = f.plan.keep_emission_order && !banded;
        if (keep) g.emission_offset.reserve(key_space.slots, s);
        cuda::keys(KeysArgs<T>{f.scene, key_space, buffers.window.views.data(), static_cast<int>(f.plan.poses.size()),
                               f.options->culling, f.guard, g.projected.data(), g.touched.data(),
                               buffers.depth.ranked_offsets.data(), buffers.depth.order(), buffers.depth.ranked,
                               keep ? g.emission_offset.data() : nullptr, rows, banded, f.reproject_actual, pairs,
                               p.tile_keys(0), p.values[0].data(), limits.keys_thread_pairs},
                   s);
        if (keep) {
            p.emitted_tiles.reserve(pairs, p.width, s);
            CATGS_CUDA_CHECK(cudaMemcpyAsync(p.emitted_keys().data, p.tile_keys(0).data,
                                             pairs * tile_key_bytes(p.width), cudaMemcpyDeviceToDevice, s));
        }
    }
    events.record(Event::keys, s);
}

/// A key frame's band, from its scan (pass_start) to its split, once the band is drawn (no
/// wait between split and rasterize: a wait there left the GPU idle for a round trip through
/// the host, outside every stage's time).
template <typename T>
void CudaRenderer<T>::Impl::add_list_times(Event pass_start) {
    events.synchronize(Event::split);
    events.add(Stage::keys, pass_start, Event::keys);
    events.add(Stage::sort, Event::keys, Event::sort);
    events.add(Stage::ranges, Event::sort, Event::ranges);
    events.add(Stage::split, Event::ranges, Event::split);
}

/// Cached frame: the Gaussians of the key frame's lists projected at the actual pose.
template <typename T>
void CudaRenderer<T>::Impl::reproject(Frame<T>& f) {
    GaussianBuffers<T>& g = buffers.gaussians;
    cuda::reproject(
        ReprojectArgs<T>{f.scene, key_space, f.view, g.touched.data(), g.projected.data(), frame_counters()}, stream);
    events.record(Event::preprocess, stream);
}

/// Cached frame that re-sorts: the key frame's pairs re-keyed by the current depth; tiles the
/// footprint left are parked.
template <typename T>
void CudaRenderer<T>::Impl::rekey(const Frame<T>& f) {
    PairBuffers& p = buffers.pairs;
    GaussianBuffers<T>& g = buffers.gaussians;
    // The key frame's depths are not needed again: sort_depth takes the current ones.
    cuda::rekey_depth(RekeyDepthArgs<T>{key_space, g.touched.data(), g.projected.data(), g.sort_depth.data()}, stream);
    order_by_depth(g.sort_depth.data(), false);
    if (f.total > 0) {
        p.current = 0;
        cuda::rekey(RekeyArgs<T>{key_space, g.touched.data(), buffers.depth.order(), buffers.depth.ranked,
                                 buffers.depth.ranked_offsets.data(), g.emission_offset.data(), p.emitted_keys(),
                                 g.projected.data(), f.view, f.options->culling, p.tile_keys(0), p.values[0].data()},
                    stream);
    }
    events.record(Event::keys, stream);
}

/// Cached frame: its events are read once the last band is drawn, so that nothing waits on
/// the host before rasterize.
template <typename T>
void CudaRenderer<T>::Impl::add_cached_list_times() {
    events.add(Stage::preprocess, Event::start, Event::preprocess);
    events.add(Stage::sort, Event::preprocess, Event::depth_order);
    events.add(Stage::scan, Event::depth_order, Event::scan);
    events.add(Stage::keys, Event::scan, Event::keys);
    events.add(Stage::sort, Event::keys, Event::sort);
    events.add(Stage::ranges, Event::sort, Event::ranges);
    events.add(Stage::split, Event::ranges, Event::split);
}

template <typename T>
void CudaRenderer<T>::Impl::sort(const Frame<T>& f, std::uint64_t pairs) {
    // Key frames emit in depth order; cached frames that re-sort regroup in it.
    cuda::sort(SortArgs{&buffers.pairs, pairs, f.tile_bits}, stream);
    events.record(Event::sort, stream);
}

/// Ranges and the task list over the sorted pairs: split tiles and heavy lists.
template <typename T>
void CudaRenderer<T>::Impl::ranges_and_split(Frame<T>& f, std::uint64_t pairs) {
    const cudaStream_t s = stream;
    TileBuffers& t = buffers.tiles;
    cuda::ranges(RangesArgs{pairs, buffers.pairs.sorted_tiles(), static_cast<std::uint32_t>(f.tiles), f.shared_list,
                            f.fixed_split_k, t.range_begin.data(), t.range_end.data(), task_counters(),
                            &frame_counters()->ranges},
                 s);
    events.record(Event::ranges, s);
    // Exact culling shares one list, which this task layout neither splits nor reorders.
    const bool lists = !f.shared_list && pairs > 0;
    f.split_used = f.splitting && lists;
    const std::uint64_t room = lists ? heavy_room() : 0;
    f.heavy_used = room > 0;
    const std::uint64_t max_extra = max_extra_tasks(f, pairs);
    if (f.split_used) {
        t.labels.reserve(max_extra, s);
        buffers.pixels.partials.reserve((max_extra + std::min<std::uint64_t>(f.tiles, max_extra)) * kTilePixels, s);
    }
    if (f.heavy_used) {
        t.heavy_tiles.reserve(room, s);
        t.runs_first.reserve(f.tiles, s);
    }
    cuda::split(SplitArgs{static_cast<std::uint32_t>(f.tiles), t.range_begin.data(), t.range_end.data(), f.split_used,
                          max_extra, f.split_auto, task_counters(), t.split_slot.data(), t.labels.data(),
                          limits.heavy_list_factor, static_cast<std::uint32_t>(room), t.heavy_tiles.data(),
                          t.runs_first.data()},
                stream);
    events.record(Event::split, s);
}

RasterLayout choose_raster_layout(std::uint64_t longest_list, std::uint64_t pairs, std::uint64_t resident_tasks) {
    if (pairs == 0) return RasterLayout::two_pixels_per_thread;
    const double share =
        static_cast<double>(longest_list) * static_cast<double>(resident_tasks) / static_cast<double>(pairs);
    return share > kCriticalListShare ? RasterLayout::pixel_per_thread : RasterLayout::two_pixels_per_thread;
}

/// The layout of this frame's rasterize, from the last frame's lists (a path's frames change
/// slowly, and this one's are known only once it is drawn).
template <typename T>
RasterLayout CudaRenderer<T>::Impl::raster_layout() {
    if (limits.raster_layout != RasterLayout::automatic) return limits.raster_layout;
    if (!last.rendered) return RasterLayout::two_pixels_per_thread;
    if (two_pixel_tasks == 0) two_pixel_tasks = cuda::resident_tasks<T>(RasterLayout::two_pixels_per_thread);
    return choose_raster_layout(last.tasks.longest_list, last.pairs, two_pixel_tasks);
}

template <typename T>
std::uint64_t CudaRenderer<T>::Impl::heavy_room() {
    if (limits.heavy_list_factor <= 0) return 0;
    if (two_pixel_tasks == 0) two_pixel_tasks = cuda::resident_tasks<T>(RasterLayout::two_pixels_per_thread);
    return two_pixel_tasks;
}

/// The band's tasks: its extra sub-tasks (bounded), its heavy lists (bounded), then its tiles.
template <typename T>
void CudaRenderer<T>::Impl::rasterize(const Frame<T>& f, TileRows rows, std::uint64_t pairs, const PixelOutputs& out) {
    const std::uint32_t first_tile = static_cast<std::uint32_t>(rows.begin) * f.view.tiles_x;
    const std::uint32_t band_tiles = static_cast<std::uint32_t>(rows.end - rows.begin) * f.view.tiles_x;
    const std::uint64_t max_extra = max_extra_tasks(f, pairs);
    const std::uint64_t max_heavy = f.heavy_used ? heavy_room() : 0;
    const TileBuffers& t = buffers.tiles;
    // Not in exact mode, the ground truth: there every Gaussian meets every pixel's own test.
    const TaskGrid grid{
        first_tile, band_tiles, f.split_used,         f.shared_list,      pairs, f.options->culling != Culling::exact,
        max_extra,  max_heavy,  t.heavy_tiles.data(), t.runs_first.data()};
    cuda::rasterize(
        RasterizeArgs<T>{grid, band_tiles + max_extra + max_heavy, raster_layout(), t.range_begin.data(),
                         t.range_end.data(), t.split_slot.data(), t.labels.data(), task_counters(),
                         buffers.pairs.values[buffers.pairs.current].data(), buffers.gaussians.projected.data(), f.view,
                         f.background, f.tail, buffers.pixels.partials.data(), t.merge_tickets.data(), out,
                         f.occlusion ? buffers.occlusion.pyramid.data() : nullptr,
                         f.record_occlusion ? buffers.occlusion.this_frame_records() : nullptr},
        stream);
    events.record(Event::rasterize, stream);
}

/// A band's stage times (rasterize and, on a key frame, its lists), once its copies are
/// enqueued (a banded frame marks them again for the next band).
template <typename T>
void CudaRenderer<T>::Impl::add_pass_times(const Frame<T>& f, Event pass_start) {
    add_raster_times();
    if (f.plan.key) add_list_times(pass_start);
}

/// Waits for the band's rasterize. Its split tiles are merged inside it (merge.cuh), so the
/// CUDA backend reports no time of its own for merge.
template <typename T>
void CudaRenderer<T>::Impl::add_raster_times() {
    events.synchronize(Event::rasterize);
    events.add(Stage::rasterize, Event::split, Event::rasterize);
}

/// The planner learns about a key frame only when its lists cover the whole frame.
template <typename T>
void CudaRenderer<T>::Impl::key_rendered(const Frame<T>& f, const FrameCounters& c) {
    cached_pairs = f.total;
    cached_split = f.split_used;
    cached_k_min = f.k_min;
    if (f.cache == CacheMode::off || f.bands.size() > 1) {
        planner.invalidate();
        return;
    }
    KeyFrameSummary summary;
    float nearest = 0, extent = 0;
    std::memcpy(&nearest, &c.min_depth_bits, sizeof(float));
    std::memcpy(&extent, &c.max_extent_bits, sizeof(float));
    summary.min_depth = std::isfinite(nearest) ? nearest : f.options->near_plane;
    summary.max_extent_px = extent;
    summary.mean_inverse_depth = c.visible ? c.inverse_depth_sum / static_cast<double>(c.visible) : 0.0;
    planner.key_rendered(f.plan, summary);
}

template <typename T>
FrameStats CudaRenderer<T>::Impl::frame_stats(const Frame<T>& f) const {
    const FrameCounters& c = host.counters.data()->frame;
    const TaskCounters& tc = host.counters.data()->tasks;
    FrameStats stats;
    stats.key_frame = f.plan.key;
    stats.window = f.plan.window;
    stats.order_reused = !f.plan.key && !f.plan.resort;
    // Render length: the pairs inside the grid that the tiles' lists hold (ranges counted them;
    // cached frames that re-sort park the rest), else every pair of the list.
    const bool ranged = !f.shared_list && f.total > 0 && f.bands.size() == 1 && (f.plan.key || f.plan.resort);
    stats.pairs = ranged ? tc.rendered_pairs : f.total;
    stats.bands = static_cast<int>(f.bands.size());
    stats.chunks = scene->partitioned() ? scene->chunk_count() : 0;
    stats.chunks_culled = key_chunks_culled;
    stats.visible = c.visible;
    stats.split_k = f.split_used ? tc.split_k : 0;
    stats.split_tasks = f.split_used ? tc.extra_tasks : 0;
    stats.tasks = f.tiles + stats.split_tasks;
    stats.longest_list = tc.longest_list;
    stats.occluded = f.occlusion ? c.occluded : 0;
    stats.occluded_pairs = f.occlusion ? c.occluded_pairs : 0;
    events.write(stats.stage_ms);
    stats.total_ms = stats.stage_ms.sum();
    stats.arena_bytes = buffers.bytes();
    return stats;
}

template class CudaRenderer<float>;
template class CudaRenderer<double>;

}  // namespace catgs::cuda
