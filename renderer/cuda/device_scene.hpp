// A scene uploaded to the device once: the Gaussians' arrays and the chunks that chunk_cull
// walks, shared read-only by any number of renderers.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "catgs/scene.hpp"

typedef struct CUstream_st* cudaStream_t;

namespace catgs::cuda {

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

}  // namespace catgs::cuda
