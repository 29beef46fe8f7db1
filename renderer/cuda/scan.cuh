// scan: where each Gaussian's keys go, the CUB exclusive sum of the tile counts of the slots in
// depth order (depth_order, sort.cuh), gathered as the scan reads them.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "device_buffer.hpp"

namespace catgs::cuda {

struct ScanArgs {
    const std::uint64_t* touched;  // per slot: its pairs
    const std::uint32_t* order;    // n slots, front to back: the k-th count is touched[order[k]]
    std::uint64_t* offsets;        // n + 1 entries: offsets[n] is the total
    std::uint64_t n;
    DeviceArray<std::uint8_t>* temp;
    std::uint64_t* host_total;  // pinned; null when the total is known (nothing is read back)
};

/// Returns the pass total (one read-back: synchronises the stream), or 0 without host_total.
std::uint64_t scan(const ScanArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
