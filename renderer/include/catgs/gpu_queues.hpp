// How many hardware work queues the CUDA driver opens for each device context
// (CUDA_DEVICE_MAX_CONNECTIONS, 8 by default, 32 at most).
//
// One CUDA renderer drives up to 17 streams: the frame's own and a copy stream for each of up
// to 16 bands of tile rows (copy_out.cuh), each waiting until its band is drawn. On 8 queues the
// streams share queues, so a band's copy can sit behind another band's wait on the same queue
// and start only when that band is drawn: bands finish out of order, and the image's copy then
// ends later than the drawing allows. On the bench kit's paths (H200, 2026-12-04, 120 frames,
// same binaries) 32 queues cut the exposed copy_out from 0.151 to 0.050 ms (garden survey 4K),
// 0.137 to 0.070 (garden low 4K) and 0.074 to 0.053 (city 1080p), and the median frame by 1.6-3.3%
// on the garden paths; the city's frames were unchanged within 1%.
#pragma once

#include <string>

namespace catgs {

/// The driver's maximum, enough for every stream of a renderer (17) on a queue of its own.
inline constexpr int kGpuHardwareQueues = 32;
/// The environment variable the CUDA driver reads them from.
inline constexpr const char* kGpuHardwareQueuesVariable = "CUDA_DEVICE_MAX_CONNECTIONS";

/// Sets CUDA_DEVICE_MAX_CONNECTIONS to kGpuHardwareQueues unless the environment already sets
/// it, and returns the value in effect. Call it first in main(): the driver reads the variable
/// when it creates a device's context, and setenv is not safe once other threads run.
std::string request_gpu_hardware_queues();

/// The environment variable that tells the CUDA runtime when to load kernels: LAZY (the
/// default since CUDA 12.2) loads each on its first launch, EAGER all at context creation.
inline constexpr const char* kKernelLoadingVariable = "CUDA_MODULE_LOADING";

/// Sets CUDA_MODULE_LOADING to EAGER unless the environment already sets it, and returns the
/// value in effect. For the server: its first session's first frames would otherwise load
/// each kernel they launch (dozens, with the cache's window and split variants) while a viewer
/// waits; eagerly they load before it listens. Call it first in main(), as above.
std::string request_eager_kernel_loading();

}  // namespace catgs
