#include "catgs/sharded_renderer.hpp"

#include <algorithm>
#include <chrono>
#include <string>
#include <utility>

#include "catgs/error.hpp"
#include "catgs/parallel.hpp"
#include "catgs/stage.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/split.hpp"

namespace catgs {
namespace {

// Rows per parallel_for chunk of the composite: a 1080p frame in ~270 chunks, enough to
// balance any core count without scheduling costs showing.
constexpr std::size_t kRowGrain = 4;

using Clock = std::chrono::steady_clock;
double elapsed_ms(Clock::time_point since) {
    return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}

}  // namespace

void composite_partials(const std::vector<const PartialImage*>& front_to_back, const std::array<float, 3>& background,
                        ImageF& out, int threads) {
    if (front_to_back.empty()) throw Error("composite_partials: no partial images to composite");
    const PartialImage& first = *front_to_back.front();
    for (std::size_t s = 0; s < front_to_back.size(); ++s) {
        const PartialImage& p = *front_to_back[s];
        const std::size_t pixels = static_cast<std::size_t>(p.width) * static_cast<std::size_t>(p.height);
        if (p.width != first.width || p.height != first.height || p.colour.size() != 3 * pixels ||
            p.transmittance.size() != pixels || p.stopped.size() != pixels)
            throw Error("composite_partials: partial " + std::to_string(s) + " is " + std::to_string(p.width) + "x" +
                        std::to_string(p.height) + " with " + std::to_string(p.transmittance.size()) +
                        " transmittances, expected the first partial's " + std::to_string(first.width) + "x" +
                        std::to_string(first.height) + " with one value per pixel");
    }
    out.resize(first.width, first.height);
    const Vec3<float> back{background[0], background[1], background[2]};
    const std::size_t width = static_cast<std::size_t>(first.width);
    parallel_for(static_cast<std::size_t>(first.height), kRowGrain, threads > 0 ? threads : default_thread_count(),
                 [&](std::size_t row_begin, std::size_t row_end) {
                     for (std::size_t pixel = row_begin * width; pixel < row_end * width; ++pixel) {
                         MergeState<float> m;
                         for (const PartialImage* p : front_to_back) {
                             if (m.done) break;
                             const float* c = &p->colour[3 * pixel];
                             merge_shard_partial(m, Partial<float>{{c[0], c[1], c[2]}, p->transmittance[pixel]},
                                                 p->stopped[pixel] != 0);
                         }
                         PixelAccumulator<float> acc;
                         acc.colour = m.colour;
                         acc.transmittance = m.transmittance;
                         const Vec3<float> v = finish_pixel(acc, back);
                         out.rgb[3 * pixel] = v.x;
                         out.rgb[3 * pixel + 1] = v.y;
                         out.rgb[3 * pixel + 2] = v.z;
                     }
                 });
}

ShardedRenderer::ShardedRenderer(const Scene& scene, int shards, const RendererFactory& make, int threads)
    : ShardedRenderer(scene, plan_shards(scene, shards), make, threads) {}

ShardedRenderer::ShardedRenderer(const Scene& scene, ShardPlan plan, const RendererFactory& make, int threads)
    : plan_(std::move(plan)), threads_(threads > 0 ? threads : default_thread_count()) {
    std::vector<std::uint8_t> held(scene.count(), 0);
    std::size_t total = 0;
    for (int s = 0; s < plan_.shards(); ++s)
        for (std::uint32_t i : plan_.members[static_cast<std::size_t>(s)]) {
            if (i >= held.size() || held[i])
                throw Error("sharded renderer: shard " + std::to_string(s) + " holds Gaussian " + std::to_string(i) +
                            (i >= held.size() ? ", past the scene's " + std::to_string(held.size())
                                              : ", which an earlier shard holds"));
            held[i] = 1;
            ++total;
        }
    if (total != scene.count() || plan_.nodes.empty() || plan_.origin != scene.origin)
        throw Error("sharded renderer: the plan's shards hold " + std::to_string(total) + " of the scene's " +
                    std::to_string(scene.count()) + " Gaussians" +
                    (plan_.origin != scene.origin ? " and its origin is not the scene's" : "") +
                    ": not a plan of this scene");
    for (int s = 0; s < plan_.shards(); ++s) {
        scenes_.push_back(
            std::make_shared<const Scene>(extract_shard(scene, plan_.members[static_cast<std::size_t>(s)])));
        std::unique_ptr<Renderer> renderer = make(s);
        if (!renderer) throw Error("sharded renderer: the factory made no renderer for shard " + std::to_string(s));
        renderer->set_scene(scenes_.back());
        renderers_.push_back(std::move(renderer));
    }
    partials_.resize(renderers_.size());
}

ShardedFrameStats ShardedRenderer::render(const Camera& camera, const RenderOptions& options, ImageF& out,
                                          const FrameHints* hints) {
    return render_frame(camera, options, &out, nullptr, hints);
}

ShardedFrameStats ShardedRenderer::render_rgb8(const Camera& camera, const RenderOptions& options, ImageRGB8& out,
                                               const FrameHints* hints) {
    return render_frame(camera, options, nullptr, &out, hints);
}

ShardedFrameStats ShardedRenderer::render_frame(const Camera& camera, const RenderOptions& options, ImageF* rgb,
                                                ImageRGB8* rgb8, const FrameHints* hints) {
    const auto start = Clock::now();
    ShardedFrameStats stats;
    stats.shards.resize(renderers_.size());
    device_partials_.resize(renderers_.size());
    const int workers = concurrent_ ? static_cast<int>(renderers_.size()) : 1;
    parallel_for(renderers_.size(), 1, workers, [&](std::size_t first, std::size_t last) {
        for (std::size_t s = first; s < last; ++s)
            stats.shards[s] = compositor_
                                  ? renderers_[s]->render_partial_on_device(camera, options, device_partials_[s], hints)
                                  : renderers_[s]->render_partial(camera, options, partials_[s], hints);
    });
    stats.render_ms = elapsed_ms(start);
    const auto merge_start = Clock::now();
    stats.order = shard_visibility_order(plan_, camera);
    if (compositor_) {
        std::vector<DevicePartialImage> ordered;
        for (int s : stats.order) ordered.push_back(device_partials_[static_cast<std::size_t>(s)]);
        const CompositeTimes t = compositor_->composite(ordered, options.background, rgb, rgb8);
        stats.transfer_ms = t.transfer_ms;
        stats.merge_ms = t.merge_ms;
        stats.copy_out_ms = t.copy_out_ms;
        stats.composited_on = compositor_->device();
        stats.peer_direct = t.peer_direct;
        stats.peer_staged = t.peer_staged;
        for (const DevicePartialImage& p : device_partials_) stats.devices.push_back(p.device);
    } else {
        std::vector<const PartialImage*> ordered;
        for (int s : stats.order) ordered.push_back(&partials_[static_cast<std::size_t>(s)]);
        ImageF composite;
        composite_partials(ordered, options.background, rgb ? *rgb : composite, threads_);
        if (rgb8) *rgb8 = to_rgb8(rgb ? *rgb : composite);
        stats.merge_ms = elapsed_ms(merge_start);
    }
    stats.total_ms = elapsed_ms(start);
    return stats;
}

FrameStats combine_shard_stats(const ShardedFrameStats& sharded, bool concurrent) {
    FrameStats s;
    s.key_frame = false;
    s.bands = 0;
    s.window = 0;
    for (const FrameStats& part : sharded.shards) {
        s.visible += part.visible;
        s.pairs += part.pairs;
        s.chunks += part.chunks;
        s.chunks_culled += part.chunks_culled;
        s.arena_bytes += part.arena_bytes;
        s.tasks += part.tasks;
        s.split_tasks += part.split_tasks;
        s.split_k = std::max(s.split_k, part.split_k);
        s.longest_list = std::max(s.longest_list, part.longest_list);
        s.bands = std::max(s.bands, part.bands);
        s.key_frame = s.key_frame || part.key_frame;
        s.window = std::max(s.window, part.window);
        for (Stage stage : kStages)
            s.stage_ms[stage] = concurrent ? std::max(s.stage_ms[stage], part.stage_ms[stage])
                                           : s.stage_ms[stage] + part.stage_ms[stage];
    }
    s.bands = std::max(s.bands, 1);
    s.window = std::max(s.window, 1);
    s.stage_ms[Stage::merge] += sharded.merge_ms;
    s.stage_ms[Stage::copy_out] += sharded.transfer_ms + sharded.copy_out_ms;
    double shards_ms = 0;
    for (const FrameStats& part : sharded.shards)
        shards_ms = concurrent ? std::max(shards_ms, part.total_ms) : shards_ms + part.total_ms;
    s.total_ms = shards_ms + sharded.transfer_ms + sharded.merge_ms + sharded.copy_out_ms;
    std::vector<int> devices = sharded.devices;
    std::sort(devices.begin(), devices.end());
    if (concurrent && std::adjacent_find(devices.begin(), devices.end()) != devices.end())
        s.total_ms = sharded.total_ms;
    return s;
}

void ShardedRenderer::reset_cache() {
    for (auto& r : renderers_) r->reset_cache();
}

std::string ShardedRenderer::name() const {
    return std::to_string(renderers_.size()) + " shards of " + (renderers_.empty() ? "none" : renderers_[0]->name());
}

}  // namespace catgs
