// Latency samples and their percentiles. All samples are kept (a 60 s run of 64 streams at
// 60 Hz is 230k doubles): exact percentiles, no histogram error.
#pragma once

#include <vector>

namespace catgs::client {

class LatencyRecorder {
public:
    void add(double ms) { samples_.push_back(ms); }
    void merge(const LatencyRecorder& other) {
        samples_.insert(samples_.end(), other.samples_.begin(), other.samples_.end());
    }
    std::size_t count() const { return samples_.size(); }
    /// p in [0, 1], nearest-rank; 0 when empty.
    double percentile(double p) const;
    double max() const;
    void clear() { samples_.clear(); }

private:
    mutable std::vector<double> samples_;
};

}  // namespace catgs::client
