// Progress reporting for long work (loading, generating, benchmarking). Library code calls
// a Progress callback; the CLIs pass one that prints to stderr at a bounded rate.
#pragma once

#include <chrono>
#include <functional>
#include <string>

namespace catgs {

/// Called with the fraction done in [0, 1] and a short label of the current step.
using Progress = std::function<void(double fraction, const std::string& label)>;

/// A Progress that prints "label: 42%" lines to stderr at most every `interval`, plus the
/// final 100% line (once, however often the step reports it). Silent when `enabled` is false.
Progress stderr_progress(bool enabled = true, std::chrono::milliseconds interval = std::chrono::milliseconds(500));

}  // namespace catgs
