#include "catgs/server/stream_session.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "catgs/server/encoder.hpp"
#include "catgs/server/wire.hpp"

namespace catgs::server {
namespace {

/// Error frames are tiny, but a client sending bad requests faster than it reads must not
/// make the server queue without bound: beyond this many waiting, errors are only counted.
constexpr std::size_t kMaxQueuedErrorFrames = 8;

/// Bit-for-bit equality: a client that repeats a pose sends the same doubles.
bool same_pose(const Pose& a, const Pose& b) { return a.rotation == b.rotation && a.translation == b.translation; }

double ms_between(StreamSession::Clock::time_point a, StreamSession::Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

const char* kind_name(const v1::StreamRequest& r) {
    switch (r.kind_case()) {
    case v1::StreamRequest::kOpen: return "open";
    case v1::StreamRequest::kFrame: return "frame";
    default: return "nothing";
    }
}

}  // namespace

StreamSession::StreamSession(ServerCore& core, grpc::CallbackServerContext* context)
    : core_(core), context_(context), id_(core.counters().next_session_id++), started_(Clock::now()),
      peer_(context->peer()) {
    // The proxy's affinity key (deploy/envoy*.yaml), logged so that an operator can follow a
    // reconnecting viewer across sessions. gRPC admits only printable ASCII in header values;
    // the length is bounded here.
    const auto& metadata = context->client_metadata();
    if (auto it = metadata.find("x-catgs-session"); it != metadata.end())
        peer_ += " (x-catgs-session " + std::string(it->second.data(), std::min<std::size_t>(it->second.size(), 128)) + ")";
    tokens_ = std::max(1.0, core_.options().limits.max_pose_rate);  // a full bucket: one second's burst
    tokens_at_ = started_;
}

StreamSession::~StreamSession() {
    // Every buffered frame is gone with the session; keep the server-wide gauges exact.
    core_.counters().frames_buffered -= buffered_frames_;
    core_.counters().bytes_buffered -= buffered_bytes_;
}

void StreamSession::start() {
    self_ = shared_from_this();
    core_.add_stream(self_);
    Actions actions;
    bool read = false;
    {
        std::lock_guard lock(mutex_);
        if (grpc::Status auth = core_.authorize(context_); !auth.ok())
            request_finish_locked(auth);
        else if (core_.admission().draining())
            request_finish_locked({grpc::StatusCode::UNAVAILABLE, "server is shutting down: reconnect to another instance"});
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
        } else if (!finish_wanted_ && !finished_) {
            request_.Clear();
            if (!parse_message(request_buffer_, &request_)) {
                // Not a half-close: the client (or something on the path) sent bytes we cannot
                // trust; later messages of this stream cannot be trusted either.
                request_finish_locked(malformed_request("StreamRequest", request_buffer_));
            } else if (phase_ == Phase::awaiting_open) {
                if (request_.has_open())
                    handle_open(request_.open());
                else
                    request_finish_locked({grpc::StatusCode::INVALID_ARGUMENT,
                                           std::string("open: the first message of a stream must be StreamRequest.open, "
                                                       "got ") + kind_name(request_)});
            } else {
                if (request_.has_frame()) {
                    handle_frame(request_.frame());
                } else {
                    ++stats_.requests_received;
                    error_frame_locked(0, {grpc::StatusCode::INVALID_ARGUMENT,
                                           request_.has_open() ? "open: the session is already open; send frame requests"
                                                               : "kind: empty StreamRequest (set open or frame)"});
                }
                delay = take_token_locked(Clock::now());
            }
            read_again = !finish_wanted_;
            if (read_again && delay > Clock::duration::zero()) {
                read_again = false;
                postpone = read_delayed_ = true;
            }
        }
        request_buffer_.Clear();
        plan_locked(actions);
    }
    run(actions);
    if (postpone) postpone_read(delay);
    if (read_again) StartRead(&request_buffer_);
}

// mutex_ held.
StreamSession::Clock::duration StreamSession::take_token_locked(Clock::time_point now) {
    const double rate = core_.options().limits.max_pose_rate;
    if (!(rate > 0)) return Clock::duration::zero();
    const double burst = std::max(1.0, rate);
    tokens_ = std::min(burst, tokens_ + rate * std::chrono::duration<double>(now - tokens_at_).count());
    tokens_at_ = now;
    tokens_ -= 1;
    if (tokens_ >= 1) return Clock::duration::zero();
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>((1 - tokens_) / rate));
}

// Called with read_delayed_ set, outside the lock: the next read starts when the alarm fires.
void StreamSession::postpone_read(Clock::duration delay) {
    core_.counters().reads_delayed++;
    auto alarm = std::make_unique<grpc::Alarm>();
    // A weak reference: the alarm lives in the session, and while read_delayed_ is set the
    // session cannot finish, so self_ keeps it alive until the alarm has fired.
    alarm->Set(std::chrono::system_clock::now() + std::chrono::duration_cast<std::chrono::system_clock::duration>(delay),
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
        if (!finish_wanted_ && !finished_) {
            read = true;  // read_delayed_ stays set, so nobody finishes before StartRead
        } else {
            read_delayed_ = false;
            plan_locked(actions);
        }
    }
    if (read) {
        StartRead(&request_buffer_);
        std::lock_guard lock(mutex_);
        read_delayed_ = false;
        plan_locked(actions);
    }
    run(actions);
}

bool StreamSession::cancel_if_stalled(Clock::time_point now, std::chrono::milliseconds timeout) {
    double stalled_ms = 0;
    {
        std::lock_guard lock(mutex_);
        if (finished_ || cancelling_ || !write_in_flight_ || now - write_started_ <= timeout) return false;
        stalled_ms = std::chrono::duration<double, std::milli>(now - write_started_).count();
        // Finish waits for cancelling_: the call stays alive for TryCancel below.
        cancelling_ = true;
        request_finish_locked({grpc::StatusCode::DEADLINE_EXCEEDED,
                               "stall-timeout: the client took no frame off the wire for " +
                                   std::to_string(static_cast<long>(stalled_ms)) + " ms"});
    }
    spdlog::warn("session {} ({}): a frame has waited {:.0f} ms for the client to read it; cancelling the stream "
                 "(stall watchdog)",
                 id_, peer_, stalled_ms);
    // Trailers cannot pass a stream the client does not read: cancelling (RST_STREAM) is the
    // only way to end it. The pending write then completes with ok = false.
    context_->TryCancel();
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        cancelling_ = false;
        plan_locked(actions);
    }
    run(actions);
    return true;
}

// mutex_ held.
void StreamSession::handle_open(const v1::SessionConfig& config) {
    grpc::Status status = parse_session_config(config, core_.options().limits, "open", &setup_);
    if (status.ok()) status = core_.admission().admit(&ticket_);
    if (status.ok()) status = acquire_scene(core_.scenes(), setup_.scene_id, "open", &lease_);
    if (!status.ok()) {
        request_finish_locked(status);
        return;
    }
    phase_ = Phase::opening;
    core_.counters().sessions_opened++;
    // Creating the renderer (and on CUDA uploading the scene) is slow: a worker does it.
    if (!core_.render_pool().post([self = shared_from_this()] { self->initialise(); }))
        request_finish_locked({grpc::StatusCode::UNAVAILABLE, "server is shutting down: reconnect to another instance"});
    if (!config.client_name().empty()) peer_ += " (" + config.client_name() + ")";
}

// mutex_ held.
void StreamSession::handle_frame(const v1::FrameRequest& request) {
    ++stats_.requests_received;
    // The acknowledgement counts even when the rest of the request is bad.
    last_ack_ = std::max(last_ack_, request.last_received_sequence());
    while (!unacked_.empty() && unacked_.front() <= last_ack_) unacked_.pop_front();

    FrameSetup frame;
    grpc::Status status;
    if (request.sequence() == 0)
        status = {grpc::StatusCode::INVALID_ARGUMENT, "frame.sequence: must be >= 1"};
    else if (request.sequence() <= last_request_sequence_)
        status = {grpc::StatusCode::INVALID_ARGUMENT,
                  "frame.sequence: " + std::to_string(request.sequence()) + " is not greater than the previous " +
                      std::to_string(last_request_sequence_)};
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
    v1::Frame frame;
    frame.set_sequence(sequence);
    frame.mutable_error()->set_code(static_cast<int>(status.error_code()));
    frame.mutable_error()->set_message(status.error_message());
    next_errors_.push_back(std::move(frame));
}

void StreamSession::initialise() {
    std::unique_ptr<Renderer> renderer;
    std::string error;
    bool out_of_memory = false;
    try {
        renderer = core_.make_session_renderer();
        renderer->set_scene(lease_->scene());  // CUDA: uploads the scene unless another session did
    } catch (const std::exception& e) {
        error = e.what();
        out_of_memory = is_out_of_memory(e);
        if (error.empty()) error = "unknown error";
    }
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        if (!error.empty()) {
            renderer.reset();  // frees whatever it had allocated before the failure
            if (out_of_memory) {
                core_.counters().out_of_memory++;
                spdlog::warn("session {}: out of memory loading scene {} for rendering: {}", id_, setup_.scene_id, error);
                request_finish_locked({grpc::StatusCode::RESOURCE_EXHAUSTED,
                                       "out-of-memory: the server cannot hold scene '" + setup_.scene_id +
                                           "' for another session (" + error + "); retry later or on another server"});
            } else {
                spdlog::error("session {}: cannot create a renderer: {}", id_, error);
                request_finish_locked({grpc::StatusCode::INTERNAL, "cannot create a renderer: " + error});
            }
        } else {
            renderer_ = std::move(renderer);
            phase_ = Phase::open;
            const Intrinsics& k = setup_.intrinsics;
            spdlog::info("session {} opened by {}: scene {}, {}x{} fx {:.1f}, {}{}, {}, max {} unacked", id_, peer_,
                         setup_.scene_id, k.width, k.height, k.fx, format_name(setup_.encode.format),
                         setup_.encode.format == Format::jpeg ? " q" + std::to_string(setup_.encode.jpeg_quality) : "",
                         renderer_->name(), setup_.max_unacked_frames);
        }
        plan_locked(actions);
    }
    run(actions);
}

void StreamSession::render_next() {
    PendingPose pose;
    Actions actions;
    std::optional<std::string> resend;  // the bytes of the last frame, when its pose repeats
    {
        std::lock_guard lock(mutex_);
        if (finish_wanted_ || finished_ || !pending_ || phase_ != Phase::open) {
            render_busy_ = false;
            plan_locked(actions);
            pose.frame.sequence = 0;
        } else {
            pose = std::move(*pending_);
            pending_.reset();
            unacked_.push_back(pose.frame.sequence);
            ++encoding_;
            if (last_sent_pose_ && same_pose(*last_sent_pose_, pose.frame.camera.pose)) {
                resend = last_sent_data_;
                render_busy_ = false;
                plan_locked(actions);  // the next pose may render meanwhile
            }
        }
    }
    if (resend) {
        run(actions);
        resend_last(std::move(pose), std::move(*resend));
        return;
    }
    if (pose.frame.sequence == 0) {
        run(actions);
        return;
    }

    const Clock::time_point begin = Clock::now();
    ImageRGB8 image;
    FrameStats frame_stats;
    std::string error;
    bool out_of_memory = false;
    try {
        frame_stats = renderer_->render_rgb8(pose.frame.camera, setup_.options, image,
                                             pose.frame.hints ? &*pose.frame.hints : nullptr);
    } catch (const std::exception& e) {
        error = e.what();
        out_of_memory = is_out_of_memory(e);
        if (error.empty()) error = "unknown error";
    }
    const Clock::time_point rendered = Clock::now();
    const std::uint64_t max_bytes = core_.options().limits.max_session_bytes;
    const bool over_limit = error.empty() && max_bytes > 0 && frame_stats.arena_bytes > max_bytes;
    {
        // The renderer is free again: the next pose may render while this one is encoded.
        std::lock_guard lock(mutex_);
        render_busy_ = false;
        render_ms_sum_ += ms_between(begin, rendered);
        if (!error.empty() || over_limit) {
            --encoding_;
            drop_unacked_locked(pose.frame.sequence);
            const Intrinsics& k = setup_.intrinsics;
            const std::string size = std::to_string(k.width) + "x" + std::to_string(k.height);
            if (over_limit) {
                // The arenas are grow-only: the session would keep holding this memory.
                core_.counters().out_of_memory++;
                request_finish_locked({grpc::StatusCode::RESOURCE_EXHAUSTED,
                                       "max-session-memory: rendering scene '" + setup_.scene_id + "' at " + size +
                                           " needed " + std::to_string(frame_stats.arena_bytes) +
                                           " bytes of renderer memory; this server allows " +
                                           std::to_string(max_bytes) + " per session; lower the resolution"});
            } else if (out_of_memory) {
                // Ending the session frees its buffers; an error frame would leave them held.
                core_.counters().out_of_memory++;
                spdlog::warn("session {}: out of memory rendering {}: {}", id_, size, error);
                request_finish_locked({grpc::StatusCode::RESOURCE_EXHAUSTED,
                                       "out-of-memory: rendering at " + size + " failed (" + error +
                                           "); lower the resolution, retry later or use another server"});
            } else {
                error_frame_locked(pose.frame.sequence, {grpc::StatusCode::INTERNAL, "render failed: " + error});
            }
        }
        plan_locked(actions);
    }
    run(actions);
    if (!error.empty() || over_limit) return;

    v1::Frame frame;
    frame.set_sequence(pose.frame.sequence);
    frame.set_encoding(to_proto(setup_.encode.format));
    frame.set_width(static_cast<std::uint32_t>(image.width));
    frame.set_height(static_cast<std::uint32_t>(image.height));
    frame.set_client_timestamp_us(pose.frame.client_timestamp_us);
    auto* timings = frame.mutable_timings();
    timings->set_queue_ms(ms_between(pose.received, begin));
    timings->set_render_ms(ms_between(begin, rendered));
    auto* cache = frame.mutable_cache();
    cache->set_key_frame(frame_stats.key_frame);
    cache->set_window(static_cast<std::uint32_t>(frame_stats.window));
    cache->set_render_length(frame_stats.pairs);
    cache->set_visible(frame_stats.visible);
    cache->set_split_k(frame_stats.split_k);
    const Clock::time_point received = pose.received;
    const bool posted = core_.encode_pool().post(
        [self = shared_from_this(), image = std::move(image), frame = std::move(frame), received,
         view = pose.frame.camera.pose]() mutable {
            const Clock::time_point start = Clock::now();
            try {
                encode_image(image, self->setup_.encode, *frame.mutable_data());
            } catch (const std::exception& e) {
                frame.clear_data();
                frame.mutable_error()->set_code(grpc::StatusCode::INTERNAL);
                frame.mutable_error()->set_message(std::string("encoding failed: ") + e.what());
            }
            const Clock::time_point done = Clock::now();
            frame.mutable_timings()->set_encode_ms(ms_between(start, done));
            frame.mutable_timings()->set_total_ms(ms_between(received, done));
            self->deliver(std::move(frame), true, &view);
        });
    if (!posted) {
        std::lock_guard lock(mutex_);
        --encoding_;
        drop_unacked_locked(pose.frame.sequence);
    }
}

void StreamSession::resend_last(PendingPose pose, std::string data) {
    // The session's image size and encoding are fixed, so the same pose is the same frame.
    v1::Frame frame;
    frame.set_sequence(pose.frame.sequence);
    frame.set_encoding(to_proto(setup_.encode.format));
    frame.set_width(static_cast<std::uint32_t>(setup_.intrinsics.width));
    frame.set_height(static_cast<std::uint32_t>(setup_.intrinsics.height));
    frame.set_client_timestamp_us(pose.frame.client_timestamp_us);
    *frame.mutable_data() = std::move(data);
    const Clock::time_point now = Clock::now();
    frame.mutable_timings()->set_queue_ms(ms_between(pose.received, now));
    frame.mutable_timings()->set_total_ms(ms_between(pose.received, now));
    frame.mutable_cache()->set_reused_previous(true);
    {
        std::lock_guard lock(mutex_);
        ++stats_.frames_reused;
    }
    deliver(std::move(frame), true, &pose.frame.camera.pose);
}

void StreamSession::deliver(v1::Frame frame, bool image, const Pose* pose) {
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        if (image) --encoding_;
        const std::uint64_t sequence = frame.sequence();
        if (finish_wanted_ || finished_) {
            drop_unacked_locked(sequence);
        } else if (frame.has_error()) {
            drop_unacked_locked(sequence);
            error_frame_locked(sequence, {static_cast<grpc::StatusCode>(frame.error().code()), frame.error().message()});
        } else if (sequence < newest_image_sequence_) {
            // Encoded out of order behind a newer frame: it is stale.
            ++stats_.frames_coalesced;
            core_.counters().frames_coalesced++;
            drop_unacked_locked(sequence);
        } else {
            encode_ms_sum_ += frame.timings().encode_ms();
            if (next_image_) {
                // The client has not taken the previous frame yet: latest wins.
                ++stats_.frames_coalesced;
                core_.counters().frames_coalesced++;
                drop_unacked_locked(next_image_->sequence());
            }
            next_image_ = std::move(frame);
            if (pose) next_image_pose_ = *pose;
            else next_image_pose_.reset();
            newest_image_sequence_ = sequence;
        }
        plan_locked(actions);
    }
    run(actions);
}

void StreamSession::OnWriteDone(bool ok) {
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        write_in_flight_ = false;
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
        spdlog::info("session {} closed: {} '{}' after {:.1f} s; {} requests, {} frames ({:.1f}/s), {} poses and {} "
                     "frames coalesced, {} re-sent for a repeated pose, {} errors, render {:.1f} ms, encode {:.1f} ms (means)",
                     id_, static_cast<int>(final_status_.error_code()), final_status_.error_message(), seconds,
                     stats_.requests_received, stats_.frames_sent, seconds > 0 ? frames / seconds : 0.0,
                     stats_.poses_coalesced, stats_.frames_coalesced, stats_.frames_reused, stats_.frame_errors,
                     frames > 0 ? render_ms_sum_ / frames : 0.0, frames > 0 ? encode_ms_sum_ / frames : 0.0);
    }
    core_.remove_stream(this);
    // Last use of `this` from gRPC. Workers may still hold references; the session (its
    // renderer, admission ticket and scene lease) goes when the last of them returns.
    std::shared_ptr<StreamSession> keep = std::move(self_);
}

// mutex_ held.
void StreamSession::request_finish_locked(const grpc::Status& status) {
    if (finish_wanted_ || finished_) return;
    finish_wanted_ = status;
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

// mutex_ held. Decides the next steps; run() performs them after the lock is released.
void StreamSession::plan_locked(Actions& actions) {
    if (!finished_) {
        const bool idle = !render_busy_ && !pending_ && encoding_ == 0 && !write_in_flight_ && !next_image_ &&
                          next_errors_.empty();
        if (!finish_wanted_ && reads_done_ && phase_ == Phase::open && idle) finish_wanted_ = grpc::Status::OK;
        if (finish_wanted_) {
            if (read_delayed_) actions.cancel_alarm = true;
            // Writes, postponed reads and watchdog cancels call into gRPC from outside a
            // reaction: Finish (after which the call may end) waits for them.
            if (!write_in_flight_ && !read_delayed_ && !cancelling_) {
                finished_ = true;
                final_status_ = *finish_wanted_;
                actions.finish = *finish_wanted_;
            }
        } else {
            // After the client half-closed it can no longer acknowledge: its last pose renders
            // regardless of credit.
            const bool credit = reads_done_ || static_cast<int>(unacked_.size()) < setup_.max_unacked_frames;
            if (phase_ == Phase::open && !render_busy_ && pending_ && credit) {
                render_busy_ = true;
                actions.schedule_render = true;
            }
            if (!write_in_flight_) {
                // Frames leave in request order: an error frame for an older request first.
                const bool error_first = !next_errors_.empty() &&
                                         (!next_image_ || next_errors_.front().sequence() < next_image_->sequence());
                bool chosen = false;
                if (error_first) {
                    in_flight_ = std::move(next_errors_.front());
                    next_errors_.pop_front();
                    chosen = true;
                } else if (next_image_) {
                    in_flight_ = std::move(*next_image_);
                    next_image_.reset();
                    in_flight_pose_ = std::move(next_image_pose_);
                    next_image_pose_.reset();
                    ++stats_.frames_sent;
                    core_.counters().frames_sent++;
                    chosen = true;
                }
                if (chosen) {
                    auto* out = in_flight_.mutable_stats();
                    out->set_requests_received(stats_.requests_received);
                    out->set_poses_coalesced(stats_.poses_coalesced);
                    out->set_frames_coalesced(stats_.frames_coalesced);
                    out->set_frames_sent(stats_.frames_sent);
                    out->set_frame_errors(stats_.frame_errors);
                    out->set_frames_reused(stats_.frames_reused);
                    write_in_flight_ = true;
                    write_started_ = Clock::now();
                    in_flight_bytes_ = static_cast<std::int64_t>(in_flight_.data().size());
                    actions.write = true;
                }
            }
        }
    }
    int frames = (write_in_flight_ ? 1 : 0) + (next_image_ ? 1 : 0) + static_cast<int>(next_errors_.size());
    std::int64_t bytes = (write_in_flight_ ? in_flight_bytes_ : 0) +
                         (next_image_ ? static_cast<std::int64_t>(next_image_->data().size()) : 0);
    set_buffered_locked(frames, bytes);
}

void StreamSession::run(const Actions& actions) {
    if (actions.schedule_render && !core_.render_pool().post([self = shared_from_this()] { self->render_next(); })) {
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
        // in_flight_ is ours until OnWriteDone (write_in_flight_ was set with it): serialize
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
