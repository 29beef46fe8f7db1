// Every CUDA runtime call goes through CATGS_CUDA_CHECK: a failure becomes a catgs::Error that
// names the call, the source line and CUDA's reason. Nothing calls exit().
#pragma once

#include <cuda_runtime_api.h>

#include <string>

#include "catgs/error.hpp"

namespace catgs::cuda {

[[noreturn]] inline void throw_cuda_error(cudaError_t status, const char* call, const char* file, int line) {
    throw Error(std::string("CUDA error in ") + call + " at " + file + ":" + std::to_string(line) + ": " +
                cudaGetErrorName(status) + ": " + cudaGetErrorString(status));
}

}  // namespace catgs::cuda

#define CATGS_CUDA_CHECK(call)                                                                      \
    do {                                                                                            \
        const cudaError_t catgs_status_ = (call);                                                   \
        if (catgs_status_ != cudaSuccess) ::catgs::cuda::throw_cuda_error(catgs_status_, #call, __FILE__, __LINE__); \
    } while (0)

/// After a kernel launch: reports launch-configuration errors at the launching line.
#define CATGS_CUDA_CHECK_LAUNCH(name) CATGS_CUDA_CHECK(cudaPeekAtLastError())
