#include "catgs/gpu_queues.hpp"

#include <cstdlib>

namespace catgs {

std::string request_gpu_hardware_queues() {
    constexpr const char* kVariable = "CUDA_DEVICE_MAX_CONNECTIONS";
    if (const char* set = std::getenv(kVariable); set != nullptr && *set != '\0') return set;
    const std::string value = std::to_string(kGpuHardwareQueues);
    setenv(kVariable, value.c_str(), /*overwrite=*/1);  // unset or empty, checked above
    return value;
}

}  // namespace catgs
