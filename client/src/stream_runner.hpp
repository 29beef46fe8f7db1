// One render stream driven open-loop: poses are sent at their scheduled times whatever the
// frames do, and each frame's latency is measured from the *intended* send time of the pose
// it answers, so a slow server cannot hide its delays by slowing the sender down (no
// coordinated omission). Poses the server coalesced get no frame and are counted instead.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/v1/catgs.grpc.pb.h"
#include "latency.hpp"

namespace catgs::client {

using Clock = std::chrono::steady_clock;

/// Metadata that front proxies route on (deploy/envoy-host.yaml, deploy/k8s/envoy.yaml): calls
/// with the same value reach the same server.
inline constexpr const char* kSessionHeader = "x-catgs-session";
inline constexpr std::size_t kMaxSessionIdLength = 128;
/// 1..kMaxSessionIdLength printable ASCII characters: a valid HTTP/2 header value.
inline bool valid_session_id(const std::string& id) {
    if (id.empty() || id.size() > kMaxSessionIdLength) return false;
    for (char c : id)
        if (c < 0x20 || c > 0x7e) return false;
    return true;
}

struct StreamPlan {
    v1::SessionConfig config;
    std::vector<Camera> path;   ///< poses, in order; repeated cyclically up to `poses`
    std::size_t poses = 0;      ///< how many to send
    double rate_hz = 30;        ///< pose rate; 0 = lock step (next pose when a frame arrives)
    bool lock_step = false;     ///< wait for each frame before the next pose (with rate_hz: at most that rate)
    int flight_plan = 0;        ///< future poses sent with each request
    bool velocity = true;       ///< send the path's velocity
    std::string authorization;  ///< "Bearer ..." or empty
    std::string session_id;     ///< sent as kSessionHeader, or empty
    Clock::duration max_duration = std::chrono::hours(24);
    std::size_t first = 0;  ///< index of the first pose to send (a resumed stream)
};

/// Reconnection after UNAVAILABLE (server restarting, draining or unreachable): jittered
/// exponential backoff. The n-th consecutive retry waits a uniformly random time between half
/// and all of min(max_backoff, backoff * 2^(n-1)); an attempt that received a frame resets n.
struct RetryPolicy {
    int retries = 6;  ///< consecutive failed attempts retried before giving up (0: none)
    std::chrono::milliseconds backoff{250};
    std::chrono::milliseconds max_backoff{5000};
    std::uint64_t seed = 0;  ///< jitter seed (0: from the clock)
};

/// The wait before retry number `attempt` (1-based) of `policy`, drawn with `random01` in [0, 1).
std::chrono::milliseconds backoff_delay(const RetryPolicy& policy, int attempt, double random01);

struct StreamResult {
    grpc::Status status;
    std::uint64_t poses_sent = 0, frames = 0, frame_errors = 0, bytes = 0;
    std::uint64_t server_poses_coalesced = 0, server_frames_coalesced = 0;
    double time_to_first_frame_ms = -1;
    LatencyRecorder latency;
    std::size_t next_index = 0;  ///< where a resumed stream starts: the first pose without a frame
    int reconnects = 0;          ///< retries after UNAVAILABLE (run_stream_with_retries)
};

/// Called for each frame received (on the reading thread) with its latency in ms.
using FrameCallback = std::function<void(const v1::Frame&, double latency_ms)>;

/// Runs one stream to completion (blocking). `stop` ends it early (a clean half-close).
StreamResult run_stream(const std::shared_ptr<grpc::Channel>& channel, const StreamPlan& plan,
                        const FrameCallback& on_frame, const std::atomic<bool>& stop);

/// run_stream, reconnecting on UNAVAILABLE as `policy` says and resuming from the last pose
/// that got no frame (a new session: the server kept nothing of the old one). `log` receives
/// one line per retry. The counters add up over the attempts.
StreamResult run_stream_with_retries(const std::shared_ptr<grpc::Channel>& channel, const StreamPlan& plan,
                                     const FrameCallback& on_frame, const std::atomic<bool>& stop,
                                     const RetryPolicy& policy, const std::function<void(const std::string&)>& log);

}  // namespace catgs::client
