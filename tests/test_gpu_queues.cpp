// request_gpu_hardware_queues and request_eager_kernel_loading (gpu_queues.hpp): the tools'
// driver settings unless the environment chose.
#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>
#include <string>

#include "catgs/gpu_queues.hpp"

namespace {

constexpr const char* kVariable = "CUDA_DEVICE_MAX_CONNECTIONS";

// Restores a variable as the test found it.
class SavedVariable {
public:
    explicit SavedVariable(const char* name = kVariable) : name_(name) {
        if (const char* v = std::getenv(name_)) saved_ = v;
    }
    ~SavedVariable() {
        if (saved_)
            setenv(name_, saved_->c_str(), 1);
        else
            unsetenv(name_);
    }

private:
    const char* name_;
    std::optional<std::string> saved_;
};

TEST(GpuQueues, UnsetBecomesTheDriversMaximum) {
    SavedVariable saved;
    unsetenv(kVariable);
    EXPECT_EQ(catgs::request_gpu_hardware_queues(), "32");
    ASSERT_NE(std::getenv(kVariable), nullptr);
    EXPECT_STREQ(std::getenv(kVariable), "32");
}

TEST(GpuQueues, EmptyCountsAsUnset) {
    SavedVariable saved;
    setenv(kVariable, "", 1);
    EXPECT_EQ(catgs::request_gpu_hardware_queues(), "32");
    EXPECT_STREQ(std::getenv(kVariable), "32");
}

TEST(GpuQueues, TheUsersChoiceIsKept) {
    SavedVariable saved;
    setenv(kVariable, "4", 1);
    EXPECT_EQ(catgs::request_gpu_hardware_queues(), "4");
    EXPECT_STREQ(std::getenv(kVariable), "4");
}

TEST(KernelLoading, UnsetOrEmptyBecomesEager) {
    SavedVariable saved(catgs::kKernelLoadingVariable);
    unsetenv(catgs::kKernelLoadingVariable);
    EXPECT_EQ(catgs::request_eager_kernel_loading(), "EAGER");
    EXPECT_STREQ(std::getenv("CUDA_MODULE_LOADING"), "EAGER");
    setenv(catgs::kKernelLoadingVariable, "", 1);
    EXPECT_EQ(catgs::request_eager_kernel_loading(), "EAGER");
    EXPECT_STREQ(std::getenv("CUDA_MODULE_LOADING"), "EAGER");
}

TEST(KernelLoading, TheUsersChoiceIsKept) {
    SavedVariable saved(catgs::kKernelLoadingVariable);
    setenv(catgs::kKernelLoadingVariable, "LAZY", 1);
    EXPECT_EQ(catgs::request_eager_kernel_loading(), "LAZY");
    EXPECT_STREQ(std::getenv("CUDA_MODULE_LOADING"), "LAZY");
}

}  // namespace
