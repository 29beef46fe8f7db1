// The CPU backend and reference renderer. It runs the same stages as the GPU:
//   preprocess -> tile keys -> sort -> tile ranges -> rasterize
// each a named member with its own buffer, using the host-device math in stages/.
// Precision is a template parameter (float and double are instantiated). Deterministic:
// keys are emitted in Gaussian order from a prefix-sum layout and sorted stably, so equal
// depths in a tile keep Gaussian-index order; the result is independent of thread count.
#pragma once

#include <cstdint>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/image.hpp"
#include "catgs/render_options.hpp"
#include "catgs/scene.hpp"
#include "catgs/stages/project.hpp"

namespace catgs {

/// [begin, end) into the sorted pair arrays. 64-bit: pair counts can pass 2^32.
struct TileRange {
    std::uint64_t begin = 0, end = 0;
};

template <typename T>
class CpuRenderer {
public:
    /// threads <= 0 uses every hardware thread.
    explicit CpuRenderer(int threads = 0);

    /// Renders one frame into `out` (resized to the camera's image). Throws catgs::Error on
    /// invalid intrinsics.
    FrameStats render(const Scene& scene, const Camera& camera, const RenderOptions& options, ImageF& out);

    // Stage outputs of the last frame, for tests and tools.
    const std::vector<Projected<T>>& projected() const { return projected_; }
    const std::vector<std::uint32_t>& tiles_touched() const { return tiles_touched_; }
    const std::vector<std::uint64_t>& sorted_keys() const { return keys_; }
    const std::vector<std::uint32_t>& sorted_values() const { return values_; }
    const std::vector<TileRange>& tile_ranges() const { return ranges_; }

private:
    void preprocess(const Scene& scene, const View<T>& view, Culling culling);
    void emit_keys(const View<T>& view, Culling culling);
    void sort_pairs(const View<T>& view);
    void find_tile_ranges(const View<T>& view, Culling culling);
    void rasterize(const View<T>& view, const RenderOptions& options, ImageF& out);

    int threads_;
    std::vector<Projected<T>> projected_;         // preprocess
    std::vector<std::uint32_t> tiles_touched_;    // preprocess: 0 = culled
    std::vector<std::uint64_t> offsets_;          // keys: exclusive scan of tiles_touched_
    std::vector<std::uint64_t> keys_;             // keys, then sorted
    std::vector<std::uint32_t> values_;           // Gaussian index per key
    std::vector<std::uint64_t> sort_keys_tmp_;    // sort: ping-pong buffers
    std::vector<std::uint32_t> sort_values_tmp_;
    std::vector<TileRange> ranges_;               // tile ranges
};

extern template class CpuRenderer<float>;
extern template class CpuRenderer<double>;

}  // namespace catgs
