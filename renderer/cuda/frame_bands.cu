// A CUDA key frame over the pair budget, drawn in bands of tile rows: the bands planned from
// the frame's pair count, and each band's pairs counted before its keys (keys.cu's count_band).
#include <string>

#include "catgs/error.hpp"
#include "cuda_check.hpp"
#include "keys.cuh"
#include "renderer_state.cuh"

namespace catgs::cuda {

/// Over the pair budget: split the tile rows so each band's pairs fit. The full-frame counts
/// are kept in `visible` so each band recounts only its own rows. A banded frame holds no
/// whole-frame lists, so it cannot start a cached window.
template <typename T>
void CudaRenderer<T>::Impl::plan_bands(Frame<T>& f, std::uint64_t budget) {
    if (f.shared_list)
        throw Error("cuda renderer: exact culling needs " + std::to_string(f.total) +
                    " pairs, more than the pair budget of " + std::to_string(budget));
    f.bands = band_rows(f.total, budget, f.view.tiles_y);
    GaussianBuffers<T>& g = buffers.gaussians;
    CATGS_CUDA_CHECK(cudaMemcpyAsync(g.visible.data(), g.touched.data(), (key_space.slots + 1) * sizeof(std::uint64_t),
                                     cudaMemcpyDeviceToDevice, stream));
}

/// A band's tile counts and their scan; returns the band's pairs, which must fit the budget.
template <typename T>
std::uint64_t CudaRenderer<T>::Impl::count_band(const Frame<T>& f, TileRows rows) {
    events.record(Event::band_count, stream);
    GaussianBuffers<T>& g = buffers.gaussians;
    cuda::count_band(CountBandArgs<T>{key_space, g.projected.data(), g.visible.data(), f.view, f.options->culling, rows,
                                      g.touched.data()},
                     stream);
    const std::uint64_t pairs = scan_ranked_counts(buffers.depth.ranked, true);
    events.record(Event::band_scan, stream);
    events.synchronize(Event::band_scan);
    events.add(Stage::scan, Event::band_count, Event::band_scan);
    if (pairs > pair_budget())
        throw Error("cuda renderer: tile rows " + std::to_string(rows.begin) + ".." + std::to_string(rows.end) +
                    " need " + std::to_string(pairs) + " tile-Gaussian pairs, more than the budget of " +
                    std::to_string(pair_budget()) + "; raise the pair budget or lower the resolution");
    return pairs;
}

template void CudaRenderer<float>::Impl::plan_bands(Frame<float>&, std::uint64_t);
template void CudaRenderer<double>::Impl::plan_bands(Frame<double>&, std::uint64_t);
template std::uint64_t CudaRenderer<float>::Impl::count_band(const Frame<float>&, TileRows);
template std::uint64_t CudaRenderer<double>::Impl::count_band(const Frame<double>&, TileRows);

}  // namespace catgs::cuda
