// The workers' side of a stream session: making its renderer, rendering the pending pose,
// encoding the frame and handing it back to the reactor side (deliver) for writing.
#include <spdlog/spdlog.h>

#include "catgs/server/frame_messages.hpp"
#include "catgs/server/stream_session.hpp"

namespace catgs::server {
namespace {

/// Bit-for-bit equality: a client that repeats a pose sends the same doubles.
bool same_pose(const Pose& a, const Pose& b) {
    return a.rotation == b.rotation && a.translation == b.translation;
}

}  // namespace

void StreamSession::initialise() {
    std::unique_ptr<Renderer> renderer;
    const std::optional<RenderFailure> failure = catch_render_failure([&] {
        // An idle pooled renderer when there is one; else a new one (CUDA: it uploads the
        // scene unless another session or pooled renderer holds it on the device).
        renderer = core_.acquire_renderer(lease_->scene(), *seat_);
    });
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        if (failure) {
            renderer.reset();  // frees whatever it had allocated before the failure
            if (failure->out_of_memory) {
                core_.counters().out_of_memory++;
                spdlog::warn("session {}: out of memory loading scene {} for rendering: {}", id_, setup_.scene_id,
                             failure->what);
            } else {
                spdlog::error("session {}: cannot create a renderer: {}", id_, failure->what);
            }
            request_finish_locked(renderer_failure_status(*failure, setup_.scene_id));
        } else {
            renderer_ = std::move(renderer);
            if (phase_ == Phase::opening) {  // not when the stream ended meanwhile
                phase_ = Phase::open;
                const Intrinsics& k = setup_.intrinsics;
                spdlog::info(
                    "session {} opened by {}: scene {} on device {}, {}x{} fx {:.1f}, {}{}, {}, max {} unacked", id_,
                    peer_, setup_.scene_id, seat_->device(), k.width, k.height, k.fx, format_name(setup_.encode.format),
                    setup_.encode.format == Format::jpeg ? " q" + std::to_string(setup_.encode.jpeg_quality) : "",
                    renderer_->name(), setup_.max_unacked_frames);
            }
        }
        plan_locked(actions);
    }
    run(actions);
}

void StreamSession::render_next() {
    std::optional<PendingPose> pose;
    std::optional<std::string> resend;  // the bytes of the last frame, when its pose repeats
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        if (phase_ == Phase::open && pending_) {
            pose = std::move(pending_);
            pending_.reset();
            unacked_.push_back(pose->frame.sequence);
            ++encoding_;
            if (last_sent_pose_ && same_pose(*last_sent_pose_, pose->frame.camera.pose)) resend = last_sent_data_;
        }
        if (!pose || resend) {
            // Nothing to render: the next pose may render meanwhile.
            render_busy_ = false;
            plan_locked(actions);
        }
    }
    run(actions);
    if (resend)
        resend_last(std::move(*pose), std::move(*resend));
    else if (pose)
        render(std::move(*pose));
}

// Render pool, render_busy_ set: renders `pose` and posts its encoding.
void StreamSession::render(PendingPose pose) {
    const Clock::time_point begin = Clock::now();
    ImageRGB8 image;
    FrameStats frame_stats;
    const std::optional<RenderFailure> failure = catch_render_failure([&] {
        frame_stats = renderer_->render_rgb8(pose.frame.camera, setup_.options, image,
                                             pose.frame.hints ? &*pose.frame.hints : nullptr);
    });
    const Clock::time_point rendered = Clock::now();
    if (!failure) seat_->record_render(frame_stats.total_ms, rendered);
    const std::uint64_t max_bytes = core_.options().limits.max_session_bytes;
    const bool over_limit = !failure && max_bytes > 0 && frame_stats.arena_bytes > max_bytes;
    // Idle pooled renderers go too, so that the client's retry finds the memory free (outside
    // mutex_: destroying renderers frees device memory, which takes a while).
    if (failure && failure->out_of_memory) core_.drop_idle_renderers(*seat_);
    Actions actions;
    {
        // The renderer is free again: the next pose may render while this one is encoded.
        std::lock_guard lock(mutex_);
        render_busy_ = false;
        render_ms_sum_ += ms_between(begin, rendered);
        if (failure || over_limit) {
            renderer_reusable_ = false;
            --encoding_;
            drop_unacked_locked(pose.frame.sequence);
            const std::string size = image_size(setup_.intrinsics);
            if (over_limit) {
                // The arenas are grow-only: the session would keep holding this memory.
                core_.counters().out_of_memory++;
                request_finish_locked(session_memory_status(setup_.scene_id, size, frame_stats.arena_bytes, max_bytes));
            } else if (failure->out_of_memory) {
                // Ending the session frees its buffers; an error frame would leave them held.
                core_.counters().out_of_memory++;
                spdlog::warn("session {}: out of memory rendering {}: {}", id_, size, failure->what);
                request_finish_locked(render_failure_status(*failure, size));
            } else {
                error_frame_locked(pose.frame.sequence, render_failure_status(*failure, size));
            }
        }
        plan_locked(actions);
    }
    run(actions);
    if (failure || over_limit) return;

    v1::Frame frame =
        rendered_frame(pose.frame, setup_.encode.format, image, frame_stats, {pose.received, begin, rendered});
    const bool posted = core_.encode_pool().post(
        encode_flow_, [self = shared_from_this(), image = std::move(image), frame = std::move(frame),
                       received = pose.received, view = pose.frame.camera.pose]() mutable {
            if (const grpc::Status status = encode_frame(image, self->setup_.encode, received, frame); !status.ok()) {
                frame.mutable_error()->set_code(static_cast<int>(status.error_code()));
                frame.mutable_error()->set_message(status.error_message());
            }
            self->deliver(std::move(frame), view);
        });
    if (!posted) {
        std::lock_guard lock(mutex_);
        --encoding_;
        drop_unacked_locked(pose.frame.sequence);
    }
}

void StreamSession::resend_last(PendingPose pose, std::string data) {
    v1::Frame frame = resent_frame(pose.frame, setup_.encode.format, setup_.intrinsics, pose.received, std::move(data));
    {
        std::lock_guard lock(mutex_);
        ++stats_.frames_reused;
    }
    deliver(std::move(frame), pose.frame.camera.pose);
}

void StreamSession::deliver(v1::Frame frame, const Pose& view) {
    Actions actions;
    {
        std::lock_guard lock(mutex_);
        --encoding_;
        const std::uint64_t sequence = frame.sequence();
        if (ending_locked()) {
            drop_unacked_locked(sequence);
        } else if (frame.has_error()) {
            drop_unacked_locked(sequence);
            error_frame_locked(sequence,
                               {static_cast<grpc::StatusCode>(frame.error().code()), frame.error().message()});
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
            next_image_pose_ = view;
            newest_image_sequence_ = sequence;
        }
        plan_locked(actions);
    }
    run(actions);
}

}  // namespace catgs::server
