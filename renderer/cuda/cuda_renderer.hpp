// The CUDA backend: the same stages as the CPU reference (stages/*.hpp are shared), on one
// explicit stream per renderer instance, with grow-only device arenas.
//
//   chunk_cull  the chunks some pose of a key frame's window may see, flagged and compacted
//               in one kernel
//   preprocess  one thread per Gaussian: cull, project, conic, SH colour, tile count
//   sort        first the slots with pairs in depth order (CUB select, 32-bit CUB radix sort),
//               after keys the pairs by tile id (a stable CUB radix sort of 16 or 32 bits)
//   scan        CUB exclusive sum of the tile counts in depth order
//   keys        each Gaussian's pairs (tile ids and its index) at its offset, in depth order
//   ranges      per tile [begin, end) in the sorted list
//   split       CaT-GS Algorithm 1: extra sub-tasks of long lists through an atomic task
//               counter, each with a (tile, split index) label
//   rasterize   one block per task (16x16 tile or sub-task), 128 threads of two pixels or 256
//               of one (RasterLayout), batches of Gaussians in shared memory; sub-tasks
//               write partial (R, A)
//   merge       composites the sub-tasks of each split tile front to back
//   copy_out    RGB8 (quantised on the device) and/or float RGB to the host, on a second
//               stream, each band of rows as soon as its tiles are drawn
// Each stage is one file (<stage>.cu) with its kernels and a launcher of the same name.
// A key frame of the CaT-GS cache preprocesses against the window's W poses; cached frames
// re-project the cached Gaussians, re-key and re-sort the cached pairs, and rasterize.
//
// When a frame's pairs exceed the pair budget, it is rendered in horizontal bands of tile
// rows, each with its own count, keys, sort and rasterize; a single tile row over budget is
// an error (catgs::Error), never an out-of-bounds write.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "catgs/cache.hpp"
#include "catgs/camera.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/image.hpp"
#include "catgs/partial_image.hpp"
#include "catgs/render_options.hpp"
#include "catgs/scene.hpp"
#include "catgs/stages/split.hpp"
#include "device_scene.hpp"

typedef struct CUstream_st* cudaStream_t;

namespace catgs::cuda {

/// True when a CUDA device is present and usable (tests skip otherwise).
bool device_available(std::string* reason = nullptr);

/// Whether the driver takes stream memory waits (cuStreamWaitValue32), which copy_out needs to
/// copy each band of rows while the rest are drawn; asked once a process.
bool stream_memory_waits_available();

/// How rasterize spreads a tile's 256 pixels over threads. Two pixels a thread share each
/// Gaussian's fetch and walk, and issue fewer instructions; one pixel a thread gives a tile
/// twice the warps, which wins where a frame waits on its longest lists (a grazing view of a
/// ground plane at 1080p). automatic picks from the last frame's longest list
/// (kCriticalListShare, cuda_renderer.cu).
enum class RasterLayout { automatic, pixel_per_thread, two_pixels_per_thread };

/// A frame waits on its longest list when that list holds more than this many times the pairs
/// each resident task gets on average (two pixels a thread): there a tile's 256 threads, one
/// pixel each, finish it sooner than 128. The bench kit's paths (H200, 2026-12-03; longest list
/// x resident tasks / pairs, rasterize median one pixel / two pixels a thread): city 4K 0.66
/// (1.90 / 1.74 ms), garden low 4K 1.37 (1.22 / 1.12), garden survey 4K 1.99 (1.70 / 1.82),
/// city 1080p 2.24 (0.83 / 0.81), garden low 1080p 5.5 (1.44 / 2.10), garden survey 1080p 5.9
/// (2.54 / 3.71).
inline constexpr double kCriticalListShare = 1.7;

/// automatic's choice for a frame like one whose longest tile list held `longest_list` of its
/// `pairs`, on a device that holds `resident_tasks` two-pixel tasks at once.
RasterLayout choose_raster_layout(std::uint64_t longest_list, std::uint64_t pairs, std::uint64_t resident_tasks);

/// A Gaussian with more pairs than this is emitted by its whole warp, a tile row a lane, not by
/// its own thread: a lone thread writing a screen-filling Gaussian's thousands of pairs holds its
/// warp long after the others are done. 64 measured best of 16, 64 and serial on the kit's 4K
/// paths (keys 5-9% faster on city_ring and garden low, even on the garden survey; H100, s26).
inline constexpr std::uint64_t kKeysThreadPairs = 64;

struct CudaLimits {
    /// Most tile-Gaussian pairs one pass may hold; 0 = derive from free device memory at
    /// the first frame (a quarter of what is free, at 24 bytes a pair plus sort space).
    std::uint64_t max_pairs = 0;
    /// Tests force each layout in turn; any other user leaves it automatic.
    RasterLayout raster_layout = RasterLayout::automatic;
    /// copy_out copies each band of rows as soon as its tiles are drawn, while the rest are;
    /// false waits for the whole pass (tests compare the two, and A/B runs measure them).
    bool overlap_copy = true;
    /// kKeysThreadPairs; tests force 0 (every Gaussian by its warp) and the maximum (none).
    std::uint64_t keys_thread_pairs = kKeysThreadPairs;
    /// kHeavyListFactor: the unsplit lists this many times the mean that rasterize starts
    /// first; 0 keeps row order (tests compare the two: the order changes no pixel).
    double heavy_list_factor = kHeavyListFactor;
    /// The heavy lists write an 8-bit image's pixels to host memory (PixelOutputs::heavy_rgb8),
    /// so that no copy band waits for them; false draws them into the device's image (tests
    /// compare the two).
    bool heavy_pixels_to_host = true;
};

/// Host copies of the last frame's stage outputs, laid out as CpuRenderer's accessors are (partials
/// through partial()), for the tests that compare the backends stage by stage.
template <typename T>
struct StageReadback {
    std::vector<std::uint64_t> sorted_keys;    ///< sort: the frame's pairs, by key
    std::vector<std::uint32_t> sorted_values;  ///< sort: the Gaussian of each key
    int tile_key_bytes = 0;                    ///< keys, sort, ranges: bytes of a pair's tile id on the device
    /// ranges: [begin, end) per tile; exact culling has one list, [0, pairs) for every tile.
    std::vector<TileRange> tile_ranges;
    /// split: every tile, then the extra sub-tasks by (tile, index). The device appends them in
    /// the order its atomics hand out; the rasterizer does not depend on it, so they are sorted.
    std::vector<TileTask> tasks;
    std::uint32_t split_k = 0;  ///< split: the k of the task list (0: not split)
    /// split: each tile's first partial slot (in the order the device's atomics handed them
    /// out), or kNoPartials when the tile is not split.
    std::vector<std::uint32_t> split_slot;
    /// split: the lists rasterize starts first (kHeavyListFactor), sorted; empty when none.
    std::vector<std::uint32_t> heavy_tiles;
    /// rasterize: the (R, A) of the split sub-tasks, kTileSize x kTileSize pixels a slot.
    std::vector<Partial<T>> partials;

    static constexpr std::uint32_t kNoPartials = 0xffffffffu;

    /// Like CpuRenderer::partial: the (R, A) that sub-task `index` of split tile `tile` left at
    /// the tile's pixels (row-major within the tile; pixels past the image edge are never
    /// written), or nullptr when the tile was not split or index is past its last sub-task.
    const Partial<T>* partial(std::uint32_t tile, std::uint32_t index) const {
        if (tile >= split_slot.size() || split_slot[tile] == kNoPartials) return nullptr;
        const TileRange& r = tile_ranges[tile];
        if (index > split_count(r.end - r.begin, split_k)) return nullptr;
        return &partials[(static_cast<std::size_t>(split_slot[tile]) + index) * kTileSize * kTileSize];
    }
};

template <typename T>
class CudaRenderer {
public:
    /// stream: the stream every launch and copy uses; nullptr creates a private one.
    explicit CudaRenderer(cudaStream_t stream = nullptr, CudaLimits limits = {});
    ~CudaRenderer();
    CudaRenderer(const CudaRenderer&) = delete;
    CudaRenderer& operator=(const CudaRenderer&) = delete;

    void set_scene(std::shared_ptr<const DeviceScene> scene);
    void set_limits(CudaLimits limits);

    /// Renders one frame; either output may be null. Stage times come from CUDA events.
    /// With options.catgs.cache on, frames inside the window reuse the key frame's lists
    /// (cache.hpp); `hints` may carry the client's flight plan or velocity.
    FrameStats render(const Camera& camera, const RenderOptions& options, ImageRGB8* rgb8, ImageF* rgb_float,
                      const FrameHints* hints = nullptr);
    /// The same frame without its background (partial_image.hpp): colour R, transmittance A
    /// and where the blend stopped, per pixel, so that C = R + A * background. What one shard
    /// of a sharded frame contributes (sharded_renderer.hpp); options.background is ignored.
    FrameStats render_partial(const Camera& camera, const RenderOptions& options, PartialImage& out,
                              const FrameHints* hints = nullptr);
    /// render_partial left in this renderer's pixel buffers on the current device, copied
    /// nowhere: `out` points at them until the next frame (the stream is synchronised, so they
    /// are complete on return). A PartialCompositor reads them (device_compositor.hpp).
    FrameStats render_partial_on_device(const Camera& camera, const RenderOptions& options, DevicePartialImage& out,
                                        const FrameHints* hints = nullptr);

    /// Forgets the inter-frame cache and the pose history (a new stream).
    void reset_cache();

    cudaStream_t stream() const;

    /// Whether copy_out copies each band of rows as soon as it is drawn: CudaLimits::overlap_copy
    /// and stream_memory_waits_available(); otherwise after each pass.
    bool copies_while_drawing() const;

    /// Test-only: copies the last frame's stage outputs to the host (synchronises the stream).
    /// Throws catgs::Error when there was no frame, or when it was rendered in bands (the
    /// device then holds only the last band's lists).
    StageReadback<T> read_back_stages();

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

extern template class CudaRenderer<float>;
extern template class CudaRenderer<double>;

}  // namespace catgs::cuda
