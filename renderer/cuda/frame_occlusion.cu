// Whether a CUDA frame takes the occlusion cut (stages/occlusion.hpp) and records its tile
// cuts; the frame-to-frame rules are OcclusionTracker's, the prediction, cut and check run in
// occlusion.cu, preprocess.cu and rasterize.cu.
#include <type_traits>

#include "renderer_state.cuh"

namespace catgs::cuda {

// The cut needs a frame whose lists serve only its own pose (a plain key frame: the cache off
// for it, one pose) and whose tiles each stop or not on their own: not split (a sub-task's stop
// says nothing of the tile's), not one shared list (exact culling), not a partial (a shard's
// transmittance goes on past its own Gaussians). Double, the reference precision, never cuts.
template <typename T>
void CudaRenderer<T>::Impl::plan_occlusion(Frame<T>& f, const Camera& now, const HostOutputs& out) {
    f.record_occlusion =
        std::is_same_v<T, float> && f.options->catgs.occlusion_cut && !f.shared_list && !out.any_partial();
    const bool eligible =
        f.record_occlusion && f.plan.key && f.cache == CacheMode::off && f.plan.poses.size() == 1 && !f.splitting;
    const std::optional<OcclusionMotion> motion = occlusion.plan(now, eligible);
    f.occlusion = motion.has_value();
    if (motion) f.occlusion_motion = *motion;
}

template <typename T>
void CudaRenderer<T>::Impl::occlusion_rendered(const Frame<T>& f, const Camera& camera, bool missed) {
    occlusion.rendered(camera, f.record_occlusion, f.occlusion, missed);
    // This frame's records feed the next frame's prediction.
    if (f.record_occlusion) buffers.occlusion.current = 1 - buffers.occlusion.current;
}

template void CudaRenderer<float>::Impl::plan_occlusion(Frame<float>&, const Camera&, const HostOutputs&);
template void CudaRenderer<double>::Impl::plan_occlusion(Frame<double>&, const Camera&, const HostOutputs&);
template void CudaRenderer<float>::Impl::occlusion_rendered(const Frame<float>&, const Camera&, bool);
template void CudaRenderer<double>::Impl::occlusion_rendered(const Frame<double>&, const Camera&, bool);

}  // namespace catgs::cuda
