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
// renderers); only their partials travel (4 floats and a byte per pixel each).
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
    double merge_ms = 0;             ///< the composite
    double total_ms = 0;
};

class ShardedRenderer {
public:
    /// Makes the renderer of shard `index` (on the CPU a CPU renderer each; one per GPU later).
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
    /// Renders the shards at once, one thread each, instead of one after another. The image is
    /// the same either way: each shard writes only its own partial.
    void set_concurrent(bool concurrent) { concurrent_ = concurrent; }
    /// Forgets every shard renderer's inter-frame cache.
    void reset_cache();

    const ShardPlan& plan() const { return plan_; }
    /// Shard `index`'s scene (its Gaussians in scene order, the scene's origin).
    const Scene& shard_scene(int index) const { return *scenes_.at(static_cast<std::size_t>(index)); }
    /// The shards' renderers' names, e.g. "cpu/float".
    std::string name() const;

private:
    ShardPlan plan_;
    std::vector<std::shared_ptr<const Scene>> scenes_;
    std::vector<std::unique_ptr<Renderer>> renderers_;
    std::vector<PartialImage> partials_;
    int threads_;
    bool concurrent_ = false;
};

}  // namespace catgs
