// One RenderService.Stream call: a ServerBidiReactor that owns a renderer for its session.
// The method is registered raw (see wire.hpp): requests arrive as bytes and are parsed here,
// so a malformed message ends the stream with INVALID_ARGUMENT instead of passing for a
// half-close; frames are serialized just before they are written.
//
// Threads: reactions (OnReadDone, OnWriteDone, OnCancel, OnDone) run on gRPC threads and only
// move data and flags under `mutex_`; rendering runs on the render pool and encoding on the
// encoder pool; StartWrite/Finish are called from whichever thread completes a step, never
// while holding `mutex_` (gRPC may run a reaction inline). The session's states are named
// phases (Phase); each step decides under the lock what to do next (plan_locked) and does it
// after unlocking (run).
//
// Backpressure (latest wins, bounded memory):
// - input: one pending pose; a newer request replaces it (poses_coalesced); frame requests
//   beyond Limits::max_pose_rate are not refused but read later (TokenBucket; the next read
//   waits on an alarm), so HTTP/2 flow control slows the client down, and each frame's
//   StreamStats.frame_requests_delayed tells it so;
// - credits: at most max_unacked_frames frames rendered but not acknowledged by the client
//   (FrameRequest.last_received_sequence); while over budget nothing is rendered;
// - output: one frame in flight in gRPC plus one waiting. A render starts only when its frame
//   will be written: with credit AND a free output place, counting the frames being rendered
//   or encoded (room_for_frame_locked), so no frame is rendered to be replaced unsent. A client
//   that acknowledges everything but never reads thus costs at most two renders, then none
//   until the stall watchdog ends it; its newer poses are coalesced meanwhile. (A newer encoded
//   frame still replaces a waiting one, frames_coalesced, should one ever overtake it.) Error
//   frames queue separately, at most a few;
// - scheduling: the session is one flow of the render pool and one of the encoder pool
//   (worker_pool.hpp): at most one render and one encode of it run at a time, in order, and
//   the pools take the next task from the flow that has used the least worker time, so a
//   small viewer's frame never waits behind the backlog of a large or greedy one;
// - stalls: a frame in flight longer than Limits::stall_timeout_ms (the client stopped
//   reading) gets the call cancelled by the server's watchdog (cancel_if_stalled), and a call
//   still without its opening message after Limits::open_timeout_ms is finished
//   (finish_if_not_opened).
//
// Finish is never called while a write, a postponed read or a cancel is under way (UnderWay):
// each of those calls into gRPC from outside a reaction, which is only safe before Finish. The
// session waits in Phase::finishing until ready_to_finish_locked().
#pragma once

#include <grpcpp/alarm.h>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "catgs/renderer.hpp"
#include "catgs/server/request_validation.hpp"
#include "catgs/server/server_core.hpp"
#include "catgs/server/token_bucket.hpp"
#include "catgs/v1/catgs.grpc.pb.h"

namespace catgs::server {

class StreamSession : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>,
                      public std::enable_shared_from_this<StreamSession> {
public:
    using Clock = std::chrono::steady_clock;

    StreamSession(ServerCore& core, grpc::CallbackServerContext* context);
    ~StreamSession() override;

    /// Registers the session and starts reading (or finishes at once if refused).
    void start();
    /// Server shutdown: drop queued work and end the stream with `status` as soon as no write
    /// is in flight.
    void drain(const grpc::Status& status);
    /// Ends the call now with `status` (or with the end already decided), even while a frame
    /// sits in flow control because the client does not read: the client still gets the status
    /// and its message (see cancel_call). For streams that drain() could not finish in time.
    void cancel(const grpc::Status& status);
    /// Watchdog: cancels the call, DEADLINE_EXCEEDED, when a frame has been in flight longer
    /// than `timeout`, counting it in ServerStats.streams_stalled first. Returns true when it
    /// cancelled.
    bool cancel_if_stalled(Clock::time_point now, std::chrono::milliseconds timeout);
    /// Watchdog: finishes the call, DEADLINE_EXCEEDED, when its opening message has not arrived
    /// within `timeout` of its start, counting it in ServerStats.open_timeouts first. Returns
    /// true when it did.
    bool finish_if_not_opened(Clock::time_point now, std::chrono::milliseconds timeout);

    void OnReadDone(bool ok) override;
    void OnWriteDone(bool ok) override;
    void OnCancel() override;
    void OnDone() override;

private:
    /// Where the call is. Phases only move forward, and finishing may follow any earlier one.
    /// Rendering and encoding run beside them on the worker pools; calls into gRPC from outside
    /// a reaction are tracked apart, in `under_way_`.
    enum class Phase {
        /// Reading the first message, which must be StreamRequest.open. Nothing renders.
        awaiting_open,
        /// Admitted (ticket_ and lease_ held); a render worker is making the renderer
        /// (initialise). Frame requests are read (a bad one gets its error frame); the newest
        /// waits in pending_, none renders.
        opening,
        /// renderer_ is made: the pending pose renders when credit allows, frames are written.
        open,
        /// The end is decided (finish_status_): nothing more is read, queued or rendered, and
        /// work still running is dropped when it completes. Finish waits for
        /// ready_to_finish_locked().
        finishing,
        /// Finish has been called; gRPC calls OnDone next.
        finished,
    };

    /// Calls into gRPC made from outside a reaction. They are safe only before Finish (after
    /// it the call may end at any moment), so Finish waits until none is under way.
    struct UnderWay {
        bool write = false;           ///< StartWrite of in_flight_buffer_; OnWriteDone has not run
        bool postponed_read = false;  ///< the next read waits on read_alarm_, or its StartRead is being made
        bool cancel = false;          ///< cancel_call is cancelling the call
        bool any() const { return write || postponed_read || cancel; }
    };

    struct PendingPose {
        FrameSetup frame;
        Clock::time_point received;
    };

    void handle_open(const v1::SessionConfig& config);
    /// `structure`: the flight plan's length, then check_enum_values of the whole StreamRequest.
    void handle_frame(const v1::FrameRequest& request, const grpc::Status& structure);
    void initialise();              // render pool: make the renderer
    void render_next();             // render pool: render the newest pose
    void render(PendingPose pose);  // render pool: render_next's render and the encode it posts
    /// Encoder or render pool: queues an image frame (or its encoding error) for writing;
    /// `view` is the pose it shows.
    void deliver(v1::Frame frame, const Pose& view);
    /// Render pool: answers `pose` with the bytes of the last frame sent, which showed the same
    /// view, instead of rendering it again.
    void resend_last(PendingPose pose, std::string data);

    // The helpers below require mutex_ held. Each returns work to do after unlocking.
    struct Actions {
        bool schedule_render = false;
        bool write = false;         // serialize in_flight_ and write it
        bool cancel_alarm = false;  // a postponed read is no longer wanted
        std::optional<grpc::Status> finish;
    };
    bool ending_locked() const { return phase_ == Phase::finishing || phase_ == Phase::finished; }
    /// The finish condition: the end is decided and nothing outside a reaction is still
    /// calling into gRPC.
    bool ready_to_finish_locked() const { return phase_ == Phase::finishing && !under_way_.any(); }
    /// The client half-closed and everything it asked for has been answered: the stream ends OK.
    bool served_locked() const;
    /// A frame rendered now would be written, not replaced unsent: the output's places (one in
    /// gRPC's hands, one waiting) are not all taken by frames written, waiting or on the way.
    bool room_for_frame_locked() const;
    void plan_locked(Actions& actions);
    void choose_write_locked(Actions& actions);
    void request_finish_locked(const grpc::Status& status);
    void run(const Actions& actions);
    void drop_unacked_locked(std::uint64_t sequence);
    void set_buffered_locked(int frames, std::int64_t bytes);
    void error_frame_locked(std::uint64_t sequence, const grpc::Status& status);
    void postpone_read(Clock::duration delay);
    void on_read_alarm();
    /// With under_way_.cancel set by the caller: cancels the call with `status`, then lets the
    /// finish proceed.
    void cancel_call(const grpc::Status& status);

    ServerCore& core_;
    grpc::CallbackServerContext* context_;
    std::shared_ptr<StreamSession> self_;  // keeps the reactor alive until OnDone
    const std::uint64_t id_;
    const Clock::time_point started_;
    std::string peer_;

    grpc::ByteBuffer request_buffer_;  // the one read in flight
    v1::StreamRequest request_;        // its parsed contents

    // Guards everything below. Held only to move data and flags, never while calling into
    // gRPC or running a render or an encode; while holding it the session takes only the
    // admission, scene registry and worker pool locks (see ServerCore for the lock order).
    std::mutex mutex_;
    Phase phase_ = Phase::awaiting_open;
    grpc::Status finish_status_;  // from finishing on: what the stream ends with
    UnderWay under_way_;
    SessionSetup setup_;
    std::unique_ptr<Admission::Ticket> ticket_;
    std::unique_ptr<SceneRegistry::Lease> lease_;
    // Set at open, before the renderer is made, and kept (read by workers without mutex_
    // after that); released before the lease and the ticket.
    std::unique_ptr<DevicePlacement::Seat> seat_;
    std::unique_ptr<Renderer> renderer_;  // used by one render task at a time
    bool renderer_reusable_ = true;       // no frame failed or outgrew the memory limit

    std::optional<PendingPose> pending_;  // the newest pose not yet taken by a render task
    std::uint64_t last_request_sequence_ = 0;
    std::uint64_t last_ack_ = 0;
    std::deque<std::uint64_t> unacked_;  // frames rendered (or rendering) and not acknowledged
    bool reads_done_ = false;            // the client half-closed (or the call broke)
    bool message_read_ = false;          // any message arrived, valid or not
    bool render_busy_ = false;           // a render task is queued or running
    int encoding_ = 0;                   // frames being rendered for encoding, or encoded

    Clock::time_point write_started_;
    v1::Frame in_flight_;                // chosen for writing; cleared once serialized
    grpc::ByteBuffer in_flight_buffer_;  // owned by gRPC between StartWrite and OnWriteDone
    std::int64_t in_flight_bytes_ = 0;
    std::optional<v1::Frame> next_image_;  // latest wins
    // The view of next_image_ and of in_flight_, and the last image written with its bytes
    // (moved out of the written message, not copied). A request for exactly that pose, bit
    // for bit (a hovering drone, a paused viewer), is answered with those bytes unrendered.
    std::optional<Pose> next_image_pose_, in_flight_pose_, last_sent_pose_;
    std::string last_sent_data_;
    std::deque<v1::Frame> next_errors_;
    std::uint64_t newest_image_sequence_ = 0;  // newest image frame queued or written
    int buffered_frames_ = 0;
    std::int64_t buffered_bytes_ = 0;

    // This session's shares of the render and encoder pools (see scheduling above).
    WorkerPool::Flow render_flow_, encode_flow_;

    TokenBucket pose_rate_;  // while under_way_.postponed_read the next read waits on read_alarm_
    std::unique_ptr<grpc::Alarm> read_alarm_;

    // Session statistics (for Frame.stats and the close log line).
    struct Counters {
        std::uint64_t requests_received = 0, poses_coalesced = 0, frames_coalesced = 0, frames_sent = 0,
                      frame_errors = 0, frames_reused = 0, frame_requests_delayed = 0;
    };
    Counters stats_;
    double render_ms_sum_ = 0, encode_ms_sum_ = 0;
};

}  // namespace catgs::server
