// The occlusion cut's frame-to-frame rules (stages/occlusion.hpp), shared by the backends:
// which frames take the cut, how far the camera moved since the cut was recorded, and the
// back-off after a frame that missed; and the host's build of the cut pyramid.
#pragma once

#include <optional>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/stages/occlusion.hpp"

namespace catgs {

/// After a miss the cut waits this many frames, doubling after each miss in a row, up to here:
/// a camera that keeps outrunning the prediction costs at most one redrawn frame in this many.
inline constexpr int kOcclusionMaxBackoff = 64;

class OcclusionTracker {
public:
    /// The motion to carry the last recorded cut over to `now`, or nothing: no cut recorded, at
    /// other intrinsics, a turn too wide (occlusion_motion), backing off after a miss, or a
    /// frame that cannot take it (`eligible` false: see the backends' rules). Once a frame.
    std::optional<OcclusionMotion> plan(const Camera& now, bool eligible);
    /// After a frame at `now`: whether it recorded its tile cuts (then they feed the next
    /// frame), took the cut, and missed (it was drawn again without it).
    void rendered(const Camera& now, bool recorded, bool took_cut, bool missed);
    void reset() { *this = OcclusionTracker{}; }

private:
    bool recorded_ = false;
    Camera camera_;  // of the frame that recorded
    int skip_ = 0;
    int backoff_ = 1;
};

/// The cut pyramid's cells (p.cells) from the last frame's recorded cuts over p's level 0, as
/// the CUDA backend's predict_occlusion builds them.
std::vector<float> occlusion_cells(const std::vector<float>& recorded, const OcclusionPyramid& p,
                                   const OcclusionMotion& motion);

}  // namespace catgs
