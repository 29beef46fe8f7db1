// Grow-only device arrays: the arenas of one renderer instance.
//
// Policy: a buffer grows to max(requested, 1.5 x its capacity), rounded up to 1 MiB, and
// never shrinks; so a stream of frames settles after a few frames and the steady state makes
// no allocation. Memory is freed when the renderer is destroyed. Growth is stream-ordered
// (cudaFreeAsync, cudaMallocAsync on the renderer's stream): the old allocation is freed after
// the kernels queued before it, and, unlike cudaFree, nothing waits for the whole device, so a
// session whose lists grow does not stall the server's other sessions on the same GPU.
#pragma once

#include <cuda_runtime_api.h>

#include <cstddef>
#include <cstdint>

#include "cuda_check.hpp"

namespace catgs::cuda {

inline constexpr std::size_t kArenaGranularity = std::size_t{1} << 20;  // 1 MiB
inline constexpr double kArenaGrowth = 1.5;

class DeviceBytes {
public:
    DeviceBytes() = default;
    DeviceBytes(const DeviceBytes&) = delete;
    DeviceBytes& operator=(const DeviceBytes&) = delete;
    ~DeviceBytes() { release(); }

    /// Ensures room for `bytes`; returns true when it had to allocate.
    bool reserve(std::size_t bytes, cudaStream_t stream) {
        if (bytes <= capacity_) return false;
        std::size_t grown = static_cast<std::size_t>(static_cast<double>(capacity_) * kArenaGrowth);
        std::size_t target = bytes > grown ? bytes : grown;
        target = (target + kArenaGranularity - 1) / kArenaGranularity * kArenaGranularity;
        if (data_) CATGS_CUDA_CHECK(cudaFreeAsync(data_, stream));
        data_ = nullptr;
        capacity_ = 0;
        CATGS_CUDA_CHECK(cudaMallocAsync(&data_, target, stream));
        capacity_ = target;
        ++allocations_;
        return true;
    }
    void release() {
        if (data_) cudaFree(data_);  // not checked: runs in destructors; frees async allocations too
        data_ = nullptr;
        capacity_ = 0;
    }
    void* data() const { return data_; }
    std::size_t capacity() const { return capacity_; }
    std::uint64_t allocations() const { return allocations_; }

private:
    void* data_ = nullptr;
    std::size_t capacity_ = 0;
    std::uint64_t allocations_ = 0;
};

template <typename T>
class DeviceArray {
public:
    bool reserve(std::size_t count, cudaStream_t stream) { return bytes_.reserve(count * sizeof(T), stream); }
    T* data() const { return static_cast<T*>(bytes_.data()); }
    std::size_t capacity() const { return bytes_.capacity() / sizeof(T); }
    std::size_t bytes() const { return bytes_.capacity(); }
    std::uint64_t allocations() const { return bytes_.allocations(); }

private:
    DeviceBytes bytes_;
};

}  // namespace catgs::cuda
