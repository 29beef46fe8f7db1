#include "catgs/gpu_queues.hpp"

#include <cstdlib>

namespace catgs {
namespace {

/// Sets `name` to `value` unless the environment gives it a non-empty value (the user's
/// choice wins); returns the value in effect.
std::string default_environment(const char* name, const std::string& value) {
    if (const char* set = std::getenv(name); set != nullptr && *set != '\0') return set;
    setenv(name, value.c_str(), /*overwrite=*/1);  // unset or empty, checked above
    return value;
}

}  // namespace

std::string request_gpu_hardware_queues() {
    return default_environment(kGpuHardwareQueuesVariable, std::to_string(kGpuHardwareQueues));
}

std::string request_eager_kernel_loading() {
    return default_environment(kKernelLoadingVariable, "EAGER");
}

}  // namespace catgs
