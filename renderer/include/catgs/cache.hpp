// CaT-GS frame planning, shared by every backend: which frames are key frames, which poses a
// key frame speculates on, the envelope of poses its cache covers, and the adaptive window W:
// bounded by the expected screen motion (WindowController), chosen within that bound from the
// frame costs the backend measured, or a plain frame where no window pays (window_cost.hpp,
// CatgsOptions::window_cost).
//
// Guarantee (docs/pipeline.md, "Guarantee", states it too): a frame is drawn from the cache only when it has the key
// frame's intrinsics and resolution and its pose lies within the envelope: within `guard_px`
// of screen motion of one of the speculated poses, by a first-order bound over every cached
// Gaussian (translation over the nearest cached depth, rotation, and the growth of the
// largest cached footprint), and within `guard_translation` metres of it. Every footprint was
// dilated by guard_px at every speculated pose, so then every tile's cached list holds every
// Gaussian the full per-frame pipeline would put there. Otherwise the frame is a key frame.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <deque>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/constants.hpp"
#include "catgs/split_choice.hpp"
#include "catgs/window_cost.hpp"

namespace catgs {

enum class CacheMode {
    off,           ///< every frame runs the full pipeline
    speculative,   ///< CaT-GS: key frames preprocess the whole window, frames in it reuse lists
    unspeculated,  ///< reuse the key frame's lists with no speculation and no envelope check:
                   ///< only to demonstrate the stripe artifacts speculation removes
};

struct CatgsOptions {
    /// Tile task splitting: lists longer than split_k entries become sub-tasks; 0 = off.
    std::uint32_t split_k = 0;
    /// Derive k per frame from the list lengths: max(kAutoSplitFloor, kAutoSplitFactor x the
    /// mean length of the non-empty lists). Overrides split_k.
    bool split_auto = false;
    /// Early-termination threshold of the sub-tasks after the first (the paper raises it;
    /// the default, 1e-4, leaves the image unchanged).
    double split_tail_transmittance = kMinTransmittance;

    CacheMode cache = CacheMode::off;
    /// Cached frames re-sort their lists by the current depth (tiles unchanged, so only the
    /// depth bits of the keys change), so that every frame is the full render's. Without it the
    /// key frame's depth order is reused for the whole window, as in the paper: faster, but
    /// where nearly coplanar layers (windows on facades, markings on roads) swap order within
    /// a window single pixels differ (up to 33 levels over the 6M city survey). On here, off in
    /// default_pipeline_options().
    bool resort_cached = true;
    /// Without resort_cached, a cached frame reuses the key frame's depth order only while its
    /// rotation is within this angle (radians) of the key frame's, and re-sorts otherwise (and
    /// for the rest of the window). Sort keys are view depths, dot(forward, mean - centre): a
    /// translation shifts every depth by the same amount and keeps their order, so only rotation
    /// can swap layers. Infinity: always reuse (the paper's cache).
    double reuse_order_max_angle = std::numeric_limits<double>::infinity();

    /// Whether a cached frame may re-sort, so a key frame must keep its pairs in emission order.
    bool cached_frames_may_resort() const { return resort_cached || std::isfinite(reuse_order_max_angle); }
    int window = 4;  ///< initial (adaptive) or fixed W, 1..16
    bool adaptive_window = true;
    double guard_px = 2.0;            ///< footprint dilation and envelope radius, pixels
    double guard_translation = 0.25;  ///< envelope radius in metres (also lowers the near plane)
    /// Screen motion (pixels) a window may span before W shrinks: one tile.
    double window_motion_budget_px = 16.0;
    /// With the adaptive window: choose W, or a plain frame, from the costs the backend measures
    /// (window_cost.hpp) within the motion-adaptive W; off: from the motion alone. Off here, so
    /// that the plans of tests and code that set their own options do not depend on timing;
    /// default_pipeline_options() measures time.
    WindowCost window_cost = WindowCost::off;
    /// Occlusion cut (stages/occlusion.hpp, float renders of either backend): a plain frame
    /// leaves out the Gaussians behind where the last frame's tiles turned opaque, checks every
    /// tile, and draws itself again without the cut where one did not turn opaque in front of
    /// it, so the image is the full lists' either way. Off by default, in
    /// default_pipeline_options() too: on the bench kit's paths one or two tiles of a frame
    /// that barely turn opaque miss on nearly every frame it is tried, and the whole-frame
    /// redraw costs more than the cut saves (docs/pipeline.md#occlusion-cut).
    bool occlusion_cut = false;
};

/// Lists this many entries long or shorter are never split by the automatic k.
inline constexpr std::uint32_t kAutoSplitFloor = 256;
/// Automatic k = this many times the mean non-empty list length.
inline constexpr double kAutoSplitFactor = 4.0;

/// Optional per-frame knowledge from the client.
struct FrameHints {
    /// The camera's next poses (a flight plan), oldest first; used for speculation instead of
    /// extrapolating the pose history.
    std::vector<Camera> plan;
    /// Reported velocity: linear (m/s, world) and angular (rad/s, magnitude).
    std::optional<std::array<double, 3>> linear_velocity;
    std::optional<double> angular_speed;
};

/// Motion-adaptive window size. W starts at `initial` and stays in [1, 16]. At each key frame
/// it is fed the expected screen motion per frame (pixels); the target is the largest W whose
/// window spans at most the motion budget. W shrinks to the target at once (render length grows
/// fast with W while moving: the paper's +4% at W=4, +44% at 8, +140% at 16), and grows only
/// when two consecutive key frames ask for more with a 25% margin, at most doubling, so it does
/// not oscillate around a boundary.
class WindowController {
public:
    explicit WindowController(int initial = 4, double budget_px = 16.0);
    int update(double motion_px_per_frame);
    int window() const { return window_; }

private:
    int window_;
    double budget_px_;
    int grow_votes_ = 0;
};

/// The angle (radians) of the rotation between two poses.
double rotation_angle(const Pose& a, const Pose& b);

/// First-order bound (pixels) on how far any footprint moves or grows on screen between
/// poses a and b (same intrinsics), for Gaussians at depth >= min_depth whose footprint
/// half-extent is at most max_extent_px.
double screen_motion_bound(const Camera& a, const Camera& b, double min_depth, double max_extent_px);

/// What a backend reports about the key frame it rendered.
struct KeyFrameSummary {
    double min_depth = 0;  ///< nearest depth of a cached Gaussian over the window's poses
    /// Mean of 1/depth over the visible Gaussians at the key pose: screen motion from
    /// translation is proportional to 1/depth, so this is the typical motion factor.
    double mean_inverse_depth = 0;
    double max_extent_px = 0;  ///< largest cached footprint half-extent (full-screen ones excluded)
};

/// Decides key and cached frames for one stream.
class FramePlanner {
public:
    struct Plan {
        bool key = true;
        std::vector<Camera> poses;  ///< key frame: the actual pose first, then the speculated ones
        int window = 1;
        /// Cached frame: re-sort the cached pairs by the current depth (else reuse the key
        /// frame's order, CatgsOptions::resort_cached and reuse_order_max_angle).
        bool resort = true;
        /// Key frame rendered as with the cache off (no speculation, guard band or kept lists):
        /// the cache is off, or a window would not pay for its key frame (FramePlanner::next).
        bool plain = false;
        /// Chosen by the cost model to refresh an estimate (WindowCostModel's probes), not as
        /// the cheapest.
        bool probe = false;
        /// Key frame: keep its pairs in emission (Gaussian) order besides the sorted lists, since
        /// a cached frame of its window may re-sort, and re-sorting re-keys from them so that
        /// the stable sort orders equal depths by index, as a full render does.
        bool keep_emission_order = false;
        /// A frame that builds task lists (a key frame, or a cached frame that re-sorts) may
        /// split its long tiles: off where the measured rasterize time says splitting does not
        /// pay on this path (SplitChooser), or where the options split nothing.
        bool split = true;
        /// The k a split frame of this plan uses (SplitChooser::k): the options' k, or the rung
        /// of the ladder the chooser measured cheapest on this path. 0: the options' k.
        std::uint32_t split_k = 0;
        /// The split choice explores (SplitChooser::exploring): the window cost model does not
        /// learn this frame's cost. At 4K the first frame splits and costs a third more than
        /// the frames after it; learned as plain's cost, it kept the kit's garden low path on
        /// windows that lost 18% for its first 66 frames (H200, session 9).
        bool split_exploring = false;

        /// The splitting options this frame renders with: `options` without splitting unless
        /// `split`, else with this plan's k (split_auto keeps deriving k from the lists).
        CatgsOptions split_options(const CatgsOptions& options) const;
        /// The cache mode this frame renders with.
        CacheMode cache(const CatgsOptions& options) const { return plain ? CacheMode::off : options.cache; }
        /// The near plane the frame's poses are projected with: a speculative window lowers
        /// `near_plane` by the translation guard (never below 1e-3, so 1/z stays finite), so that a
        /// pose inside the envelope finds the Gaussians that cross the near plane on the way.
        double window_near_plane(const CatgsOptions& options, double near_plane) const;
    };

    /// The plan of the frame at `actual`. A cached frame is planned only after key_rendered, and
    /// only if the backend holds what it needs: one that would re-sort without the key frame's
    /// pairs in emission order (Plan::keep_emission_order was off) is a key frame instead.
    Plan next(const Camera& actual, const CatgsOptions& options, const FrameHints* hints = nullptr);
    /// Called by the backend after rendering a key frame of `plan`.
    void key_rendered(const Plan& plan, const KeyFrameSummary& summary);
    /// Called by the backend after every frame with what it measured: the cost model
    /// (CatgsOptions::window_cost) learns from it. Frames of other plans, or of an option
    /// without the cost model, teach it nothing.
    void frame_rendered(const Plan& plan, const FrameStats& stats);
    /// The last frame could not be cached (e.g. rendered in bands): the next is a key frame.
    void invalidate();
    /// Forgets the cache, the pose history and the learned costs (a new scene or stream).
    void reset();
    /// What the cost model has learned (tests and tools read it).
    const WindowCostModel& cost_model() const { return costs_; }
    const SplitChooser& split_chooser() const { return split_; }

private:
    /// next() without the split choice.
    Plan plan_frame(const Camera& actual, const CatgsOptions& options, const FrameHints* hints);
    /// Radians the camera turns per frame: the reported angular speed, else the last step.
    double expected_turn_per_frame(const FrameHints* hints) const;
    /// W from the expected screen motion (the adaptive window), or the fixed W.
    int motion_window(const Camera& actual, const CatgsOptions& options, const FrameHints* hints);

    std::deque<Camera> history_;  // recent actual cameras, newest last
    std::optional<WindowController> controller_;
    std::vector<Camera> envelope_;  // speculated poses of the current cache
    KeyFrameSummary summary_;
    int frames_in_window_ = 0;
    int window_ = 1;
    // A cached frame of this window re-sorted: the lists no longer hold the key frame's order
    // (re-sorting drops pairs whose footprint left their tile), so the later ones re-sort too.
    bool window_resorted_ = false;
    // The key frame of this window kept its pairs in emission order (Plan::keep_emission_order).
    bool emission_order_kept_ = false;
    // The cost model, the feed it learns from (the options of the last plan) and the
    // intrinsics its costs were measured at (costs change with the resolution).
    WindowCostModel costs_;
    WindowCost cost_feed_ = WindowCost::off;
    std::optional<Intrinsics> cost_intrinsics_;
    SplitChooser split_;
    // Split costs per pair measured at other intrinsics say little about these.
    std::optional<Intrinsics> split_intrinsics_;
    // The current window's length has been reported to the cost model.
    bool window_end_reported_ = true;
};

/// Extrapolates `count` poses after the newest camera of `history` at constant linear and
/// angular velocity, spaced by the history's last frame interval.
std::vector<Camera> predict_poses(const std::deque<Camera>& history, int count);

const char* cache_mode_name(CacheMode mode);
/// "off", "speculative", "unspeculated"; throws catgs::Error otherwise.
CacheMode parse_cache_mode(const std::string& name);

}  // namespace catgs
