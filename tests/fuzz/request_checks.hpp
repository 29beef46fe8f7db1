// Invariants of what the server's request validation accepts (request_validation.hpp): a
// SessionSetup and FrameSetup that the renderer and encoder can use as they are.
#pragma once

#include <cmath>
#include <string>

#include <grpcpp/support/status.h>

#include "camera_checks.hpp"
#include "catgs/constants.hpp"
#include "catgs/server/request_validation.hpp"
#include "fuzz_util.hpp"

namespace catgs::fuzz {

/// A refusal is INVALID_ARGUMENT naming the field (it starts with the prefix) or
/// RESOURCE_EXHAUSTED naming the limit, on one line.
inline void check_refusal(const grpc::Status& status, const std::string& prefix) {
    check_one_line(status.error_message());
    if (status.error_code() == grpc::StatusCode::INVALID_ARGUMENT) {
        require(status.error_message().rfind(prefix + ".", 0) == 0,
                "INVALID_ARGUMENT does not name a field under '" + prefix + "': " + status.error_message());
    } else {
        require(status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED,
                "unexpected status code " + std::to_string(status.error_code()) + ": " + status.error_message());
    }
}

inline void check_session(const server::SessionSetup& s, const server::Limits& limits) {
    require(!s.scene_id.empty(), "empty scene_id accepted");
    check_camera(Camera{s.intrinsics, Pose{}, "", 0.0}, "session");
    require(s.intrinsics.width <= limits.max_width && s.intrinsics.height <= limits.max_height,
            "resolution above the limit accepted");
    require(s.encode.jpeg_quality >= 1 && s.encode.jpeg_quality <= 100, "JPEG quality outside 1..100 accepted");
    require(s.max_unacked_frames >= 1 && s.max_unacked_frames <= server::kMaxUnackedFramesLimit,
            "max_unacked_frames outside 1..2 accepted");
    const RenderOptions& o = s.options;
    require(std::isfinite(o.near_plane) && o.near_plane > 0, "near plane not finite and positive");
    for (float c : o.background) require(c >= 0.0f && c <= 1.0f, "background outside [0, 1] accepted");
    require(o.catgs.window >= 1 && o.catgs.window <= kMaxWindow, "window outside 1..16 accepted");
    require(o.catgs.split_k <= (1u << 24), "split_k above 2^24 accepted");
}

inline void check_frame(const server::FrameSetup& f) {
    check_camera(f.camera, "frame");
    if (!f.hints) return;
    if (f.hints->linear_velocity)
        for (double v : *f.hints->linear_velocity) require(std::isfinite(v), "non-finite velocity accepted");
    if (f.hints->angular_speed)
        require(std::isfinite(*f.hints->angular_speed) && *f.hints->angular_speed >= 0,
                "non-finite or negative angular speed accepted");
    require(f.hints->plan.size() <= static_cast<std::size_t>(server::kMaxFlightPlanPoses), "flight plan too long");
    for (const Camera& c : f.hints->plan) check_camera(c, "flight plan");
}

}  // namespace catgs::fuzz
