// Admission control: how many sessions run at once, and the resolution and scene-size limits.
// Refusals are RESOURCE_EXHAUSTED with a message naming the limit, so a client (or a load
// balancer retry policy) can try another server.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include <grpcpp/support/status.h>

namespace catgs::server {

struct Limits {
    /// Concurrent sessions (streams and unary renders) per GPU (--gpus: per device): each session
    /// owns a renderer with its own arenas, and frame rate drops for everyone beyond a few.
    int max_sessions = 8;
    /// Largest image a session may ask for; 4K covers every viewer and bounds arena memory.
    int max_width = 3840;
    int max_height = 2160;
    /// Host memory of all loaded scenes together (0: no limit). On the CUDA backend the
    /// sessions of a scene share one device copy of the same size, so this also bounds the
    /// device memory held by scenes.
    std::uint64_t max_scene_bytes = 0;
    /// Renderer memory one session may hold, as the backend reports it after each frame
    /// (FrameStats::arena_bytes: the GPU arenas; the CPU backend reports none): a session
    /// above it ends with RESOURCE_EXHAUSTED (0: no limit). The resolution limits above bound
    /// the per-pixel part; the tile-pair part depends on the scene and the view.
    std::uint64_t max_session_bytes = 0;
    /// Frame requests per second one stream may send (0: no limit), with a burst of one
    /// second's worth. Faster clients are not refused: the server reads their next message
    /// later, so HTTP/2 flow control slows them down.
    double max_pose_rate = 240;
    /// A stream whose client has not taken a frame off the wire for this long (a write stuck
    /// in flow control) is cancelled with DEADLINE_EXCEEDED, freeing its session (0: never).
    int stall_timeout_ms = 20000;
    /// A stream that has not sent its opening message this long after it started is finished
    /// with DEADLINE_EXCEEDED (0: never): an idle call would otherwise hold a stream slot, its
    /// buffers and a place in the shutdown drain for as long as the client likes.
    int open_timeout_ms = 10000;
};

/// The status of every call refused or ended because the server is draining (shutting down):
/// UNAVAILABLE, so that clients reconnect, behind a load balancer to another instance.
inline grpc::Status shutting_down_status() {
    return {grpc::StatusCode::UNAVAILABLE,
            "server is shutting down: reconnect (to this address or another instance) and resume from your last pose"};
}

class Admission {
public:
    explicit Admission(int max_sessions) : max_sessions_(max_sessions) {}

    /// Held by an admitted session; releases its slot when destroyed.
    class Ticket {
    public:
        explicit Ticket(Admission* owner) : owner_(owner) {}
        ~Ticket() { owner_->release(); }
        Ticket(const Ticket&) = delete;
        Ticket& operator=(const Ticket&) = delete;

    private:
        Admission* owner_;
    };

    int max_sessions() const { return max_sessions_; }

    /// A ticket, or a status: UNAVAILABLE while draining, RESOURCE_EXHAUSTED at the limit.
    grpc::Status admit(std::unique_ptr<Ticket>* ticket) {
        std::lock_guard lock(mutex_);
        if (draining_) return shutting_down_status();
        if (active_ >= max_sessions_)
            return {grpc::StatusCode::RESOURCE_EXHAUSTED,
                    "max-sessions: the server already runs " + std::to_string(active_) + " of " +
                        std::to_string(max_sessions_) + " sessions; retry later or on another server"};
        ++active_;
        ticket->reset(new Ticket(this));
        return grpc::Status::OK;
    }
    /// From now on every admit() is refused with UNAVAILABLE.
    void drain() {
        std::lock_guard lock(mutex_);
        draining_ = true;
    }
    bool draining() const {
        std::lock_guard lock(mutex_);
        return draining_;
    }
    int active() const {
        std::lock_guard lock(mutex_);
        return active_;
    }

private:
    void release() {
        std::lock_guard lock(mutex_);
        --active_;
    }
    mutable std::mutex mutex_;  // a leaf: nothing is locked under it (lock order: server_core.hpp)
    int max_sessions_;
    int active_ = 0;
    bool draining_ = false;
};

}  // namespace catgs::server
