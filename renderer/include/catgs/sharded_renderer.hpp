// One frame of a scene shared by several renderers (GPUs): the scene is cut into k spatial
// shards (shard_plan.hpp), each renderer holds one shard's Gaussians and renders its partial
// colour R and transmittance A per pixel (Renderer::render_partial), and the partials are
// composited front to back in the shards' visibility order for the frame's camera:
//   C = C_front + A_front * C_back,  A = A_front * A_back,  pixel = C + A * background,
// the split-tile merge's operation (stages/split.hpp, merge_shard_partial).
//
// The composite equals the unsharded frame, up to float rounding, where every Gaussian a pixel
// blends lies inside its shard's cell (straddles no plane) and blends in its cell's order. Two
// things differ otherwise, both measured in tests/test_shards.cpp and docs/sharding.md: a
// Gaussian that straddles a plane is blended in its mean's shard, so it is ordered against the
// other shards as if it lay wholly on its mean's side; and a shard behind another starts its
// blend at T = 1, so it stops (at T < 1e-4) later than the unsharded blend, which knew the
// front shards' transmittance.
//
// Shards render one after another by default (on the CPU each renderer uses every core), or
// at once, one thread each (set_concurrent: renderers on separate GPUs, or single-threaded CPU
// renderers); only their partials travel (4 floats and a byte per pixel each). By default they
// travel to the host and composite there; with set_compositor (GPU renderers) they stay on
// their GPUs and one GPU gathers and composites them (device_compositor.hpp), so that only
// the finished image crosses PCIe.
#pragma once

#include <array>
#include <functional>
#include <memory>
#include <vector>

#include "catgs/image.hpp"
#include "catgs/partial_image.hpp"
#include "catgs/renderer.hpp"
#include "catgs/shard_plan.hpp"

namespace catgs {

/// Composites `front_to_back` partials (all of one size) into `out`. Throws catgs::Error
/// naming the partial whose size differs from the first's, or when there is none.
void composite_partials(const std::vector<const PartialImage*>& front_to_back, const std::array<float, 3>& background,
                        ImageF& out, int threads = 0);

/// What one sharded frame did.
struct ShardedFrameStats {
    std::vector<FrameStats> shards;  ///< per shard, by shard index
    std::vector<int> order;          ///< the shards front to back for this frame's camera
    double render_ms = 0;            ///< wall time of every shard's partial
    double merge_ms = 0;             ///< the composite (on a GPU: its kernel, CUDA events)
    /// On a GPU (set_compositor): the other devices' partials copied to the compositing one,
    /// and the finished image to the host (CUDA events); 0 on the host.
    double transfer_ms = 0, copy_out_ms = 0;
    int composited_on = -1;  ///< the compositing device; -1: the host
    int peer_direct = 0;     ///< partials copied device to device (peers: NVLink or PCIe)
    int peer_staged = 0;     ///< partials the driver staged through host memory
    /// Per shard, the GPU its partial was drawn on (composited on a GPU); empty on the host.
    std::vector<int> devices;
    double total_ms = 0;  ///< wall time of the whole frame
};

/// A sharded frame as one frame's stats: the shards' counts summed, a key frame if any shard's
/// was, each stage's time summed over the shards when they render in turn or the slowest
/// shard's when they render at once (`concurrent`); the composite's time added to merge, the
/// transfer between GPUs and the final image's copy to copy_out. total_ms is measured as an
/// unsharded frame's is (on a GPU: CUDA events, not the host's wall clock): the shards' totals
/// (summed, or the slowest) plus the composite's. Except where shards rendering at once share
/// a GPU (`sharded.devices`): their event spans then overlap on it, so no sum or maximum of
/// them is the device's time, and total_ms is the frame's wall time (`sharded.total_ms`, which
/// also holds the host's part), an upper bound.
FrameStats combine_shard_stats(const ShardedFrameStats& sharded, bool concurrent);

class ShardedRenderer {
public:
    /// Makes the renderer of shard `index` (a CPU renderer each, or a CUDA renderer on the shard's device).
    using RendererFactory = std::function<std::unique_ptr<Renderer>(int index)>;

    /// Plans `shards` shards of `scene` (plan_shards, whose errors it throws) and gives each
    /// renderer from `make` its shard's scene. `threads` (<= 0: all) runs the composite.
    ShardedRenderer(const Scene& scene, int shards, const RendererFactory& make, int threads = 0);
    /// The same with a plan made beforehand (plan_shards of this scene). Throws catgs::Error
    /// when the plan's shards do not hold each of the scene's Gaussians once.
    ShardedRenderer(const Scene& scene, ShardPlan plan, const RendererFactory& make, int threads = 0);

    /// Renders every shard's partial at `camera` and composites them into `out`.
    ShardedFrameStats render(const Camera& camera, const RenderOptions& options, ImageF& out,
                             const FrameHints* hints = nullptr);
    /// The same in 8 bits (a GPU compositor quantises on the device and copies a quarter of
    /// the bytes; the host composite quantises its float image).
    ShardedFrameStats render_rgb8(const Camera& camera, const RenderOptions& options, ImageRGB8& out,
                                  const FrameHints* hints = nullptr);
    /// Composites on a GPU: each shard's renderer leaves its partial on its device
    /// (Renderer::render_partial_on_device, which its backend must have) and `compositor`
    /// gathers them. Null: back to the host composite.
    void set_compositor(std::unique_ptr<PartialCompositor> compositor) { compositor_ = std::move(compositor); }
    /// The compositing device; -1: the host.
    int compositor_device() const { return compositor_ ? compositor_->device() : -1; }
    /// Renders the shards at once, one thread each, instead of one after another. The image is
    /// the same either way: each shard writes only its own partial.
    void set_concurrent(bool concurrent) { concurrent_ = concurrent; }
    bool concurrent() const { return concurrent_; }
    /// Forgets every shard renderer's inter-frame cache.
    void reset_cache();

    const ShardPlan& plan() const { return plan_; }
    /// Shard `index`'s scene (its Gaussians in scene order, the scene's origin).
    const Scene& shard_scene(int index) const { return *scenes_.at(static_cast<std::size_t>(index)); }
    /// The shards' renderers' names, e.g. "cpu/float".
    std::string name() const;

private:
    ShardedFrameStats render_frame(const Camera& camera, const RenderOptions& options, ImageF* rgb, ImageRGB8* rgb8,
                                   const FrameHints* hints);

    ShardPlan plan_;
    std::vector<std::shared_ptr<const Scene>> scenes_;
    std::vector<std::unique_ptr<Renderer>> renderers_;
    std::vector<PartialImage> partials_;
    std::vector<DevicePartialImage> device_partials_;
    std::unique_ptr<PartialCompositor> compositor_;
    int threads_;
    bool concurrent_ = false;
};

}  // namespace catgs
