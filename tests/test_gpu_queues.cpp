// request_gpu_hardware_queues (gpu_queues.hpp): 32 queues unless the environment chose.
#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>
#include <string>

#include "catgs/gpu_queues.hpp"

namespace {

constexpr const char* kVariable = "CUDA_DEVICE_MAX_CONNECTIONS";

// Restores the variable as the test found it.
class SavedVariable {
public:
    SavedVariable() {
        if (const char* v = std::getenv(kVariable)) saved_ = v;
    }
    ~SavedVariable() {
        if (saved_)
            setenv(kVariable, saved_->c_str(), 1);
        else
            unsetenv(kVariable);
    }

private:
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

}  // namespace
