#include "catgs/server/stream_session.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "catgs/server/encoder.hpp"

namespace catgs::server {
namespace {

/// Error frames are tiny, but a client sending bad requests faster than it reads must not
/// make the server queue without bound: beyond this many waiting, errors are only counted.
constexpr std::size_t kMaxQueuedErrorFrames = 8;

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
      peer_(context->peer()) {}

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
    if (read) StartRead(&request_);
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
    bool read_again = false;
    {
        std::lock_guard lock(mutex_);
        if (!ok) {
            // The client half-closed (or the call broke): finish once the pipeline is empty.
            reads_done_ = true;
            if (phase_ == Phase::awaiting_open)
                request_finish_locked({grpc::StatusCode::INVALID_ARGUMENT,
                                       "open: the stream ended before its opening message (StreamRequest.open)"});
        } else if (!finish_wanted_ && !finished_) {
            if (phase_ == Phase::awaiting_open) {
                if (request_.has_open())
                    handle_open(request_.open());
                else
                    request_finish_locked({grpc::StatusCode::INVALID_ARGUMENT,
                                           std::string("open: the first message of a stream must be StreamRequest.open, "
                                                       "got ") + kind_name(request_)});
            } else if (request_.has_frame()) {
                handle_frame(request_.frame());
            } else {
                ++stats_.requests_received;
                error_frame_locked(0, {grpc::StatusCode::INVALID_ARGUMENT,
                                       request_.has_open() ? "open: the session is already open; send frame requests"
                                                           : "kind: empty StreamRequest (set open or frame)"});
            }
            read_again = !finish_wanted_;
        }
        plan_locked(actions);
    }
    run(actions);
    if (read_again) StartRead(&request_);
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
    try {
        renderer = core_.make_session_renderer();
        renderer->set_scene(lease_->scene());
    } catch (const std::exception& e) {
        error = e.what();
    }
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        if (!error.empty()) {
            spdlog::error("session {}: cannot create a renderer: {}", id_, error);
            request_finish_locked({grpc::StatusCode::INTERNAL, "cannot create a renderer: " + error});
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
        }
    }
    if (pose.frame.sequence == 0) {
        run(actions);
        return;
    }

    const Clock::time_point begin = Clock::now();
    ImageRGB8 image;
    FrameStats frame_stats;
    std::string error;
    try {
        frame_stats = renderer_->render_rgb8(pose.frame.camera, setup_.options, image,
                                             pose.frame.hints ? &*pose.frame.hints : nullptr);
    } catch (const std::exception& e) {
        error = e.what();
    }
    const Clock::time_point rendered = Clock::now();
    {
        // The renderer is free again: the next pose may render while this one is encoded.
        std::lock_guard lock(mutex_);
        render_busy_ = false;
        render_ms_sum_ += ms_between(begin, rendered);
        if (!error.empty()) {
            --encoding_;
            drop_unacked_locked(pose.frame.sequence);
            error_frame_locked(pose.frame.sequence, {grpc::StatusCode::INTERNAL, "render failed: " + error});
        }
        plan_locked(actions);
    }
    run(actions);
    if (!error.empty()) return;

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
        [self = shared_from_this(), image = std::move(image), frame = std::move(frame), received]() mutable {
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
            self->deliver(std::move(frame), true);
        });
    if (!posted) {
        std::lock_guard lock(mutex_);
        --encoding_;
        drop_unacked_locked(pose.frame.sequence);
    }
}

void StreamSession::deliver(v1::Frame frame, bool image) {
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
                     "frames coalesced, {} errors, render {:.1f} ms, encode {:.1f} ms (means)",
                     id_, static_cast<int>(final_status_.error_code()), final_status_.error_message(), seconds,
                     stats_.requests_received, stats_.frames_sent, seconds > 0 ? frames / seconds : 0.0,
                     stats_.poses_coalesced, stats_.frames_coalesced, stats_.frame_errors,
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
            if (!write_in_flight_) {
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
                    write_in_flight_ = true;
                    actions.write = &in_flight_;
                }
            }
        }
    }
    int frames = (write_in_flight_ ? 1 : 0) + (next_image_ ? 1 : 0) + static_cast<int>(next_errors_.size());
    std::int64_t bytes = (write_in_flight_ ? static_cast<std::int64_t>(in_flight_.data().size()) : 0) +
                         (next_image_ ? static_cast<std::int64_t>(next_image_->data().size()) : 0);
    set_buffered_locked(frames, bytes);
}

void StreamSession::run(const Actions& actions) {
    if (actions.schedule_render && !core_.render_pool().post([self = shared_from_this()] { self->render_next(); })) {
        std::lock_guard lock(mutex_);
        render_busy_ = false;
    }
    if (actions.write) StartWrite(actions.write, grpc::WriteOptions().set_no_compression());
    if (actions.finish) Finish(*actions.finish);
}

}  // namespace catgs::server
