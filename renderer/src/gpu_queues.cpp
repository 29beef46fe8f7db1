#include "catgs/gpu_queues.hpp"

#include <cstdlib>

namespace catgs {

std::string request_gpu_hardware_queues() {
    if (const char* set = std::getenv(kGpuHardwareQueuesVariable); set != nullptr && *set != '\0') return set;
    const std::string value = std::to_string(kGpuHardwareQueues);
    setenv(kGpuHardwareQueuesVariable, value.c_str(), /*overwrite=*/1);  // unset or empty, checked above
    return value;
}

std::string request_eager_kernel_loading() {
    if (const char* set = std::getenv(kKernelLoadingVariable); set != nullptr && *set != '\0') return set;
    setenv(kKernelLoadingVariable, "EAGER", /*overwrite=*/1);  // unset or empty, checked above
    return "EAGER";
}

}  // namespace catgs
