#include "catgs/cpu_renderer.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>

#include "catgs/parallel.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/chunks.hpp"
#include "catgs/stages/envelope.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/keys.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"

namespace catgs {
namespace {

// Chunk sizes for parallel_for: large enough that scheduling costs nothing, small enough to
// balance two to sixteen threads on scenes of 10^4 Gaussians and up.
constexpr std::size_t kGaussianGrain = 4096;
constexpr std::size_t kTaskGrain = 4;

// Radix sort digit width: 8 bits keeps the histogram (256 counters) in L1.
constexpr int kRadixBits = 8;

// A tile that is not split has no partial slots.
constexpr std::uint32_t kNoSlot = std::numeric_limits<std::uint32_t>::max();
constexpr std::size_t kTilePixels = static_cast<std::size_t>(kTileSize) * kTileSize;

// Stores one finished pixel: C + T * background in the image, or (C, T) and whether the blend
// stopped in the partial.
template <typename T>
void store_pixel(ImageF* image, PartialImage* partial, int x, int y, Vec3<T> colour, T transmittance, bool stopped,
                 const Vec3<T>& background) {
    const std::size_t pixel =
        static_cast<std::size_t>(y) * static_cast<std::size_t>(image ? image->width : partial->width) +
        static_cast<std::size_t>(x);
    if (image) {
        PixelAccumulator<T> acc;
        acc.colour = colour;
        acc.transmittance = transmittance;
        const Vec3<T> c = finish_pixel(acc, background);
        float* dst = &image->rgb[3 * pixel];
        dst[0] = static_cast<float>(c.x);
        dst[1] = static_cast<float>(c.y);
        dst[2] = static_cast<float>(c.z);
        return;
    }
    float* dst = &partial->colour[3 * pixel];
    dst[0] = static_cast<float>(colour.x);
    dst[1] = static_cast<float>(colour.y);
    dst[2] = static_cast<float>(colour.z);
    partial->transmittance[pixel] = static_cast<float>(transmittance);
    partial->stopped[pixel] = stopped ? 1 : 0;
}

using Clock = std::chrono::steady_clock;
double elapsed_ms(Clock::time_point since) {
    return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}

}  // namespace

template <typename T>
CpuRenderer<T>::CpuRenderer(int threads, CpuLimits limits)
    : threads_(threads > 0 ? threads : default_thread_count()), limits_(limits) {}

template <typename T>
void CpuRenderer<T>::reset_cache() {
    planner_.reset();
    occlusion_.reset();
}

template <typename T>
FrameStats CpuRenderer<T>::render(const Scene& scene, const Camera& camera, const RenderOptions& options, ImageF& out,
                                  const FrameHints* hints) {
    return render_frame(scene, camera, options, FrameOutput{&out, nullptr}, hints);
}

template <typename T>
FrameStats CpuRenderer<T>::render_partial(const Scene& scene, const Camera& camera, const RenderOptions& options,
                                          PartialImage& out, const FrameHints* hints) {
    return render_frame(scene, camera, options, FrameOutput{nullptr, &out}, hints);
}

template <typename T>
FrameStats CpuRenderer<T>::render_frame(const Scene& scene, const Camera& camera, const RenderOptions& options,
                                        const FrameOutput& out, const FrameHints* hints) {
    validate(camera.intrinsics, "camera '" + camera.name + "'");
    scene.check_consistent("cpu renderer: scene");
    const View<T> view = make_view<T>(camera, scene.origin, options.near_plane);
    const FramePlanner::Plan plan = planner_.next(camera, options.catgs, hints);
    FrameStats stats;
    stats.key_frame = plan.key;
    stats.window = plan.window;
    stats.order_reused = !plan.key && !plan.resort;
    const auto start = Clock::now();
    tiles_y_ = view.tiles_y;
    if (out.image)
        out.image->resize(view.width, view.height);
    else
        out.partial->resize(view.width, view.height);
    const Window window = plan.key ? key_window(scene, plan, options) : Window{};
    const bool banded = draw_frame(scene, camera, view, window, plan, options, out, stats);
    if (plan.key) {
        // A banded frame keeps no whole-frame lists to cache.
        if (!banded && plan.cache(options.catgs) != CacheMode::off)
            planner_.key_rendered(plan, summarize(scene, window, options.culling));
        else
            planner_.invalidate();
    }
    stats.total_ms = elapsed_ms(start);
    stats.split_k = split_k_;
    stats.chunks = scene.chunks.size();
    stats.chunks_culled = chunks_culled_;
    for (std::size_t i = 0; i < projected_.size(); ++i)
        stats.visible += tiles_touched_[i] > 0 && projected_[i].opacity > 0;
    planner_.frame_rendered(plan, stats);
    return stats;
}

template <typename T>
bool CpuRenderer<T>::draw(const Scene& scene, const View<T>& view, const Window& window, const FramePlanner::Plan& plan,
                          const RenderOptions& options, const FrameOutput& out, FrameStats& stats) {
    auto t = Clock::now();
    band_ = TileRows{};
    if (plan.key) {
        chunk_cull(scene, window, options.chunk_culling && options.culling != Culling::exact);
        stats.stage_ms[Stage::chunk_cull] += elapsed_ms(t);
        t = Clock::now();
        preprocess(scene, view, window, options.culling);
        if (needs_bands(options.culling)) {
            // The cut and its record are for whole-frame lists: a frame too large for one pass
            // is drawn in bands with every Gaussian.
            record_occlusion_ = false;
            if (cutting()) {
                occlusion_cells_.clear();
                preprocess(scene, view, window, options.culling);
            }
            stats.stage_ms[Stage::preprocess] += elapsed_ms(t);
            render_bands(scene, view, window, options, plan.split_options(options.catgs), out, stats);
            return true;
        }
        stats.stage_ms[Stage::preprocess] += elapsed_ms(t);
        t = Clock::now();
        keys(scene, window, options.culling);
        // Cached frames that re-sort re-key from the pairs in emission (Gaussian) order
        // (rekey); with the depth order reused they never read them.
        if (plan.keep_emission_order) {
            emitted_keys_ = keys_;
            emitted_values_ = values_;
        } else {
            emitted_keys_.clear();
            emitted_values_.clear();
        }
        stats.stage_ms[Stage::keys] += elapsed_ms(t);
        sort_and_schedule(view, options, plan.split_options(options.catgs), stats);
    } else {
        reproject(scene, view);
        stats.stage_ms[Stage::preprocess] += elapsed_ms(t);
        if (plan.resort) {
            t = Clock::now();
            rekey(view, options.culling);
            stats.stage_ms[Stage::keys] += elapsed_ms(t);
            sort_and_schedule(view, options, plan.split_options(options.catgs), stats);
        }
    }
    draw_tasks(view, options, out, stats);
    stats.pairs = rendered_pairs_;
    stats.tasks = tasks_.size();
    stats.split_tasks = split_tasks_;
    stats.longest_list = longest_list_;
    return false;
}

// Rasterize and merge, timed: the pixels of the task list in place (a frame's, or a band's).
template <typename T>
void CpuRenderer<T>::draw_tasks(const View<T>& view, const RenderOptions& options, const FrameOutput& out,
                                FrameStats& stats) {
    auto t = Clock::now();
    rasterize(view, options, out);
    stats.stage_ms[Stage::rasterize] += elapsed_ms(t);
    t = Clock::now();
    merge(view, options, out);
    stats.stage_ms[Stage::merge] += elapsed_ms(t);
}

// Sort, tile ranges and the task list, timed: what key frames and re-sorting cached frames
// run after their keys are in place.
template <typename T>
void CpuRenderer<T>::sort_and_schedule(const View<T>& view, const RenderOptions& options,
                                       const CatgsOptions& split_options, FrameStats& stats) {
    // Accumulated: a banded frame runs these once per band.
    auto t = Clock::now();
    sort(view);
    stats.stage_ms[Stage::sort] += elapsed_ms(t);
    t = Clock::now();
    ranges(view, options.culling);
    stats.stage_ms[Stage::ranges] += elapsed_ms(t);
    t = Clock::now();
    // The plan's (FramePlanner::Plan::split_options): no split where the planner measured that
    // splitting does not pay here, and the k it measured cheapest (SplitChooser).
    split_k_ = split(split_options);
    stats.stage_ms[Stage::split] += elapsed_ms(t);
}

template <typename T>
std::uint32_t CpuRenderer<T>::project_window(const Scene& scene, std::size_t i, const Window& window,
                                             Projected<T>* poses) const {
    const std::size_t sh_stride = scene.sh_floats_per_gaussian();
    const GaussianRef g{&scene.positions[3 * i], &scene.scales[3 * i],     &scene.rotations[4 * i],
                        scene.opacities[i],      &scene.sh[sh_stride * i], scene.sh_degree};
    std::uint32_t valid = 0;
    for (std::size_t k = 0; k < window.views.size(); ++k)
        if (project_geometry(g, window.views[k], poses[k])) valid |= 1u << k;
    return valid;
}

// The runs of Gaussians to preprocess: the chunks that some pose of the window may see (an
// unpartitioned scene: all of it, in runs of the same size).
template <typename T>
void CpuRenderer<T>::chunk_cull(const Scene& scene, const Window& window, bool cull_chunks) {
    const std::size_t n = scene.count();
    const int w = static_cast<int>(window.views.size());
    runs_.clear();
    chunks_culled_ = 0;
    if (scene.chunks.empty()) {
        for (std::size_t b = 0; b < n; b += kChunkGaussians)
            runs_.push_back({b, std::min<std::size_t>(n, b + kChunkGaussians)});
    } else {
        for (const Chunk& c : scene.chunks) {
            if (!cull_chunks || chunk_in_window(c, window.views.data(), w, window.guard, window.guard_translation))
                runs_.push_back({c.begin, c.end});
            else
                ++chunks_culled_;
        }
    }
}

// Project every Gaussian of the runs at the actual pose (for rasterizing) and count the tiles
// of the union of its footprints over the window (0 = not in any list).
template <typename T>
void CpuRenderer<T>::preprocess(const Scene& scene, const View<T>& actual, const Window& window, Culling culling) {
    const std::size_t n = scene.count();
    const int w = static_cast<int>(window.views.size());
    projected_.resize(n);
    tiles_touched_.assign(n, 0);
    sort_depth_.resize(n);
    const std::size_t sh_stride = scene.sh_floats_per_gaussian();
    window_min_depth_ = std::numeric_limits<double>::infinity();
    uncached_bound_px_ = 0;
    occluded_ = occluded_pairs_ = 0;
    const bool cut = cutting() && w == 1;  // the cut is planned for single poses only
    std::mutex min_mutex;
    parallel_for(
        runs_.size(), kGaussianGrain / kChunkGaussians, threads_, [&](std::size_t first_run, std::size_t last_run) {
            Projected<T> poses[kMaxWindow];
            double local_min = std::numeric_limits<double>::infinity(), local_bound = 0;
            std::uint64_t local_occluded = 0, local_occluded_pairs = 0;
            for (std::size_t run = first_run; run < last_run; ++run) {
                for (std::size_t i = runs_[run].first; i < runs_[run].second; ++i) {
                    const std::uint32_t valid = project_window(scene, i, window, poses);
                    tiles_touched_[i] = for_each_window_tile<kMaxWindow>(poses, valid, w, culling, window.guard,
                                                                         window.views[0], [](std::uint32_t) {});
                    if (cut && tiles_touched_[i] > 0 && occluded_at(poses[0], culling, window.views[0])) {
                        // Behind every tile it touches: no list holds it, and it needs no colour.
                        ++local_occluded;
                        local_occluded_pairs += tiles_touched_[i];
                        tiles_touched_[i] = 0;
                        continue;
                    }
                    if (tiles_touched_[i] == 0) {
                        // In no list, but close enough to enter the image within the envelope (a near
                        // Gaussian just outside it moves f dt / z; a needle just outside opens up into
                        // it): the planner must bound its motion too, or a cached frame misses it. At
                        // every pose of the window: a cached frame may lie near any of them.
                        const float* sc = &scene.scales[3 * i];
                        const T max_scale =
                            static_cast<T>(std::max({std::fabs(sc[0]), std::fabs(sc[1]), std::fabs(sc[2])}));
                        if (window.guard > T(0) && culling != Culling::exact) {
                            T nearest = std::numeric_limits<T>::infinity(), bound = T(0);
                            summarize_uncached<kMaxWindow>(poses, valid, w, window.views.data(),
                                                           &scene.positions[3 * i], culling, window.guard,
                                                           window.guard_translation, max_scale, nearest, bound);
                            local_min = std::min(local_min, static_cast<double>(nearest));
                            local_bound = std::max(local_bound, static_cast<double>(bound));
                        }
                        continue;
                    }
                    // Keys sort by the depth at the key pose, for every listed Gaussian, also one
                    // behind the camera there that a later pose brings into view: a cached frame
                    // reuses this order while the camera has only translated, which shifts every
                    // depth taken at one pose alike (depths taken at different poses, such as
                    // each Gaussian's first visible one, do not keep their order). The envelope
                    // needs the nearest depth at any pose.
                    sort_depth_[i] =
                        (valid & 1u) ? poses[0].key_depth : key_depth_at(window.views[0], &scene.positions[3 * i]);
                    for (int k = 0; k < w; ++k)
                        if (valid >> k & 1u) local_min = std::min(local_min, static_cast<double>(poses[k].depth));
                    // At the actual pose: pose 0's geometry unless the window lowered the near plane;
                    // the SH colour only now that the Gaussian is known to touch a tile.
                    const GaussianRef g{&scene.positions[3 * i], &scene.scales[3 * i],     &scene.rotations[4 * i],
                                        scene.opacities[i],      &scene.sh[sh_stride * i], scene.sh_degree};
                    bool at_actual = (valid & 1u) != 0;
                    if (window.near_plane != actual.near_plane)
                        at_actual = project_geometry(g, actual, projected_[i]);
                    else
                        projected_[i] = poses[0];
                    if (at_actual)
                        shade_gaussian(g, actual, projected_[i]);
                    else
                        projected_[i].opacity = T(0);
                }
            }
            std::lock_guard lock(min_mutex);
            window_min_depth_ = std::min(window_min_depth_, local_min);
            uncached_bound_px_ = std::max(uncached_bound_px_, local_bound);
            occluded_ += local_occluded;
            occluded_pairs_ += local_occluded_pairs;
        });
}

// Cached frame: only the Gaussians in the cached lists are projected again, at the actual
// pose: means, conics, colours. Culled ones get opacity 0, which the blend skips.
template <typename T>
void CpuRenderer<T>::reproject(const Scene& scene, const View<T>& actual) {
    const std::size_t n = tiles_touched_.size();
    const std::size_t sh_stride = scene.sh_floats_per_gaussian();
    parallel_for(n, kGaussianGrain, threads_, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            if (tiles_touched_[i] == 0) continue;
            const GaussianRef g{&scene.positions[3 * i], &scene.scales[3 * i],     &scene.rotations[4 * i],
                                scene.opacities[i],      &scene.sh[sh_stride * i], scene.sh_degree};
            if (!project_gaussian(g, actual, projected_[i])) projected_[i].opacity = T(0);
        }
    });
}

// Exclusive scan of the tile counts (64-bit; the scan stage, folded in here), then emit
// (tile | depth) keys in Gaussian order through the same predicate the count used. A band
// counts its own rows first (the same predicate, restricted to them).
template <typename T>
void CpuRenderer<T>::keys(const Scene& scene, const Window& window, Culling culling) {
    const std::size_t n = tiles_touched_.size();
    const int w = static_cast<int>(window.views.size());
    offsets_.resize(n);
    if (banded()) {
        parallel_for(n, kGaussianGrain, threads_, [&](std::size_t begin, std::size_t end) {
            Projected<T> poses[kMaxWindow];
            for (std::size_t i = begin; i < end; ++i) {
                offsets_[i] = 0;
                if (tiles_touched_[i] == 0) continue;
                const std::uint32_t valid = project_window(scene, i, window, poses);
                offsets_[i] = for_each_window_tile<kMaxWindow>(
                    poses, valid, w, culling, window.guard, window.views[0], [](std::uint32_t) {}, band_);
            }
        });
    } else {
        for (std::size_t i = 0; i < n; ++i) offsets_[i] = tiles_touched_[i];
    }
    std::uint64_t total = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint64_t count = offsets_[i];
        offsets_[i] = total;
        total += count;
    }
    keys_.resize(total);
    values_.resize(total);
    parallel_for(n, kGaussianGrain, threads_, [&](std::size_t begin, std::size_t end) {
        Projected<T> poses[kMaxWindow];
        for (std::size_t i = begin; i < end; ++i) {
            if (tiles_touched_[i] == 0) continue;
            std::uint64_t slot = offsets_[i];
            const std::uint32_t valid = project_window(scene, i, window, poses);
            for_each_window_tile<kMaxWindow>(
                poses, valid, w, culling, window.guard, window.views[0],
                [&](std::uint32_t tile) {
                    keys_[slot] = make_sort_key(tile, sort_depth_[i]);
                    values_[slot] = static_cast<std::uint32_t>(i);
                    ++slot;
                },
                band_);
        }
    });
}

// Cached frame, re-sort: every pair the key frame emitted keeps its tile if the Gaussian's
// footprint at the current pose still touches it (the single-frame predicate), with the
// Gaussian's current depth; the others, and Gaussians culled at this pose, are parked past
// the grid (they sort last and no range covers them). Re-keying from the emission order
// makes the stable sort order equal depths by Gaussian index. The lists become exactly the
// per-frame lists, in exact depth order, without preprocessing the scene again.
template <typename T>
void CpuRenderer<T>::rekey(const View<T>& view, Culling culling) {
    keys_.resize(emitted_keys_.size());
    values_ = emitted_values_;
    parallel_for(keys_.size(), kGaussianGrain * 16, threads_, [&](std::size_t begin, std::size_t end) {
        // A Gaussian's pairs are consecutive, row by row: one RekeyedTiles serves them all.
        for (std::size_t j = begin; j < end;) {
            const std::uint32_t gaussian = values_[j];
            const Projected<T>& p = projected_[gaussian];
            RekeyedTiles<T> rekeyed(p, culling, view);
            for (; j < end && values_[j] == gaussian; ++j)
                keys_[j] = make_sort_key(rekeyed(key_tile(emitted_keys_[j])), p.key_depth);
        }
    });
}

// Stable LSD radix sort over the used key bits only (sort_key_tile_bits), as CUB does on the
// GPU. Stability keeps Gaussian order for ties.
template <typename T>
void CpuRenderer<T>::sort(const View<T>& view) {
    const std::size_t n = keys_.size();
    const int tile_bits = sort_key_tile_bits(static_cast<std::uint64_t>(view.tiles_x) * view.tiles_y);
    const int passes = (kSortKeyDepthBits + tile_bits + kRadixBits - 1) / kRadixBits;
    sort_keys_tmp_.resize(n);
    sort_values_tmp_.resize(n);
    constexpr std::size_t kBuckets = std::size_t{1} << kRadixBits;
    for (int pass = 0; pass < passes; ++pass) {
        const int shift = pass * kRadixBits;
        std::uint64_t count[kBuckets] = {};
        for (std::size_t i = 0; i < n; ++i) ++count[(keys_[i] >> shift) & (kBuckets - 1)];
        std::uint64_t sum = 0;
        for (auto& c : count) {
            std::uint64_t here = c;
            c = sum;
            sum += here;
        }
        for (std::size_t i = 0; i < n; ++i) {
            const std::uint64_t slot = count[(keys_[i] >> shift) & (kBuckets - 1)]++;
            sort_keys_tmp_[slot] = keys_[i];
            sort_values_tmp_[slot] = values_[i];
        }
        keys_.swap(sort_keys_tmp_);
        values_.swap(sort_values_tmp_);
    }
}

// [begin, end) of every tile in the sorted pairs. Exact mode has one list, which every tile
// shares.
template <typename T>
void CpuRenderer<T>::ranges(const View<T>& view, Culling culling) {
    const std::size_t tiles = static_cast<std::size_t>(view.tiles_x) * view.tiles_y;
    ranges_.assign(tiles, TileRange{});
    const std::size_t n = keys_.size();
    if (culling == Culling::exact) {
        std::size_t kept = 0;  // cached frames park unneeded pairs past the grid, at the end
        while (kept < n && key_tile(keys_[kept]) < tiles) ++kept;
        for (auto& r : ranges_) r = {0, kept};
        rendered_pairs_ = kept;
        return;
    }
    rendered_pairs_ = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint32_t tile = key_tile(keys_[i]);
        if (tile >= tiles) continue;  // parked by rekey
        if (i == 0 || key_tile(keys_[i - 1]) != tile) ranges_[tile].begin = i;
        if (i + 1 == n || key_tile(keys_[i + 1]) != tile) ranges_[tile].end = i + 1;
        ++rendered_pairs_;
    }
}

// CaT-GS Algorithm 1: one task per tile, then the extra sub-tasks of every tile longer than k
// appended with their (tile, split index) label; split tiles get partial slots. Returns the k
// used (0: no splitting).
template <typename T>
std::uint32_t CpuRenderer<T>::split(const CatgsOptions& options) {
    std::uint32_t k = options.split_k;
    if (options.split_auto) {
        std::uint64_t nonempty = 0, pairs = 0;
        for (const TileRange& r : ranges_) {
            nonempty += r.end > r.begin;
            pairs += r.end - r.begin;
        }
        const double mean = nonempty ? static_cast<double>(pairs) / static_cast<double>(nonempty) : 0.0;
        k = std::max(kAutoSplitFloor, static_cast<std::uint32_t>(std::ceil(kAutoSplitFactor * mean)));
    }
    // The tiles of the band (all of them unless the frame is banded), then the extra sub-tasks.
    const std::uint32_t tiles = static_cast<std::uint32_t>(ranges_.size());
    const std::uint32_t tiles_x = tiles_y_ > 0 ? tiles / static_cast<std::uint32_t>(tiles_y_) : tiles;
    const std::uint32_t first = static_cast<std::uint32_t>(std::max(band_.begin, 0)) * tiles_x;
    const std::uint32_t last = static_cast<std::uint32_t>(
        std::min<std::uint64_t>(tiles, std::uint64_t{tiles_x} * std::min(band_.end, tiles_y_)));
    tasks_.clear();
    split_slot_.assign(tiles, kNoSlot);
    for (std::uint32_t t = first; t < last; ++t) tasks_.push_back({t, 0});
    std::uint32_t slots = 0;
    split_tasks_ = 0;
    longest_list_ = 0;
    for (std::uint32_t t = first; t < last; ++t) {
        const std::uint64_t size = ranges_[t].end - ranges_[t].begin;
        longest_list_ = std::max(longest_list_, size);
        const std::uint32_t splits = split_count(size, k);
        if (splits == 0) continue;
        split_slot_[t] = slots;
        slots += splits + 1;
        split_tasks_ += splits;
        for (std::uint32_t i = 1; i <= splits; ++i) tasks_.push_back({t, i});
    }
    partials_.resize(static_cast<std::size_t>(slots) * kTilePixels);
    return k;
}

// Every task blends its slice of its tile's list from T = 1. A tile that is not
// split writes its pixels; a sub-task of a split tile writes (R, A) to its partial slot. A
// tile also notes the sort depth by which all its pixels had stopped, for the occlusion cut.
template <typename T>
void CpuRenderer<T>::rasterize(const View<T>& view, const RenderOptions& options, const FrameOutput& out) {
    const Vec3<T> background{static_cast<T>(options.background[0]), static_cast<T>(options.background[1]),
                             static_cast<T>(options.background[2])};
    const T tail_threshold = static_cast<T>(options.catgs.split_tail_transmittance);
    std::atomic<std::uint64_t> misses{0};
    parallel_for(tasks_.size(), kTaskGrain, threads_, [&](std::size_t begin, std::size_t end) {
        std::vector<const Projected<T>*> list;
        std::uint64_t local_misses = 0;
        for (std::size_t task = begin; task < end; ++task) {
            const TileTask tt = tasks_[task];
            const TileRange range = ranges_[tt.tile];
            std::uint64_t first = range.begin, last = range.end;
            if (split_slot_[tt.tile] != kNoSlot) subtask_range(range.begin, range.end, split_k_, tt.index, first, last);
            list.clear();
            for (std::uint64_t j = first; j < last; ++j) list.push_back(&projected_[values_[j]]);
            const T threshold = tt.index > 0 ? tail_threshold : static_cast<T>(kMinTransmittance);
            const int x0 = static_cast<int>(tt.tile % view.tiles_x) * kTileSize;
            const int y0 = static_cast<int>(tt.tile / view.tiles_x) * kTileSize;
            const int x1 = std::min(x0 + kTileSize, view.width), y1 = std::min(y0 + kTileSize, view.height);
            float stop_depth = -INFINITY;
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) {
                    PixelAccumulator<T> acc;
                    const T px = static_cast<T>(x) + T(0.5), py = static_cast<T>(y) + T(0.5);
                    for (const Projected<T>* g : list)
                        if (blend_gaussian(acc, g->mean, g->conic, g->opacity, g->colour, px, py, threshold)) {
                            stop_depth = std::max(stop_depth, g->key_depth);
                            break;
                        }
                    if (!acc.done) stop_depth = INFINITY;
                    if (split_slot_[tt.tile] == kNoSlot) {
                        store_pixel(out.image, out.partial, x, y, acc.colour, acc.transmittance, acc.done, background);
                    } else {
                        const std::size_t slot = split_slot_[tt.tile] + tt.index;
                        partials_[slot * kTilePixels + static_cast<std::size_t>((y - y0) * kTileSize + (x - x0))] =
                            Partial<T>{acc.colour, acc.transmittance};
                    }
                }
            // A sub-task's stop says nothing of its tile's.
            if (tt.index == 0)
                local_misses += tile_stopped(tt.tile, split_slot_[tt.tile] == kNoSlot ? stop_depth : INFINITY);
        }
        misses += local_misses;
    });
    occlusion_misses_ = misses;
}

// Composite each split tile's sub-tasks front to back.
template <typename T>
void CpuRenderer<T>::merge(const View<T>& view, const RenderOptions& options, const FrameOutput& out) {
    const Vec3<T> background{static_cast<T>(options.background[0]), static_cast<T>(options.background[1]),
                             static_cast<T>(options.background[2])};
    const std::size_t tiles = ranges_.size();
    parallel_for(tiles, kTaskGrain, threads_, [&](std::size_t begin, std::size_t end) {
        for (std::size_t tile = begin; tile < end; ++tile) {
            if (split_slot_[tile] == kNoSlot) continue;
            const std::uint32_t parts = split_count(ranges_[tile].end - ranges_[tile].begin, split_k_) + 1;
            const int x0 = static_cast<int>(tile % view.tiles_x) * kTileSize;
            const int y0 = static_cast<int>(tile / view.tiles_x) * kTileSize;
            const int x1 = std::min(x0 + kTileSize, view.width), y1 = std::min(y0 + kTileSize, view.height);
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) {
                    MergeState<T> m;
                    const std::size_t pixel = static_cast<std::size_t>((y - y0) * kTileSize + (x - x0));
                    for (std::uint32_t i = 0; i < parts && !m.done; ++i)
                        merge_partial(m, partials_[(split_slot_[tile] + i) * kTilePixels + pixel]);
                    store_pixel(out.image, out.partial, x, y, m.colour, m.transmittance, m.done, background);
                }
        }
    });
}

template <typename T>
const Partial<T>* CpuRenderer<T>::partial(std::uint32_t tile, std::uint32_t index) const {
    if (tile >= split_slot_.size() || split_slot_[tile] == kNoSlot) return nullptr;
    if (index > split_count(ranges_[tile].end - ranges_[tile].begin, split_k_)) return nullptr;
    return &partials_[(split_slot_[tile] + index) * kTilePixels];
}

template class CpuRenderer<float>;
template class CpuRenderer<double>;

}  // namespace catgs
