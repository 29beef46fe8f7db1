#include "catgs/progress.hpp"

#include <cstdio>
#include <memory>

namespace catgs {

Progress stderr_progress(bool enabled, std::chrono::milliseconds interval) {
    if (!enabled) return {};
    struct State {
        std::chrono::steady_clock::time_point last{};
        std::string label;
    };
    auto state = std::make_shared<State>();
    return [state, interval](double fraction, const std::string& label) {
        auto now = std::chrono::steady_clock::now();
        bool finished = fraction >= 1.0;
        if (!finished && label == state->label && now - state->last < interval) return;
        state->last = now;
        state->label = label;
        std::fprintf(stderr, "%s: %3.0f%%\n", label.c_str(), 100.0 * (fraction > 1.0 ? 1.0 : fraction));
    };
}

}  // namespace catgs
