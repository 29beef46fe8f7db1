// The occlusion cut (stages/occlusion.hpp) in CpuRenderer: which frames take it and record
// their tile cuts, as the CUDA backend decides (frame_occlusion.cu); the frame-to-frame rules
// are OcclusionTracker's. preprocess leaves out what lies behind the predicted cut, rasterize
// checks and records each tile's stop, and a frame that missed is drawn again.
#include <cmath>
#include <type_traits>

#include "catgs/cpu_renderer.hpp"

namespace catgs {

// The cut needs a frame whose lists serve only its own pose (a plain key frame: the cache off
// for it, one pose) and whose tiles each stop or not on their own: not split (a sub-task's stop
// says nothing of the tile's), not one shared list (exact culling), not a partial (a shard's
// transmittance goes on past its own Gaussians). Double, the reference precision, never cuts.
// A frame that turns out banded (known after preprocess) drops both in draw.
template <typename T>
void CpuRenderer<T>::plan_occlusion(const Camera& camera, const View<T>& view, const RenderOptions& options,
                                    const FramePlanner::Plan& plan, const FrameOutput& out) {
    const CatgsOptions& catgs = options.catgs;
    record_occlusion_ =
        std::is_same_v<T, float> && catgs.occlusion_cut && options.culling != Culling::exact && out.image != nullptr;
    const CatgsOptions split = plan.split_options(catgs);
    const bool splitting = split.split_k > 0 || split.split_auto;
    const bool eligible =
        record_occlusion_ && plan.key && plan.cache(catgs) == CacheMode::off && plan.poses.size() == 1 && !splitting;
    const std::optional<OcclusionMotion> motion = occlusion_.plan(camera, eligible);
    const std::size_t tiles = static_cast<std::size_t>(view.tiles_x) * static_cast<std::size_t>(view.tiles_y);
    occlusion_cells_.clear();
    occlusion_misses_ = 0;
    // The tracker only plans from a recording at the same intrinsics, hence the same grid.
    if (motion && occlusion_last_.size() == tiles) {
        occlusion_pyramid_ = occlusion_pyramid(view.tiles_x, view.tiles_y);
        occlusion_cells_ = occlusion_cells(occlusion_last_, occlusion_pyramid_, *motion);
    }
    if (record_occlusion_) occlusion_now_.assign(tiles, INFINITY);
}

// The cut pass, and where a tile missed the whole frame again without the cut.
template <typename T>
bool CpuRenderer<T>::draw_frame(const Scene& scene, const Camera& camera, const View<T>& view, const Window& window,
                                const FramePlanner::Plan& plan, const RenderOptions& options, const FrameOutput& out,
                                FrameStats& stats) {
    plan_occlusion(camera, view, options, plan, out);
    bool banded = draw(scene, view, window, plan, options, out, stats);
    const bool took_cut = cutting();  // a pass that turned out banded dropped it
    const bool missed = took_cut && occlusion_misses_ > 0;
    if (took_cut) {
        stats.occluded = occluded_;
        stats.occluded_pairs = occluded_pairs_;
    }
    if (missed) {
        // A tile did not turn opaque in front of the cut: the frame again with every Gaussian,
        // timed as both passes (draw adds its stage times), since both were spent on it.
        occlusion_cells_.clear();
        banded = draw(scene, view, window, plan, options, out, stats);
        stats.occlusion_redrawn = true;
    }
    occlusion_rendered(camera, took_cut, missed);
    return banded;
}

template <typename T>
bool CpuRenderer<T>::occluded_at(const Projected<T>& pose, Culling culling, const View<T>& view) const {
    return occluded(occlusion_pyramid_, occlusion_cells_.data(), tile_rect(pose, culling, view.tiles_x, view.tiles_y),
                    pose.key_depth);
}

// Called once a tile, from rasterize's threads: each writes its own tile's record.
template <typename T>
bool CpuRenderer<T>::tile_stopped(std::uint32_t tile, float stop_depth) {
    if (record_occlusion_) occlusion_now_[tile] = stop_depth;
    return cutting() && !occlusion_holds(occlusion_cells_[tile], stop_depth);  // level 0: one cell a tile
}

template <typename T>
void CpuRenderer<T>::occlusion_rendered(const Camera& camera, bool took_cut, bool missed) {
    occlusion_.rendered(camera, record_occlusion_, took_cut, missed);
    // This frame's records feed the next frame's prediction.
    if (record_occlusion_) occlusion_last_.swap(occlusion_now_);
}

// The class is instantiated in cpu_renderer.cpp; these are its members defined here.
#define CATGS_CPU_OCCLUSION_MEMBERS(T)                                                                            \
    template bool CpuRenderer<T>::draw_frame(const Scene&, const Camera&, const View<T>&, const Window&,          \
                                             const FramePlanner::Plan&, const RenderOptions&, const FrameOutput&, \
                                             FrameStats&);                                                        \
    template void CpuRenderer<T>::plan_occlusion(const Camera&, const View<T>&, const RenderOptions&,             \
                                                 const FramePlanner::Plan&, const FrameOutput&);                  \
    template bool CpuRenderer<T>::occluded_at(const Projected<T>&, Culling, const View<T>&) const;                \
    template bool CpuRenderer<T>::tile_stopped(std::uint32_t, float);                                             \
    template void CpuRenderer<T>::occlusion_rendered(const Camera&, bool, bool);
CATGS_CPU_OCCLUSION_MEMBERS(float)
CATGS_CPU_OCCLUSION_MEMBERS(double)
#undef CATGS_CPU_OCCLUSION_MEMBERS

}  // namespace catgs
