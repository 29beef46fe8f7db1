#include "catgs/progress.hpp"

#include <cstdio>
#include <memory>

namespace catgs {

Progress stderr_progress(bool enabled, std::chrono::milliseconds interval) {
    if (!enabled) return {};
    struct State {
        std::chrono::steady_clock::time_point last{};
        std::string label;
        bool finished = false;  // the 100% line of `label` is printed
    };
    auto state = std::make_shared<State>();
    return [state, interval](double fraction, const std::string& label) {
        auto now = std::chrono::steady_clock::now();
        bool finished = fraction >= 1.0;
        const bool same_step = label == state->label;
        // A loader reports its last chunk (100%) and then that it is done (100% again); a step
        // run again under the same label reports below 100% first, and ends with its own line.
        if (same_step && state->finished) {
            if (finished) return;
            state->finished = false;
        }
        if (!finished && same_step && now - state->last < interval) return;
        state->last = now;
        state->label = label;
        state->finished = finished;
        std::fprintf(stderr, "%s: %3.0f%%\n", label.c_str(), 100.0 * (fraction > 1.0 ? 1.0 : fraction));
    };
}

}  // namespace catgs
