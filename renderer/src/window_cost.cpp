#include "catgs/window_cost.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "catgs/error.hpp"
#include "catgs/render_options.hpp"

namespace catgs {
namespace {

// Weight of a new sample in an estimate. Plain and cached frames are sampled at every such
// frame, so about the last five count, which smooths the frame-to-frame noise of GPU times
// (p90 1.3x the median on plain city frames); key frames and window lengths are sampled once
// a window, so the last two count and a change of content is followed within a few windows.
constexpr double kFrameWeight = 0.2;
constexpr double kWindowWeight = 0.5;
// With nothing known, the first window has at most this W: a window that cannot pay must not
// cost much to find out, and key(W) for larger W is then extrapolated from it and plain. At 4 it
// was the slowest frame of every kit path (2-2.3x a plain frame, H200, 2026-12-02); a key frame
// of 2 poses costs 1.2-1.5x.
constexpr int kLearningWindow = 2;
// A sample above this many times the estimate counts as this much: one stall (an allocation,
// another process on the GPU) must not turn the model off windows or plain frames for long.
constexpr double kSpikeClip = 3.0;
// A measured window that served this many frames fewer than its W was ended by the envelope.
constexpr double kEarlyEndSlack = 0.5;

// frame_work's weights: nanoseconds per unit on the H200, from the plain pipeline's stage
// medians on city_ring at 4K (shared/bench-kit README): preprocess 1.71 ms over its 6M
// Gaussians, emit 1.71, sort 1.46 and rasterize 2.02 ms over its pairs (about 29M, the issue's
// largest count), copy 0.46 ms over 8.3M pixels. Relative weights are what matters: they put
// a W = 4 key frame at about 1.9x a plain frame and a cached frame at about 0.55x, as measured.
constexpr double kProjectionNs = 0.28;
constexpr double kEmitNs = 0.06;
constexpr double kSortNs = 0.05;
constexpr double kBlendNs = 0.07;
constexpr double kPixelNs = 0.055;
constexpr double kNsPerMs = 1e6;

}  // namespace

const char* window_cost_name(WindowCost cost) {
    switch (cost) {
        case WindowCost::off:
            return "off";
        case WindowCost::time:
            return "time";
        case WindowCost::work:
            return "work";
    }
    return "?";
}

WindowCost parse_window_cost(const std::string& name) {
    if (name == "off") return WindowCost::off;
    if (name == "time") return WindowCost::time;
    if (name == "work") return WindowCost::work;
    throw Error("unknown window cost '" + name + "' (expected off, time or work)");
}

double frame_work(const FrameStats& s) {
    const double pixels = static_cast<double>(s.tasks - std::min(s.tasks, s.split_tasks)) * kTileSize * kTileSize;
    const double pairs = static_cast<double>(s.pairs), visible = static_cast<double>(s.visible);
    double ns = pixels * kPixelNs;
    if (s.key_frame) {
        // Every Gaussian of the live chunks is projected at each pose of the window (a scene
        // without chunks: the visible ones, all that FrameStats counts), the visible ones
        // shaded; the union of the footprints is emitted, sorted and blended.
        const double live = s.chunks > 0 ? static_cast<double>(s.chunks - std::min(s.chunks, s.chunks_culled)) *
                                               static_cast<double>(kChunkGaussians)
                                         : visible;
        ns += (live * std::max(s.window, 1) + visible) * kProjectionNs + pairs * (kEmitNs + kSortNs + kBlendNs);
    } else {
        // Only the cached Gaussians are projected again; a re-sorting frame re-keys and sorts.
        ns += visible * kProjectionNs + pairs * (s.order_reused ? kBlendNs : kEmitNs + kSortNs + kBlendNs);
    }
    return ns / kNsPerMs;
}

double frame_cost(const FrameStats& stats, WindowCost cost) {
    switch (cost) {
        case WindowCost::time:
            return stats.total_ms;
        case WindowCost::work:
            return frame_work(stats);
        case WindowCost::off:
            break;
    }
    return 0;
}

void CostEstimate::add(double sample, std::uint64_t frame, double weight) {
    if (samples_ == 0)
        value_ = sample;
    else
        value_ += weight * (std::min(sample, kSpikeClip * value_) - value_);
    ++samples_;
    last_frame_ = frame;
}

void WindowCostModel::spend(double cost) {
    if (probing_) {
        probe_cost_ += cost;
        ++probe_frames_;
    }
    // The budget banks at most kProbeBankFrames frames' share, so a long cheap stretch cannot
    // pay for a burst of probes in the next one.
    const double bank = kProbeShare * kProbeBankFrames * plain_.value();
    probe_budget_ = std::min(probe_budget_ + kProbeShare * cost, std::max(bank, kProbeShare * cost));
    ++frame_;
}

void WindowCostModel::plain_rendered(double cost) {
    plain_.add(cost, frame_, kFrameWeight);
    spend(cost);
}

void WindowCostModel::key_rendered(int window, double cost) {
    learn(key_, window, cost);
    spend(cost);
}

void WindowCostModel::cached_rendered(int window, double cost) {
    learn(cached_, window, cost);
    spend(cost);
}

void WindowCostModel::learn(std::array<CostEstimate, kMaxWindow + 1>& estimates, int window, double cost) {
    CostEstimate& e = estimates[std::clamp(window, 1, kMaxWindow)];
    const double before = e.value();
    const bool first = !e.known();
    e.add(cost, frame_, &estimates == &key_ ? kWindowWeight : kFrameWeight);
    if (first || !(before > 0)) return;
    const double factor = e.value() / before;
    for (CostEstimate& other : estimates)
        if (&other != &e && other.known()) other.scale(factor);
}

void WindowCostModel::window_ended(int window, int frames) {
    const int w = std::clamp(window, 1, kMaxWindow);
    served_[w].add(std::clamp(frames, 1, w), frame_, kWindowWeight);
}

std::optional<double> WindowCostModel::plain_cost() const {
    if (!plain_.known()) return std::nullopt;
    return plain_.value();
}

std::optional<double> WindowCostModel::key_cost(int window) const {
    const int w = std::clamp(window, 1, kMaxWindow);
    if (key_[w].known()) return key_[w].value();
    // The measured points around w; plain stands for W = 1 (one pose, no guard band).
    auto point = [&](int v) -> std::optional<double> {
        if (key_[v].known()) return key_[v].value();
        if (v == 1 && plain_.known()) return plain_.value();
        return std::nullopt;
    };
    int below = 0, below2 = 0, above = 0;
    for (int v = w - 1; v >= 1; --v) {
        if (!point(v)) continue;
        if (below == 0) {
            below = v;
        } else {
            below2 = v;
            break;
        }
    }
    for (int v = w + 1; v <= kMaxWindow && above == 0; ++v)
        if (point(v)) above = v;
    if (below && above)
        return *point(below) + (*point(above) - *point(below)) * (w - below) / static_cast<double>(above - below);
    // Key frames cost more with more poses: a smaller W costs at most the smallest measured one.
    if (above) return point(above);
    if (below2) {
        const double slope = std::max(0.0, (*point(below) - *point(below2)) / static_cast<double>(below - below2));
        return *point(below) + slope * (w - below);
    }
    // One point: a key frame alone carries over; plain alone says nothing about windows.
    if (below > 1) return point(below);
    return std::nullopt;
}

std::optional<double> WindowCostModel::cached_cost(int window) const {
    const int w = std::clamp(window, 1, kMaxWindow);
    for (int d = 0; d < kMaxWindow; ++d) {
        if (w - d >= 1 && cached_[w - d].known()) return cached_[w - d].value();
        if (w + d <= kMaxWindow && cached_[w + d].known()) return cached_[w + d].value();
    }
    return plain_cost();
}

double WindowCostModel::served(int window) const {
    const int w = std::clamp(window, 1, kMaxWindow);
    if (served_[w].known()) return std::clamp(served_[w].value(), 1.0, static_cast<double>(w));
    double bound = w;
    for (int v = 1; v <= kMaxWindow; ++v)
        if (served_[v].known() && served_[v].value() < v - kEarlyEndSlack) bound = std::min(bound, served_[v].value());
    return std::max(1.0, bound);
}

std::optional<double> WindowCostModel::expected_frame_cost(int window) const {
    const std::optional<double> key = key_cost(window);
    if (!key) return std::nullopt;
    const double cached = cached_cost(window).value_or(*key);
    const double s = served(window);
    return (*key + (s - 1) * cached) / s;
}

void WindowCostModel::settle_probe() {
    if (!probing_) return;
    probing_ = false;
    const double lost = probe_cost_ - probe_frames_ * probe_baseline_;
    probe_budget_ -= std::max(0.0, lost - probe_paid_);
}

WindowCostModel::Choice WindowCostModel::choose(int max_window) {
    settle_probe();
    const int most = std::clamp(max_window, 2, kMaxWindow);
    // Learning: one plain frame, then a window (the motion-adaptive W, at most
    // kLearningWindow), so that both sides are measured before the model decides.
    if (!plain_.known()) return {1, false};
    bool any_key = false;
    for (int w = 2; w <= kMaxWindow; ++w) any_key = any_key || key_[w].known();
    if (!any_key) return {std::min(most, kLearningWindow), false};
    double cheapest = std::numeric_limits<double>::infinity();
    for (int w = 2; w <= most; ++w)
        if (key_within_tail(w)) cheapest = std::min(cheapest, expected_frame_cost(w).value_or(cheapest));
    // Among the windows within kWindowTieMargin of the cheapest, the smallest: its key frame is
    // the smallest spike in the frame times, and it wastes the least when cut short.
    int best = 2;
    double best_cost = cheapest;
    for (int w = 2; w <= most; ++w) {
        const std::optional<double> e = expected_frame_cost(w);
        if (e && key_within_tail(w) && *e <= cheapest * (1 + kWindowTieMargin)) {
            best = w;
            best_cost = *e;
            break;
        }
    }
    const bool windows_pay = std::isfinite(cheapest) && best_cost < (1 - kWindowPayMargin) * plain_.value();
    if (const std::optional<Choice> p = probe(best, windows_pay, most)) return *p;
    return {windows_pay ? best : 1, false};
}

bool WindowCostModel::key_within_tail(int window) const {
    const std::optional<double> key = key_cost(window);
    const std::optional<double> plain = plain_cost();
    if (!key || !plain || *key <= kMaxKeyFrameCost * *plain) return true;
    // Past the bound, estimates get no new samples: once the newest is kStaleKeyFrames old, the
    // smallest window may be probed again, or a stretch where windows became cheap is never found.
    std::uint64_t newest = 0;
    for (int w = 2; w <= kMaxWindow; ++w)
        if (key_[w].known()) newest = std::max(newest, key_[w].last_frame());
    return window == 2 && frame_ >= newest + kStaleKeyFrames;
}

// The probe due now, if the spacing and the budget allow it (the header's rule).
std::optional<WindowCostModel::Choice> WindowCostModel::probe(int best, bool windows_pay, int max_window) {
    if (frame_ < last_probe_frame_ + kMinFramesBetweenProbes) return std::nullopt;
    const double plain = plain_.value();
    const double best_cost = expected_frame_cost(best).value_or(plain);
    Choice c{1, true};
    double loss = 0;
    if (!windows_pay) {
        // The window that risks the least: a wrong estimate then costs the least to correct.
        loss = std::numeric_limits<double>::infinity();
        c.window = 0;
        for (int w = 2; w <= max_window; ++w) {
            if (!key_within_tail(w)) continue;
            const double risk = served(w) * (expected_frame_cost(w).value_or(plain) - plain);
            if (risk < loss) {
                loss = risk;
                c.window = w;
            }
        }
        if (c.window == 0) return std::nullopt;  // every window's key frame would set the tail
    } else {
        // The neighbour whose key cost is the stalest (never measured first).
        int neighbour = 0;
        for (int w : {best - 1, best + 1}) {
            if (w < 2 || w > max_window || !key_within_tail(w)) continue;
            if (neighbour == 0 || !key_[w].known() ||
                (key_[neighbour].known() && key_[w].last_frame() < key_[neighbour].last_frame()))
                neighbour = w;
        }
        if (next_probe_plain_ || neighbour == 0) {
            loss = plain - best_cost;
        } else {
            c.window = neighbour;
            loss = served(neighbour) * (expected_frame_cost(neighbour).value_or(plain) - best_cost);
        }
    }
    // A probe dearer than the bank waits for a full bank and leaves a debt that the next
    // frames repay first, so probes still cost kProbeShare of the frames over time.
    loss = std::max(loss, 0.0);
    const double bank = kProbeShare * kProbeBankFrames * plain;
    if (probe_budget_ < std::min(loss, bank)) return std::nullopt;
    probe_budget_ -= loss;
    probing_ = true;
    probe_cost_ = 0;
    probe_frames_ = 0;
    probe_baseline_ = windows_pay ? best_cost : plain;
    probe_paid_ = loss;
    if (windows_pay) next_probe_plain_ = !next_probe_plain_;
    last_probe_frame_ = frame_;
    ++probes_;
    return c;
}

}  // namespace catgs
