#include "catgs/cache.hpp"

#include <algorithm>
#include <cmath>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include "catgs/error.hpp"
#include "catgs/host_vector.hpp"

namespace catgs {
namespace {

// Frames kept to estimate velocity and extrapolate poses.
constexpr std::size_t kHistoryLength = 8;
// Frame interval assumed when timestamps do not give one (a 30 fps viewer).
constexpr double kDefaultFrameInterval = 1.0 / 30.0;
// W grows only when the target exceeds it with this margin on the motion (hysteresis).
constexpr double kGrowMargin = 1.25;
// Consecutive key frames that must ask for a larger W before it grows.
constexpr int kGrowVotes = 2;
// The speculative near plane never goes below this, so 1/z stays finite.
constexpr double kMinSpeculativeNear = 1e-3;

glm::dquat to_glm(const std::array<double, 4>& q) {
    return glm::dquat(q[0], q[1], q[2], q[3]);
}

double frame_interval(const std::deque<Camera>& history) {
    if (history.size() < 2) return kDefaultFrameInterval;
    const double dt = history.back().timestamp - history[history.size() - 2].timestamp;
    return dt > 0 && std::isfinite(dt) ? dt : kDefaultFrameInterval;
}

/// The largest |x/z| or |y/z| inside the projection's Jacobian clamp region.
double max_tangent(const Intrinsics& k) {
    const double slack = kJacobianClampFactor - 1.0;
    const double tx = std::max(k.cx, k.width - k.cx) / k.fx + slack * 0.5 * k.width / k.fx;
    const double ty = std::max(k.cy, k.height - k.cy) / k.fy + slack * 0.5 * k.height / k.fy;
    return std::max(tx, ty);
}

}  // namespace

WindowController::WindowController(int initial, double budget_px)
    : window_(std::clamp(initial, 1, kMaxWindow)), budget_px_(budget_px) {}

int WindowController::update(double motion) {
    // Largest W whose window spans at most the budget; a still camera allows the maximum.
    auto target_for = [&](double m) {
        if (!(m > 0)) return kMaxWindow;
        return static_cast<int>(std::clamp(std::floor(budget_px_ / m), 1.0, static_cast<double>(kMaxWindow)));
    };
    const int target = target_for(motion);
    if (target < window_) {
        window_ = target;
        grow_votes_ = 0;
    } else if (target_for(motion * kGrowMargin) > window_) {
        if (++grow_votes_ >= kGrowVotes) {
            window_ = std::min(target_for(motion * kGrowMargin), 2 * window_);
            grow_votes_ = 0;
        }
    } else {
        grow_votes_ = 0;
    }
    return window_;
}

double rotation_angle(const Pose& a, const Pose& b) {
    // R = Ra Rb^T; angle from its trace and skew part (atan2 stays accurate for small angles).
    const auto& p = a.rotation;
    const auto& q = b.rotation;
    double r[3][3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            r[i][j] = p[3 * i] * q[3 * j] + p[3 * i + 1] * q[3 * j + 1] + p[3 * i + 2] * q[3 * j + 2];
    const double sx = r[2][1] - r[1][2], sy = r[0][2] - r[2][0], sz = r[1][0] - r[0][1];
    const double s = 0.5 * std::sqrt(sx * sx + sy * sy + sz * sz);
    const double c = 0.5 * (r[0][0] + r[1][1] + r[2][2] - 1.0);
    return std::atan2(s, c);
}

double screen_motion_bound(const Camera& a, const Camera& b, double min_depth, double max_extent_px) {
    // A ray to a point at depth >= min_depth turns by at most (rotation + translation / depth)
    // radians; within the clamp region a direction change moves the image point by at most
    // f (1 + tan^2) per radian. A footprint of half-extent r scales with 1/z and is warped by
    // the rotation, which adds at most r (translation / depth + (1 + tan^2) rotation).
    const double f = std::max(a.intrinsics.fx, a.intrinsics.fy);
    const double tangent = max_tangent(a.intrinsics);
    const double kappa = 1.0 + tangent * tangent;
    const double dt = distance(camera_centre(a.pose), camera_centre(b.pose));
    const double dtheta = rotation_angle(a.pose, b.pose);
    const double depth = std::max(min_depth, 1e-6);
    return f * kappa * (dtheta + dt / depth) + max_extent_px * (dt / depth + kappa * dtheta);
}

std::vector<Camera> predict_poses(const std::deque<Camera>& history, int count) {
    std::vector<Camera> out;
    if (history.empty() || count <= 0) return out;
    const Camera& now = history.back();
    const double dt = frame_interval(history);
    if (history.size() < 2) {
        for (int k = 1; k <= count; ++k) {
            Camera c = now;
            c.timestamp = now.timestamp + k * dt;
            out.push_back(c);
        }
        return out;
    }
    const Camera& before = history[history.size() - 2];
    const HostVec3 c1 = camera_centre(now.pose), c0 = camera_centre(before.pose);
    const glm::dquat q1 = to_glm(camera_to_world_quaternion(now.pose));
    const glm::dquat q0 = to_glm(camera_to_world_quaternion(before.pose));
    // World-frame rotation increment per frame, as an angle about an axis.
    glm::dquat step = q1 * glm::inverse(q0);
    if (step.w < 0) step = -step;
    const double angle = glm::angle(step);
    const glm::dvec3 axis = angle > 1e-12 ? glm::axis(step) : glm::dvec3(0, 0, 1);
    for (int k = 1; k <= count; ++k) {
        const glm::dquat qk = glm::angleAxis(angle * k, axis) * q1;
        const HostVec3 ck{c1[0] + k * (c1[0] - c0[0]), c1[1] + k * (c1[1] - c0[1]), c1[2] + k * (c1[2] - c0[2])};
        Camera c = now;
        c.pose = pose_from_quaternion(ck, {qk.w, qk.x, qk.y, qk.z});
        c.timestamp = now.timestamp + k * dt;
        c.name.clear();
        out.push_back(c);
    }
    return out;
}

FramePlanner::Plan FramePlanner::next(const Camera& actual, const CatgsOptions& options, const FrameHints* hints) {
    Plan plan = plan_frame(actual, options, hints);
    if (!split_intrinsics_ || !same_intrinsics(*split_intrinsics_, actual.intrinsics)) {
        split_.reset();
        split_intrinsics_ = actual.intrinsics;
    }
    if (plan.key || plan.resort) {
        plan.split = split_.choose(options);
        plan.split_k = plan.split ? split_.k() : 0;
        plan.split_exploring = split_.exploring();
    }
    return plan;
}

FramePlanner::Plan FramePlanner::plan_frame(const Camera& actual, const CatgsOptions& options,
                                            const FrameHints* hints) {
    history_.push_back(actual);
    while (history_.size() > kHistoryLength) history_.pop_front();
    Plan plan;
    plan.poses = {actual};
    plan.plain = options.cache == CacheMode::off;
    cost_feed_ = options.window_cost;
    // Costs measured at other intrinsics say little about these (4K frames cost ~2-4x 1080p).
    if (cost_feed_ != WindowCost::off &&
        (!cost_intrinsics_ || !same_intrinsics(*cost_intrinsics_, actual.intrinsics))) {
        costs_.reset();
        cost_intrinsics_ = actual.intrinsics;
    }
    if (plan.plain) return plan;

    // Cached frame: inside the current window and (with speculation) inside its envelope.
    if (!envelope_.empty() && frames_in_window_ < window_ &&
        same_intrinsics(actual.intrinsics, envelope_.front().intrinsics)) {
        bool inside = options.cache == CacheMode::unspeculated;
        for (const Camera& c : envelope_) {
            if (inside) break;
            inside = distance(camera_centre(c.pose), camera_centre(actual.pose)) <= options.guard_translation &&
                     screen_motion_bound(c, actual, summary_.min_depth, summary_.max_extent_px) <= options.guard_px;
        }
        if (inside) {
            ++frames_in_window_;
            plan.key = false;
            plan.window = window_;
            window_resorted_ = window_resorted_ || options.resort_cached ||
                               rotation_angle(envelope_.front().pose, actual.pose) > options.reuse_order_max_angle;
            plan.resort = window_resorted_;
            if (!plan.resort || emission_order_kept_) return plan;
            // Re-sorting needs the pairs in emission order, which a key frame that reused the
            // depth order did not keep: a key frame of the actual pose alone instead.
            Plan key;
            key.poses = {actual};
            key.window = window_;
            key.keep_emission_order = key.cache(options) != CacheMode::off && options.cached_frames_may_resort();
            return key;
        }
    }

    // Key frame: the window that ends here is reported to the cost model, then W is chosen
    // from the expected screen motion and, with the cost model, from the measured costs.
    if (!window_end_reported_) {
        costs_.window_ended(window_, frames_in_window_);
        window_end_reported_ = true;
    }
    int w = motion_window(actual, options, hints);
    plan.window = w;
    // Key frames that no window can pay for are plain frames, which skip the cache's work
    // (speculation, guard band, kept pairs; 6M city survey 1080p, H200: 1.59 ms at W = 1
    // against 1.40 plain): windows of one frame, and, with the adaptive window, frames that
    // turn past the order-reuse angle, since their cached frames would re-sort and cost what a
    // plain frame does (city survey: 1.40 ms either way; an orbit: W = 2 windows took 3.47 ms
    // median against 2.64 plain).
    const bool turning = options.adaptive_window && !options.resort_cached &&
                         expected_turn_per_frame(hints) > options.reuse_order_max_angle;
    if (options.cache == CacheMode::speculative && w > 1 && !turning && options.adaptive_window &&
        options.window_cost != WindowCost::off) {
        // Within the motion bound, the cost model picks W, or a plain frame where no window pays.
        const WindowCostModel::Choice choice = costs_.choose(w);
        w = choice.window;
        plan.window = w;
        plan.probe = choice.probe;
    }
    if (options.cache == CacheMode::speculative && (w == 1 || turning)) {
        plan.plain = true;
        plan.window = 1;
        return plan;
    }
    plan.keep_emission_order = options.cached_frames_may_resort();
    if (options.cache == CacheMode::speculative && w > 1) {
        std::vector<Camera> future;
        if (hints && !hints->plan.empty())
            future.assign(hints->plan.begin(), hints->plan.begin() + std::min<std::size_t>(hints->plan.size(), w - 1));
        else
            future = predict_poses(history_, w - 1);
        for (Camera& c : future) {
            c.intrinsics = actual.intrinsics;
            plan.poses.push_back(c);
        }
    }
    return plan;
}

int FramePlanner::motion_window(const Camera& actual, const CatgsOptions& options, const FrameHints* hints) {
    const int fixed = std::clamp(options.window, 1, kMaxWindow);
    if (!options.adaptive_window) return fixed;
    if (!controller_) controller_.emplace(fixed, options.window_motion_budget_px);
    const double dt = frame_interval(history_);
    double speed = 0;
    if (hints && hints->linear_velocity) {
        const auto& v = *hints->linear_velocity;
        speed = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    } else if (history_.size() >= 2) {
        speed = distance(camera_centre(history_.back().pose), camera_centre(history_[history_.size() - 2].pose)) / dt;
    }
    // Typical screen motion per frame, from the last key frame's depths (none yet: keep W).
    if (!(summary_.mean_inverse_depth > 0)) return controller_->window();
    const double f = std::max(actual.intrinsics.fx, actual.intrinsics.fy);
    return controller_->update(f * (speed * dt * summary_.mean_inverse_depth + expected_turn_per_frame(hints)));
}

double FramePlanner::expected_turn_per_frame(const FrameHints* hints) const {
    if (hints && hints->angular_speed) return *hints->angular_speed * frame_interval(history_);
    if (history_.size() < 2) return 0;
    return rotation_angle(history_.back().pose, history_[history_.size() - 2].pose);
}

void FramePlanner::key_rendered(const Plan& plan, const KeyFrameSummary& summary) {
    envelope_ = plan.poses;
    summary_ = summary;
    window_ = plan.window;
    frames_in_window_ = 1;
    window_resorted_ = false;
    emission_order_kept_ = plan.keep_emission_order;
    window_end_reported_ = false;
}

void FramePlanner::frame_rendered(const Plan& plan, const FrameStats& stats) {
    if (plan.key || plan.resort) split_.learn(plan.split, stats);
    if (cost_feed_ == WindowCost::off || plan.split_exploring) return;
    const double cost = frame_cost(stats, cost_feed_);
    if (!(cost > 0) || !std::isfinite(cost)) return;
    if (plan.plain)
        costs_.plain_rendered(cost);
    else if (!plan.key)
        costs_.cached_rendered(plan.window, cost);
    else if (plan.poses.size() > 1)  // not the key frame of one pose that re-keys a window (next)
        costs_.key_rendered(plan.window, cost);
}

void FramePlanner::invalidate() {
    if (!window_end_reported_ && !envelope_.empty()) costs_.window_ended(window_, frames_in_window_);
    window_end_reported_ = true;
    envelope_.clear();
    frames_in_window_ = 0;
    window_resorted_ = false;
    emission_order_kept_ = false;
}

void FramePlanner::reset() {
    costs_.reset();
    split_.reset();
    split_intrinsics_.reset();
    cost_intrinsics_.reset();
    window_end_reported_ = true;
    history_.clear();
    controller_.reset();
    envelope_.clear();
    summary_ = {};
    frames_in_window_ = 0;
    window_ = 1;
    window_resorted_ = false;
    emission_order_kept_ = false;
}

CatgsOptions FramePlanner::Plan::split_options(const CatgsOptions& options) const {
    CatgsOptions o = options;
    if (!split) {
        o.split_k = 0;
        o.split_auto = false;
    } else if (!o.split_auto && split_k > 0) {
        o.split_k = split_k;
    }
    return o;
}

double FramePlanner::Plan::window_near_plane(const CatgsOptions& options, double near_plane) const {
    return cache(options) == CacheMode::speculative
               ? std::max(kMinSpeculativeNear, near_plane - options.guard_translation)
               : near_plane;
}

const char* cache_mode_name(CacheMode mode) {
    switch (mode) {
        case CacheMode::off:
            return "off";
        case CacheMode::speculative:
            return "speculative";
        case CacheMode::unspeculated:
            return "unspeculated";
    }
    return "?";
}

CacheMode parse_cache_mode(const std::string& name) {
    if (name == "off") return CacheMode::off;
    if (name == "speculative") return CacheMode::speculative;
    if (name == "unspeculated") return CacheMode::unspeculated;
    throw Error("unknown cache mode '" + name + "' (expected off, speculative or unspeculated)");
}

}  // namespace catgs
