// The cost model of the adaptive window: at each key frame, open the window of W frames whose
// expected cost per frame is lowest, or render a plain frame where no window pays for itself.
//
// The rule. A window of W frames costs its key frame, key(W), plus one cached frame for each
// further frame it serves, and it serves served(W) <= W frames before W or the envelope ends
// it (windows end early while moving fast). Its expected cost per frame is
//     e(W) = (key(W) + (served(W) - 1) * cached(W)) / served(W),
// against plain, the cost of a plain frame (no speculation, guard band or kept pairs). At a
// key frame the planner takes the W in 2..M with the lowest e(W) (the smallest W of those
// within kWindowTieMargin of it) among those whose key frame costs at most kMaxKeyFrameCost plain
// frames, where M is the motion-adaptive window (WindowController:
// frames past the envelope become key frames anyway, so a larger W cannot serve more), and
// opens it only if e(W) < (1 - kWindowPayMargin) * plain; otherwise the frame is plain. Every estimate is learned from
// what the backend measured for each frame (FrameStats::total_ms, or the work counts of frame_work) through
// FramePlanner::frame_rendered.
//
// Learning. Costs are exponentially weighted averages per W, so they follow a path's content;
// a sample at one W scales the other W's key (or cached) estimates by the same factor, since a
// denser stretch of the scene makes every window dearer alike; a W never measured takes key(W) by linear interpolation
// between the measured W (and plain as W = 1), extrapolated past the largest by the last slope; cached(W) from the
// nearest measured W (none: plain, since frames never drawn from the cache cannot be assumed to save); served(W) = W
// unless a smaller window ended early, which bounds it. With nothing known the first frame is plain (it has no motion
// to speculate on either) and the first window takes the motion-adaptive W up to 2, so both sides are measured before
// the model decides and finding out that windows cannot pay costs little. Frames on which the
// split choice explores (SplitChooser::exploring) are not learned: their cost includes a choice
// the planner would not make.
//
// Probing, deterministic and bounded. Estimates of the side not chosen go stale (the scene or
// the motion changes), so the model sometimes renders the other side: where plain wins, the
// window that risks the least (the smallest expected loss); where windows win, alternately a
// plain frame and a neighbouring W. A probe runs
// only at least kMinFramesBetweenProbes frames after the last, and only when a budget that
// every frame feeds with kProbeShare of its cost (banking at most kProbeBankFrames frames'
// share) covers the probe's expected loss; once the probe's window has ended, the budget also
// pays what it really lost beyond that. So probes cost at most about kProbeShare of any
// stretch of a path, plus one bank and one probe, however wrong the estimates were.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "catgs/constants.hpp"

namespace catgs {

struct FrameStats;

/// What the adaptive window is chosen from (CatgsOptions::window_cost).
enum class WindowCost {
    off,   ///< the expected screen motion alone (WindowController): the plans do not depend on costs
    time,  ///< motion and each frame's measured cost, FrameStats::total_ms: the fastest plans
    work,  ///< motion and each frame's work counts (frame_work): plans reproducible on any machine
};

const char* window_cost_name(WindowCost cost);
/// "off", "time", "work"; throws catgs::Error otherwise.
WindowCost parse_window_cost(const std::string& name);

/// A deterministic proxy of a frame's cost from its work counts: projections, pairs emitted and
/// sorted, pairs blended, pixels copied, weighted by what each cost per unit on the H200
/// (window_cost.cpp gives the numbers). It tracks the GPU's time closely enough to choose
/// between windows and plain frames, and is no prediction of it.
double frame_work(const FrameStats& stats);
/// The cost the planner learns from a frame: total_ms (time), frame_work (work), 0 (off).
double frame_cost(const FrameStats& stats, WindowCost cost);

/// An exponentially weighted average of samples, with the frame of its newest sample.
class CostEstimate {
public:
    /// `weight`: how much the sample moves the estimate, in (0, 1].
    void add(double sample, std::uint64_t frame, double weight);
    bool known() const { return samples_ > 0; }
    double value() const { return value_; }
    /// Scales the value as content that makes this cost change scales it (no new sample).
    void scale(double factor) { value_ *= factor; }
    int samples() const { return samples_; }
    std::uint64_t last_frame() const { return last_frame_; }

private:
    double value_ = 0;
    int samples_ = 0;
    std::uint64_t last_frame_ = 0;
};

/// Windows open only when their expected cost per frame undercuts plain by this fraction:
/// estimates wander by a few percent from frame to frame, and a window that pays less than
/// that is not worth the key frame's spike.
inline constexpr double kWindowPayMargin = 0.02;
/// Windows whose expected cost per frame is within this fraction of the cheapest one count as
/// ties, and the smallest W of them is taken: a larger W saves that little per frame, while its
/// key frame sets the frame-time tail (p90, max) and a window cut short (a turn, the end of a
/// stream) wastes most of it.
inline constexpr double kWindowTieMargin = 0.02;
/// Windows whose key frame is expected to cost more than this many plain frames are neither
/// opened nor probed, even where they would pay over the window: their key frames set the tail
/// of the frame times (the kit's city at 1080p: W = 4 key frames at 2.3x plain were its slowest
/// frames, for 0.5% saved over the path; H200, 2026-12-02). A viewer sees the slowest frames.
inline constexpr double kMaxKeyFrameCost = 1.5;
/// ... except that W = 2 may be probed once the newest key sample is this many frames old, so
/// that a stretch where key frames became cheap is found: at most one such frame per this many.
inline constexpr std::uint64_t kStaleKeyFrames = 200;
/// The share of every frame's cost set aside for probes: probes cost at most about this much of
/// a path (the issue allows the default 2% over plain; the first window can cost another frame).
inline constexpr double kProbeShare = 0.01;
/// The probe budget banks at most this many frames' share of plain frames: enough for one
/// probe of a window that loses a plain frame, too little for a burst after a long stretch.
inline constexpr double kProbeBankFrames = 100;
/// At least this many frames between two probes, so that a probe's window has ended and been
/// learned before the next one starts.
inline constexpr int kMinFramesBetweenProbes = 16;

/// The learned costs and the choice between windows and plain frames (the header's rule).
class WindowCostModel {
public:
    struct Choice {
        int window = 1;      ///< W to open; 1: a plain frame
        bool probe = false;  ///< chosen to refresh an estimate, not because it is the cheapest
    };

    /// At a key frame, with W at most `max_window` (>= 2, the motion-adaptive window).
    Choice choose(int max_window);

    void plain_rendered(double cost);
    void key_rendered(int window, double cost);
    void cached_rendered(int window, double cost);
    /// A window of `window` frames ended after serving `frames` frames (its key frame included).
    void window_ended(int window, int frames);

    std::optional<double> plain_cost() const;
    /// key(W): measured, else interpolated (the header's rule); nullopt with nothing to go on.
    std::optional<double> key_cost(int window) const;
    /// cached(W): measured, else the nearest measured W's, else plain's.
    std::optional<double> cached_cost(int window) const;
    /// served(W): measured, else W bounded by the windows that ended early.
    double served(int window) const;
    /// e(W), the expected cost per frame of a window of W; nullopt while key(W) is unknown.
    std::optional<double> expected_frame_cost(int window) const;

    /// Frames rendered as probes since the last reset.
    int probes() const { return probes_; }
    void reset() { *this = WindowCostModel{}; }

private:
    void spend(double cost);
    /// Adds a sample to estimates[w] and scales the other W's estimates alike.
    void learn(std::array<CostEstimate, kMaxWindow + 1>& estimates, int window, double cost);
    std::optional<Choice> probe(int best, bool windows_pay, int max_window);
    /// key(W) within kMaxKeyFrameCost of plain (or unknown).
    bool key_within_tail(int window) const;
    /// A probe's window has ended: the budget pays what it really lost beyond the estimate.
    void settle_probe();

    CostEstimate plain_;
    std::array<CostEstimate, kMaxWindow + 1> key_{}, cached_{}, served_{};
    std::uint64_t frame_ = 0;  // frames recorded so far: the estimates' clock
    std::uint64_t last_probe_frame_ = 0;
    double probe_budget_ = 0;
    int probes_ = 0;
    // The probe under way: its frames' cost so far, how many, what a frame would have cost
    // without it, and the loss already paid from the budget.
    bool probing_ = false;
    double probe_cost_ = 0, probe_baseline_ = 0, probe_paid_ = 0;
    int probe_frames_ = 0;
    bool next_probe_plain_ = true;  // where windows win, probes alternate plain and a neighbour W
};

}  // namespace catgs
