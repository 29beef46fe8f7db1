#include "device_scene.hpp"

#include <cuda_runtime_api.h>

#include <algorithm>
#include <limits>
#include <vector>

#include "catgs/constants.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

template <typename V>
V* alloc_copy(const std::vector<V>& host, cudaStream_t stream, std::size_t& bytes) {
    V* d = nullptr;
    const std::size_t n = std::max<std::size_t>(host.size(), 1) * sizeof(V);
    CATGS_CUDA_CHECK(cudaMalloc(&d, n));
    if (!host.empty())
        CATGS_CUDA_CHECK(cudaMemcpyAsync(d, host.data(), host.size() * sizeof(V), cudaMemcpyHostToDevice, stream));
    bytes += n;
    return d;
}

}  // namespace

DeviceScene::DeviceScene(const Scene& scene, cudaStream_t stream)
    : count_(scene.count()), sh_degree_(scene.sh_degree), origin_(scene.origin) {
    scene.check_consistent("scene upload");
    try {
        positions_ = alloc_copy(scene.positions, stream, bytes_);
        scales_ = alloc_copy(scene.scales, stream, bytes_);
        rotations_ = alloc_copy(scene.rotations, stream, bytes_);
        opacities_ = alloc_copy(scene.opacities, stream, bytes_);
        sh_ = alloc_copy(scene.sh, stream, bytes_);
        // An unpartitioned scene: runs of kChunkGaussians with infinite boxes, so that every
        // frame walks one compacted index space and culls nothing.
        partitioned_ = !scene.chunks.empty();
        std::vector<Chunk> chunks = scene.chunks;
        if (!partitioned_) {
            constexpr float kInf = std::numeric_limits<float>::infinity();
            for (std::size_t b = 0; b < count_; b += kChunkGaussians) {
                Chunk c;
                for (int a = 0; a < 3; ++a) {
                    c.lo[a] = -kInf;
                    c.hi[a] = kInf;
                }
                c.radius = kInf;
                c.begin = static_cast<std::uint32_t>(b);
                c.end = static_cast<std::uint32_t>(std::min<std::size_t>(count_, b + kChunkGaussians));
                chunks.push_back(c);
            }
        }
        chunk_count_ = static_cast<std::uint32_t>(chunks.size());
        std::vector<std::uint32_t> ids(chunks.size());
        for (std::size_t c = 0; c < ids.size(); ++c) ids[c] = static_cast<std::uint32_t>(c);
        chunks_ = alloc_copy(chunks, stream, bytes_);
        all_chunks_ = alloc_copy(ids, stream, bytes_);
        CATGS_CUDA_CHECK(cudaStreamSynchronize(stream));
    } catch (...) {
        free_all();
        throw;
    }
}

void DeviceScene::free_all() {
    for (float* p : {positions_, scales_, rotations_, opacities_, sh_}) cudaFree(p);
    cudaFree(chunks_);
    cudaFree(all_chunks_);
}

DeviceScene::~DeviceScene() {
    free_all();
}

}  // namespace catgs::cuda
