// The scene-format oracle: @playcanvas/splat-transform (tests/oracle/, installed by
// tests/oracle/install-deps.sh), the converter that writes every format catgs reads. Tests
// convert scenes with it into a temporary folder and load the results.
//
// Without it (or without node) an oracle test skips with the reason, unless the environment
// sets CATGS_REQUIRE_ORACLE=1 (CI does): then it fails. CATGS_SPLAT_TRANSFORM overrides the
// executable's path.
#pragma once

#include <gtest/gtest.h>

#include <cstddef>
#include <string>
#include <vector>

#include "catgs/scene.hpp"

namespace catgs::oracle {

/// The splat-transform executable, or "" when absent; `why` then says what is missing.
std::string splat_transform(std::string* why = nullptr);

/// Whether CATGS_REQUIRE_ORACLE=1 asks for a failure instead of a skip.
bool oracle_required();

/// A fresh folder for one test's files under CATGS_TEST_TMP, removed when it goes.
class TempDir {
public:
    explicit TempDir(const std::string& name);
    ~TempDir();
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    std::string path(const std::string& file) const { return dir_ + "/" + file; }

private:
    std::string dir_;
};

struct RunResult {
    int exit_status = -1;  ///< -1 when it could not start or was killed by a signal
    std::string output;    ///< stdout and stderr together
    double seconds = 0;
};

/// Runs splat-transform with `args` (no shell), waiting for it.
RunResult run_splat_transform(const std::vector<std::string>& args);

struct Conversion {
    std::string in, out;
    std::vector<std::string> flags;  ///< splat-transform options, e.g. {"--spz-version", "3"}
};

/// `splat-transform -q -w [flags] in out`; a failure adds a test failure with its output and
/// returns false.
bool convert(const Conversion& conversion);

/// Every conversion, kParallelConversions at a time (each is one single-threaded node process
/// for most of its run); false if any failed (each failure is reported).
bool convert_all(const std::vector<Conversion>& conversions);
inline constexpr std::size_t kParallelConversions = 2;

/// Random Gaussians in a box far from symmetric about every axis (x in [1, 3], y in [-2, -1.5],
/// z in [4, 7]), so that a flipped axis moves every Gaussian and the bounds by metres.
Scene asymmetric_scene(int sh_degree, std::size_t n, unsigned seed);

}  // namespace catgs::oracle

/// At the top of an oracle test: skips (or fails, under CATGS_REQUIRE_ORACLE=1) without
/// splat-transform.
#define CATGS_NEED_ORACLE()                                                                                    \
    do {                                                                                                       \
        std::string catgs_oracle_why;                                                                          \
        if (::catgs::oracle::splat_transform(&catgs_oracle_why).empty()) {                                     \
            if (::catgs::oracle::oracle_required()) FAIL() << catgs_oracle_why << " (CATGS_REQUIRE_ORACLE=1)"; \
            GTEST_SKIP() << catgs_oracle_why;                                                                  \
        }                                                                                                      \
    } while (0)
