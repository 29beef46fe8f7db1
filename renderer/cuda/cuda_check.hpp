// Every CUDA runtime call goes through CATGS_CUDA_CHECK: a failure becomes a catgs::Error that
// names the call, the source line and CUDA's reason (a catgs::OutOfMemoryError when the device
// cannot allocate). Nothing calls exit().
#pragma once

#include <cuda_runtime_api.h>

#include <string>

#include "catgs/error.hpp"

namespace catgs::cuda {

[[noreturn]] inline void throw_cuda_error(cudaError_t status, const char* call, const char* file, int line) {
    const std::string message = std::string("CUDA error in ") + call + " at " + file + ":" + std::to_string(line) +
                                ": " + cudaGetErrorName(status) + ": " + cudaGetErrorString(status);
    if (status == cudaErrorMemoryAllocation) throw OutOfMemoryError(message);
    throw Error(message);
}

}  // namespace catgs::cuda

#define CATGS_CUDA_CHECK(call)                                                                                       \
    do {                                                                                                             \
        const cudaError_t catgs_status_ = (call);                                                                    \
        if (catgs_status_ != cudaSuccess) ::catgs::cuda::throw_cuda_error(catgs_status_, #call, __FILE__, __LINE__); \
    } while (0)

/// After a kernel launch: reports launch-configuration errors at the launching line, naming
/// the kernel.
#define CATGS_CUDA_CHECK_LAUNCH(name)                                                                                  \
    do {                                                                                                               \
        const cudaError_t catgs_status_ = cudaPeekAtLastError();                                                       \
        if (catgs_status_ != cudaSuccess)                                                                              \
            ::catgs::cuda::throw_cuda_error(catgs_status_, (std::string("the launch of ") + (name)).c_str(), __FILE__, \
                                            __LINE__);                                                                 \
    } while (0)
