#include "latency.hpp"

#include <algorithm>
#include <cmath>

namespace catgs::client {

double LatencyRecorder::percentile(double p) const {
    if (samples_.empty()) return 0;
    std::sort(samples_.begin(), samples_.end());
    const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(samples_.size())));
    return samples_[std::min(samples_.size() - 1, rank == 0 ? 0 : rank - 1)];
}

double LatencyRecorder::max() const {
    return samples_.empty() ? 0 : *std::max_element(samples_.begin(), samples_.end());
}

}  // namespace catgs::client
