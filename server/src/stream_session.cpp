// The reactor side of a stream session: the reactions, the pose-rate limit, the watchdog's
// cancel and the step planner. The workers' side is in stream_session_render.cpp.
#include "catgs/server/stream_session.hpp"

#include <grpc/grpc.h>
#include <spdlog/spdlog.h>

#include <algorithm>

#include "catgs/server/frame_messages.hpp"
#include "catgs/server/wire.hpp"

namespace catgs::server {
namespace {

/// Error frames are tiny, but a client sending bad requests faster than it reads must not
/// make the server queue without bound: beyond this many waiting, errors are only counted.
constexpr std::size_t kMaxQueuedErrorFrames = 8;
/// Image frames a session holds on the way out: one in gRPC's hands and one waiting, so that
/// the next frame is ready the moment the previous one leaves, and no more, so that a client
/// that stops reading costs at most that.
constexpr int kOutputFrames = 2;

const char* kind_name(const v1::StreamRequest& r) {
    switch (r.kind_case()) {
        case v1::StreamRequest::kOpen:
            return "open";
        case v1::StreamRequest::kFrame:
            return "frame";
        default:
            return "nothing";
    }
}

/// The checks of a frame request that need no session state: the flight plan's length first,
/// so that a long plan is refused before the enum walk visits each of its elements (with the
/// session's mutex held).
grpc::Status check_frame_structure(const v1::StreamRequest& request) {
    if (grpc::Status s = check_flight_plan_length(request.frame(), "frame"); !s.ok()) return s;
    return check_enum_values(request, "");
}

}  // namespace

StreamSession::StreamSession(ServerCore& core, grpc::CallbackServerContext* context)
    : core_(core),
      context_(context),
      id_(core.counters().next_session_id++),
      started_(Clock::now()),
      peer_(context->peer()),
      render_flow_(core.render_pool().open_flow()),
      encode_flow_(core.encode_pool().open_flow()),
      pose_rate_(core.options().limits.max_pose_rate, started_) {
    // The proxy's affinity key (deploy/envoy*.yaml), logged so that an operator can follow a
    // reconnecting viewer across sessions. gRPC admits only printable ASCII in header values;
    // the length is bounded here.
    const auto& metadata = context->client_metadata();
    if (auto it = metadata.find("x-catgs-session"); it != metadata.end())
        peer_ +=
            " (x-catgs-session " + std::string(it->second.data(), std::min<std::size_t>(it->second.size(), 128)) + ")";
    // The browser's address, for streams bridged by the web endpoint (in-process peers).
    if (auto it = metadata.find("x-catgs-web-peer"); it != metadata.end())
        peer_ += " (" + std::string(it->second.data(), std::min<std::size_t>(it->second.size(), 192)) + ")";
}

StreamSession::~StreamSession() {
    // Every buffered frame is gone with the session; keep the server-wide gauges exact.
    core_.counters().frames_buffered -= buffered_frames_;
    core_.counters().bytes_buffered -= buffered_bytes_;
    // No task uses the renderer any more. Pooled while the seat and lease still hold the scene,
    // unless a frame failed or outgrew the session memory limit (the arenas only grow).
    if (renderer_ && renderer_reusable_ && seat_ && lease_)
        core_.release_renderer(std::move(renderer_), lease_->scene(), *seat_);
}

void StreamSession::start() {
    self_ = shared_from_this();
    const grpc::Status added = core_.add_stream(self_);
    Actions actions;
    bool read = false;
    {
        std::lock_guard lock(mutex_);
        if (!added.ok())
            request_finish_locked(added);
        else if (grpc::Status auth = core_.authorize(context_); !auth.ok())
            request_finish_locked(auth);
        else if (core_.admission().draining())
            request_finish_locked(shutting_down_status());
        else
            read = true;
        plan_locked(actions);
    }
    run(actions);
    if (read) StartRead(&request_buffer_);
}

void StreamSession::drain(const grpc::Status& status) {
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        request_finish_locked(status);
        plan_locked(actions);
    }
    run(actions);
}

void StreamSession::OnReadDone(bool ok) {
    Actions actions;
    bool read_again = false, postpone = false;
    Clock::duration delay{0};
    {
        std::lock_guard lock(mutex_);
        if (!ok) {
            // The client half-closed (or the call broke): finish once the pipeline is empty.
            reads_done_ = true;
            if (phase_ == Phase::awaiting_open)
                request_finish_locked({grpc::StatusCode::INVALID_ARGUMENT,
                                       "open: the stream ended before its opening message (StreamRequest.open)"});
        } else if (!ending_locked()) {
            message_read_ = true;
            request_.Clear();
            if (!parse_message(request_buffer_, &request_)) {
                // Not a half-close: the client (or something on the path) sent bytes we cannot
                // trust; later messages of this stream cannot be trusted either.
                request_finish_locked(malformed_request("StreamRequest", request_buffer_));
            } else if (phase_ == Phase::awaiting_open) {
                if (!request_.has_open())
                    request_finish_locked(
                        {grpc::StatusCode::INVALID_ARGUMENT,
                         std::string("open: the first message of a stream must be StreamRequest.open, "
                                     "got ") +
                             kind_name(request_)});
                else if (grpc::Status fields = check_enum_values(request_, ""); !fields.ok())
                    request_finish_locked(fields);
                else
                    handle_open(request_.open());
            } else {
                if (request_.has_frame()) {
                    handle_frame(request_.frame(), check_frame_structure(request_));
                } else {
                    ++stats_.requests_received;
                    error_frame_locked(0,
                                       {grpc::StatusCode::INVALID_ARGUMENT,
                                        request_.has_open() ? "open: the session is already open; send frame requests"
                                                            : "kind: empty StreamRequest (set open or frame)"});
                }
                delay = pose_rate_.take(Clock::now());
            }
            read_again = !ending_locked();
            if (read_again && delay > Clock::duration::zero()) {
                read_again = false;
                postpone = under_way_.postponed_read = true;
                ++stats_.frame_requests_delayed;
            }
        }
        request_buffer_.Clear();
        plan_locked(actions);
    }
    run(actions);
    if (postpone) postpone_read(delay);
    if (read_again) StartRead(&request_buffer_);
}

// Called with under_way_.postponed_read set, outside the lock: the next read starts when the
// alarm fires.
void StreamSession::postpone_read(Clock::duration delay) {
    core_.counters().reads_delayed++;
    auto alarm = std::make_unique<grpc::Alarm>();
    // A weak reference: the alarm lives in the session, and while the read is postponed the
    // session cannot finish, so self_ keeps it alive until the alarm has fired.
    alarm->Set(
        std::chrono::system_clock::now() + std::chrono::duration_cast<std::chrono::system_clock::duration>(delay),
        [weak = weak_from_this()](bool) {
            if (auto self = weak.lock()) self->on_read_alarm();
        });
    std::unique_ptr<grpc::Alarm> previous;  // fired long ago; destroyed outside the lock
    std::lock_guard lock(mutex_);
    previous = std::move(read_alarm_);
    read_alarm_ = std::move(alarm);
}

void StreamSession::on_read_alarm() {
    Actions actions;
    bool read = false;
    {
        std::lock_guard lock(mutex_);
        if (!ending_locked()) {
            read = true;  // postponed_read stays set, so nobody finishes before StartRead
        } else {
            under_way_.postponed_read = false;
            plan_locked(actions);
        }
    }
    if (read) {
        StartRead(&request_buffer_);
        std::lock_guard lock(mutex_);
        under_way_.postponed_read = false;
        plan_locked(actions);
    }
    run(actions);
}

void StreamSession::cancel(const grpc::Status& status) {
    grpc::Status decided;
    {
        std::lock_guard lock(mutex_);
        if (phase_ == Phase::finished || under_way_.cancel) return;
        request_finish_locked(status);
        decided = finish_status_;
        under_way_.cancel = true;  // Finish waits: the call stays alive for cancel_call
    }
    cancel_call(decided);
}

bool StreamSession::cancel_if_stalled(Clock::time_point now, std::chrono::milliseconds timeout) {
    double stalled_ms = 0;
    grpc::Status decided;
    {
        std::lock_guard lock(mutex_);
        if (phase_ == Phase::finished || under_way_.cancel || !under_way_.write || now - write_started_ <= timeout)
            return false;
        stalled_ms = std::chrono::duration<double, std::milli>(now - write_started_).count();
        request_finish_locked(
            {grpc::StatusCode::DEADLINE_EXCEEDED, "stall-timeout: the client took no frame off the wire for " +
                                                      std::to_string(static_cast<long>(stalled_ms)) + " ms (limit " +
                                                      std::to_string(timeout.count()) + " ms)"});
        decided = finish_status_;
        under_way_.cancel = true;
    }
    spdlog::warn(
        "session {} ({}): a frame has waited {:.0f} ms for the client to read it; cancelling the stream "
        "(stall watchdog)",
        id_, peer_, stalled_ms);
    // Counted before the status leaves, so a client that sees it sees the count too.
    core_.counters().streams_stalled++;
    cancel_call(decided);
    return true;
}

void StreamSession::cancel_call(const grpc::Status& status) {
    // Finish would queue the trailers behind the frame stuck in flow control, where they never
    // pass a client that does not read. A cancel carrying a status makes gRPC's HTTP/2
    // transport send the trailers (status and message) at once, ahead of the stream's data and
    // outside its flow-control window, then RST_STREAM. The pending write then completes with
    // ok = false and Finish follows; the status it sends no longer reaches the wire.
    grpc_call_cancel_with_status(context_->c_call(), static_cast<grpc_status_code>(status.error_code()),
                                 status.error_message().c_str(), nullptr);
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        under_way_.cancel = false;
        plan_locked(actions);
    }
    run(actions);
}

bool StreamSession::finish_if_not_opened(Clock::time_point now, std::chrono::milliseconds timeout) {
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        if (phase_ != Phase::awaiting_open || now - started_ <= timeout) return false;
        // No write is under way before the session opens: Finish's trailers leave at once.
        request_finish_locked(
            {grpc::StatusCode::DEADLINE_EXCEEDED, "open-timeout: no opening message (StreamRequest.open) within " +
                                                      std::to_string(timeout.count()) + " ms of the call's start"});
        plan_locked(actions);
    }
    spdlog::info("session {} ({}): no opening message within {} ms; finishing the call", id_, peer_, timeout.count());
    // Counted before the status leaves, so a client that sees it sees the count too.
    core_.counters().open_timeouts++;
    run(actions);
    return true;
}

// mutex_ held.
void StreamSession::handle_open(const v1::SessionConfig& config) {
    grpc::Status status = parse_session_config(config, core_.options().limits, "open", &setup_);
    if (status.ok()) status = core_.admission().admit(&ticket_);
    if (status.ok()) status = acquire_scene(core_.scenes(), setup_.scene_id, "open", &lease_);
    if (status.ok()) status = core_.placement().place(setup_.scene_id, &seat_);
    if (!status.ok()) {
        request_finish_locked(status);
        return;
    }
    phase_ = Phase::opening;
    core_.counters().sessions_opened++;
    // Creating the renderer (and on CUDA uploading the scene) is slow: a worker does it.
    if (!core_.render_pool().post(render_flow_, [self = shared_from_this()] { self->initialise(); }))
        request_finish_locked(shutting_down_status());
    if (!config.client_name().empty()) peer_ += " (" + config.client_name() + ")";
}

// mutex_ held.
void StreamSession::handle_frame(const v1::FrameRequest& request, const grpc::Status& structure) {
    ++stats_.requests_received;
    // The acknowledgement counts even when the rest of the request is bad.
    last_ack_ = std::max(last_ack_, request.last_received_sequence());
    while (!unacked_.empty() && unacked_.front() <= last_ack_) unacked_.pop_front();

    FrameSetup frame;
    grpc::Status status;
    if (request.sequence() == 0)
        status = {grpc::StatusCode::INVALID_ARGUMENT, "frame.sequence: must be >= 1"};
    else if (request.sequence() <= last_request_sequence_)
        status = {grpc::StatusCode::INVALID_ARGUMENT, "frame.sequence: " + std::to_string(request.sequence()) +
                                                          " is not greater than the previous " +
                                                          std::to_string(last_request_sequence_)};
    else if (!structure.ok())
        status = structure;
    else
        status = parse_frame_request(request, setup_.intrinsics, "frame", &frame);
    if (!status.ok()) {
        error_frame_locked(request.sequence(), status);
        return;
    }
    last_request_sequence_ = frame.sequence;
    if (pending_) {
        // Latest wins: the client moved on before this pose could be rendered.
        ++stats_.poses_coalesced;
        core_.counters().poses_coalesced++;
    }
    pending_ = PendingPose{std::move(frame), Clock::now()};
}

// mutex_ held.
void StreamSession::error_frame_locked(std::uint64_t sequence, const grpc::Status& status) {
    ++stats_.frame_errors;
    core_.counters().frame_errors++;
    if (next_errors_.size() >= kMaxQueuedErrorFrames) return;
    next_errors_.push_back(error_frame(sequence, status));
}

void StreamSession::OnWriteDone(bool ok) {
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        under_way_.write = false;
        in_flight_bytes_ = 0;
        if (!ok) request_finish_locked({grpc::StatusCode::CANCELLED, "write failed: the client went away"});
        plan_locked(actions);
    }
    run(actions);
}

void StreamSession::OnCancel() {
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        request_finish_locked({grpc::StatusCode::CANCELLED, "cancelled"});
        plan_locked(actions);
    }
    run(actions);
}

void StreamSession::OnDone() {
    const double seconds = std::chrono::duration<double>(Clock::now() - started_).count();
    {
        std::lock_guard lock(mutex_);
        const double frames = static_cast<double>(stats_.frames_sent);
        // A call that sent nothing (refused at max-streams, ended by the open timeout, one of a
        // flood of idle calls) is logged at debug: a hostile client must not fill the log.
        // ServerStats counts those.
        const auto level = message_read_ ? spdlog::level::info : spdlog::level::debug;
        spdlog::log(
            level,
            "session {} closed: {} '{}' after {:.1f} s; {} requests, {} frames ({:.1f}/s), {} poses and {} "
            "frames coalesced, {} re-sent for a repeated pose, {} errors, render {:.1f} ms, encode {:.1f} ms (means)",
            id_, static_cast<int>(finish_status_.error_code()), finish_status_.error_message(), seconds,
            stats_.requests_received, stats_.frames_sent, seconds > 0 ? frames / seconds : 0.0, stats_.poses_coalesced,
            stats_.frames_coalesced, stats_.frames_reused, stats_.frame_errors,
            frames > 0 ? render_ms_sum_ / frames : 0.0, frames > 0 ? encode_ms_sum_ / frames : 0.0);
    }
    core_.remove_stream(this);
    // Last use of `this` from gRPC. Workers may still hold references; the session (its
    // renderer, admission ticket and scene lease) goes when the last of them returns.
    std::shared_ptr<StreamSession> keep = std::move(self_);
}

// mutex_ held. The first end decided wins; later ones are ignored.
void StreamSession::request_finish_locked(const grpc::Status& status) {
    if (ending_locked()) return;
    phase_ = Phase::finishing;
    finish_status_ = status;
    // Nothing queued will be sent any more.
    pending_.reset();
    next_image_.reset();
    next_errors_.clear();
}

// mutex_ held.
void StreamSession::drop_unacked_locked(std::uint64_t sequence) {
    auto it = std::find(unacked_.begin(), unacked_.end(), sequence);
    if (it != unacked_.end()) unacked_.erase(it);
}

// mutex_ held.
void StreamSession::set_buffered_locked(int frames, std::int64_t bytes) {
    auto& c = core_.counters();
    c.frames_buffered += frames - buffered_frames_;
    c.bytes_buffered += bytes - buffered_bytes_;
    buffered_frames_ = frames;
    buffered_bytes_ = bytes;
    std::int64_t peak = c.peak_session_buffered.load();
    while (frames > peak && !c.peak_session_buffered.compare_exchange_weak(peak, frames)) {
    }
}

// mutex_ held.
bool StreamSession::served_locked() const {
    const bool pipeline_empty =
        !render_busy_ && !pending_ && encoding_ == 0 && !under_way_.write && !next_image_ && next_errors_.empty();
    return phase_ == Phase::open && reads_done_ && pipeline_empty;
}

// mutex_ held. A frame written now counts as taking its place until OnWriteDone (the write
// completes when the transport has taken it, i.e. when flow control lets it through).
bool StreamSession::room_for_frame_locked() const {
    const int taken = (under_way_.write ? 1 : 0) + (next_image_ ? 1 : 0) + encoding_;
    return taken < kOutputFrames;
}

// mutex_ held. Decides the next steps; run() performs them after the lock is released.
void StreamSession::plan_locked(Actions& actions) {
    if (served_locked()) request_finish_locked(grpc::Status::OK);
    if (phase_ == Phase::finishing) {
        if (under_way_.postponed_read) actions.cancel_alarm = true;
        if (ready_to_finish_locked()) {
            phase_ = Phase::finished;
            actions.finish = finish_status_;
        }
    } else if (phase_ != Phase::finished) {
        // After the client half-closed it can no longer acknowledge: its last pose renders
        // regardless of credit.
        const bool credit = reads_done_ || static_cast<int>(unacked_.size()) < setup_.max_unacked_frames;
        if (phase_ == Phase::open && !render_busy_ && pending_ && credit && room_for_frame_locked()) {
            render_busy_ = true;
            actions.schedule_render = true;
        }
        if (!under_way_.write) choose_write_locked(actions);
    }
    int frames = (under_way_.write ? 1 : 0) + (next_image_ ? 1 : 0) + static_cast<int>(next_errors_.size());
    std::int64_t bytes = (under_way_.write ? in_flight_bytes_ : 0) +
                         (next_image_ ? static_cast<std::int64_t>(next_image_->data().size()) : 0);
    set_buffered_locked(frames, bytes);
}

// mutex_ held, no write under way: moves the next frame, if any, into in_flight_.
void StreamSession::choose_write_locked(Actions& actions) {
    // Frames leave in request order: an error frame for an older request first.
    const bool error_first =
        !next_errors_.empty() && (!next_image_ || next_errors_.front().sequence() < next_image_->sequence());
    if (error_first) {
        in_flight_ = std::move(next_errors_.front());
        next_errors_.pop_front();
    } else if (next_image_) {
        in_flight_ = std::move(*next_image_);
        next_image_.reset();
        in_flight_pose_ = std::move(next_image_pose_);
        next_image_pose_.reset();
        ++stats_.frames_sent;
        core_.counters().frames_sent++;
    } else {
        return;
    }
    auto* out = in_flight_.mutable_stats();
    out->set_requests_received(stats_.requests_received);
    out->set_poses_coalesced(stats_.poses_coalesced);
    out->set_frames_coalesced(stats_.frames_coalesced);
    out->set_frames_sent(stats_.frames_sent);
    out->set_frame_errors(stats_.frame_errors);
    out->set_frames_reused(stats_.frames_reused);
    out->set_frame_requests_delayed(stats_.frame_requests_delayed);
    under_way_.write = true;
    write_started_ = Clock::now();
    in_flight_bytes_ = static_cast<std::int64_t>(in_flight_.data().size());
    actions.write = true;
}

void StreamSession::run(const Actions& actions) {
    if (actions.schedule_render &&
        !core_.render_pool().post(render_flow_, [self = shared_from_this()] { self->render_next(); })) {
        std::lock_guard lock(mutex_);
        render_busy_ = false;
    }
    if (actions.cancel_alarm) {
        std::unique_ptr<grpc::Alarm> alarm;
        {
            std::lock_guard lock(mutex_);
            alarm = std::move(read_alarm_);
        }
        if (alarm) alarm->Cancel();  // its callback runs (ok = false) and lets Finish proceed
    }
    if (actions.write) {
        // in_flight_ is ours until OnWriteDone (under_way_.write was set with it): serialize
        // it outside the lock, then let its copy of the image go.
        serialize_message(in_flight_, &in_flight_buffer_);
        if (!in_flight_.has_error()) {
            // Keep the written image's bytes for a repeated pose; the rest of it goes.
            std::lock_guard lock(mutex_);
            last_sent_data_.swap(*in_flight_.mutable_data());
            last_sent_pose_ = std::move(in_flight_pose_);
            in_flight_pose_.reset();
        }
        in_flight_.Clear();
        StartWrite(&in_flight_buffer_, grpc::WriteOptions().set_no_compression());
    }
    if (actions.finish) Finish(*actions.finish);
}

}  // namespace catgs::server
