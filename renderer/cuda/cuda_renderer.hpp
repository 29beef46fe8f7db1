// The CUDA backend: the same stages as the CPU reference (stages/*.hpp are shared), on one
// explicit stream per renderer instance, with grow-only device arenas.
//
//   preprocess  one thread per Gaussian: cull, project, conic, SH colour, tile count
//   scan        CUB exclusive sum of the 64-bit tile counts (the total read back once)
//   emit        one thread per Gaussian writes (tile | depth) keys at its offset
//   sort        CUB radix sort over the used key bits only (32 + bits of the tile count)
//   ranges      per tile [begin, end) in the sorted list
//   split       CaT-GS Algorithm 1: extra sub-tasks of long lists through an atomic task
//               counter, each with a (tile, split index) label
//   rasterize   one 256-thread block per task (16x16 tile or sub-task), batches of Gaussians
//               in shared memory; sub-tasks write partial (R, A)
//   merge       composites the sub-tasks of each split tile front to back
//   copy-out    RGB8 (quantised on the device) and/or float RGB to the host
// A key frame of the CaT-GS cache preprocesses against the window's W poses; cached frames
// re-project the cached Gaussians, re-key and re-sort the cached pairs, and rasterize.
//
// When a frame's pairs exceed the pair budget, it is rendered in horizontal bands of tile
// rows, each with its own count, emit, sort and rasterize; a single tile row over budget is
// an error (catgs::Error), never an out-of-bounds write.
#pragma once

#include <cstdint>
#include <memory>

#include "catgs/cache.hpp"
#include "catgs/camera.hpp"
#include "catgs/image.hpp"
#include "catgs/render_options.hpp"
#include "catgs/scene.hpp"

typedef struct CUstream_st* cudaStream_t;

namespace catgs::cuda {

/// True when a CUDA device is present and usable (tests skip otherwise).
bool device_available(std::string* reason = nullptr);

/// A scene uploaded to the current device once, shareable by several renderers.
class DeviceScene {
public:
    explicit DeviceScene(const Scene& scene, cudaStream_t stream = nullptr);
    ~DeviceScene();
    DeviceScene(const DeviceScene&) = delete;
    DeviceScene& operator=(const DeviceScene&) = delete;

    std::size_t count() const { return count_; }
    std::size_t bytes() const { return bytes_; }
    int sh_degree() const { return sh_degree_; }
    const std::array<double, 3>& origin() const { return origin_; }

    const float* positions() const { return positions_; }
    const float* scales() const { return scales_; }
    const float* rotations() const { return rotations_; }
    const float* opacities() const { return opacities_; }
    const float* sh() const { return sh_; }

    /// The scene's chunks (an unpartitioned scene gets runs of kChunkGaussians that are never
    /// culled), and the list 0..chunk_count()-1 for frames that cull none.
    const Chunk* chunks() const { return chunks_; }
    const std::uint32_t* all_chunks() const { return all_chunks_; }
    std::uint32_t chunk_count() const { return chunk_count_; }
    /// Whether the chunks came from the scene (Scene::chunks) and carry real bounds.
    bool partitioned() const { return partitioned_; }

private:
    void free_all();

    std::size_t count_ = 0, bytes_ = 0;
    int sh_degree_ = 0;
    std::array<double, 3> origin_{};
    float *positions_ = nullptr, *scales_ = nullptr, *rotations_ = nullptr, *opacities_ = nullptr, *sh_ = nullptr;
    Chunk* chunks_ = nullptr;
    std::uint32_t* all_chunks_ = nullptr;
    std::uint32_t chunk_count_ = 0;
    bool partitioned_ = false;
};

struct CudaLimits {
    /// Most tile-Gaussian pairs one pass may hold; 0 = derive from free device memory at
    /// the first frame (a quarter of what is free, at 24 bytes a pair plus sort space).
    std::uint64_t max_pairs = 0;
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

    /// Forgets the inter-frame cache and the pose history (a new stream).
    void reset_cache();

    cudaStream_t stream() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

extern template class CudaRenderer<float>;
extern template class CudaRenderer<double>;

}  // namespace catgs::cuda
