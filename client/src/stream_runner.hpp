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

struct StreamPlan {
    v1::SessionConfig config;
    std::vector<Camera> path;     ///< poses, in order; repeated cyclically up to `poses`
    std::size_t poses = 0;        ///< how many to send
    double rate_hz = 30;          ///< pose rate; 0 = lock step (next pose when a frame arrives)
    int flight_plan = 0;          ///< future poses sent with each request
    bool velocity = true;         ///< send the path's velocity
    std::string authorization;    ///< "Bearer ..." or empty
    Clock::duration max_duration = std::chrono::hours(24);
};

struct StreamResult {
    grpc::Status status;
    std::uint64_t poses_sent = 0, frames = 0, frame_errors = 0, bytes = 0;
    std::uint64_t server_poses_coalesced = 0, server_frames_coalesced = 0;
    double time_to_first_frame_ms = -1;
    LatencyRecorder latency;
};

/// Called for each frame received (on the reading thread) with its latency in ms.
using FrameCallback = std::function<void(const v1::Frame&, double latency_ms)>;

/// Runs one stream to completion (blocking). `stop` ends it early (a clean half-close).
StreamResult run_stream(const std::shared_ptr<grpc::Channel>& channel, const StreamPlan& plan,
                        const FrameCallback& on_frame, const std::atomic<bool>& stop);

v1::Pose to_pose(const Camera& camera);

}  // namespace catgs::client
