// The stress suite's families and property tests, one list run on every backend of the test
// binary (stress_backends(): the CPU in catgs_tests, CUDA in catgs_gpu_tests): the adversarial
// scenes of stress_scenes.hpp through every configuration of the backend, each frame against
// the exact double reference, within the bounds the backend sets per family (test_stress.cpp
// and gpu/test_cuda_stress.cpp say why each is what it is). Seeds are fresh every run
// (test::fresh_seed prints them; CATGS_TEST_SEED replays one). A backend that cannot render
// here (no CUDA device) skips.
#include <gtest/gtest.h>

#include <string>
#include <tuple>

#include "stress_harness.hpp"
#include "stress_scenes.hpp"

namespace catgs {
namespace {

namespace stress = test::stress;

void skip_unless_available(const stress::Backend& backend) {
    if (const std::string why = backend.unavailable(); !why.empty()) GTEST_SKIP() << why;
}

/// One family on one backend: StressFamilies.Family/<backend>_<family>.
class StressFamilies : public ::testing::TestWithParam<std::tuple<std::string, std::size_t>> {
protected:
    const stress::Backend& backend() const { return stress::stress_backend(std::get<0>(GetParam())); }
    const stress::FamilyGenerator& family() const { return stress::family_generators()[std::get<1>(GetParam())]; }
    void SetUp() override { skip_unless_available(backend()); }
};

TEST_P(StressFamilies, Family) {
    stress::run_family(backend(), family());
}

std::vector<std::size_t> family_indices() {
    std::vector<std::size_t> out(stress::family_generators().size());
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = i;
    return out;
}

INSTANTIATE_TEST_SUITE_P(Backends, StressFamilies,
                         ::testing::Combine(::testing::ValuesIn(stress::stress_backend_names()),
                                            ::testing::ValuesIn(family_indices())),
                         [](const auto& instance) {
                             return std::get<0>(instance.param) + "_" +
                                    stress::family_generators()[std::get<1>(instance.param)].test_name;
                         });

/// The property tests and the measurement on one backend: <Test>/<backend>.
class StressProperty : public ::testing::TestWithParam<std::string> {
protected:
    const stress::Backend& backend() const { return stress::stress_backend(GetParam()); }
    void SetUp() override { skip_unless_available(backend()); }
};

TEST_P(StressProperty, RandomAdversarialMixtures) {
    stress::run_cases(backend(), "mixtures", stress::mixture_cases);
}

TEST_P(StressProperty, FieldOfViewFiveToHundredFiftyDegrees) {
    stress::run_cases(backend(), "field of view", stress::field_of_view_cases);
}

TEST_P(StressProperty, TinyAndOddResolutions) {
    stress::run_cases(backend(), "resolutions", stress::resolution_cases);
}

// CATGS_STRESS_SEEDS=N build/tests/catgs_tests (or tests/catgs_gpu_tests on a GPU host)
//   --gtest_also_run_disabled_tests --gtest_filter='*MeasureBounds*' prints the worst error
// over N seeds (default 20) per family and configuration class, and per family and
// configuration: the numbers each backend's bounds were set from.
TEST_P(StressProperty, DISABLED_MeasureBounds) {
    stress::measure_bounds(backend());
}

INSTANTIATE_TEST_SUITE_P(Backends, StressProperty, ::testing::ValuesIn(stress::stress_backend_names()),
                         [](const auto& instance) { return instance.param; });

}  // namespace
}  // namespace catgs
