// scan: the CUB exclusive sum of the 64-bit tile counts, where each Gaussian's keys go.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "device_buffer.hpp"

namespace catgs::cuda {

struct ScanArgs {
    std::uint64_t* counts;   // n + 1 entries, the last 0 (not const: CUB is instantiated as before)
    std::uint64_t* offsets;  // n + 1 entries: offsets[n] is the total
    std::uint64_t n;
    DeviceArray<std::uint8_t>* temp;
    std::uint64_t* host_total;  // pinned; null when the total is known (nothing is read back)
};

/// Returns the pass total (one read-back: synchronises the stream), or 0 without host_total.
std::uint64_t scan(const ScanArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
