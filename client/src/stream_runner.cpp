#include "stream_runner.hpp"

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <random>
#include <thread>

#include "catgs/common/pose_wire.hpp"

namespace catgs::client {

namespace {

double ms_since(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

std::int64_t micros(Clock::time_point t, Clock::time_point origin) {
    return std::chrono::duration_cast<std::chrono::microseconds>(t - origin).count();
}

}  // namespace

StreamResult run_stream(const std::shared_ptr<grpc::Channel>& channel, const StreamPlan& plan,
                        const FrameCallback& on_frame, const std::atomic<bool>& stop) {
    StreamResult result;
    auto stub = v1::RenderService::NewStub(channel);
    grpc::ClientContext context;
    if (!plan.authorization.empty()) context.AddMetadata("authorization", plan.authorization);
    if (!plan.session_id.empty()) context.AddMetadata(kSessionHeader, plan.session_id);
    const Clock::time_point start = Clock::now();
    auto stream = stub->Stream(&context);
    v1::StreamRequest open;
    *open.mutable_open() = plan.config;
    result.next_index = plan.first;
    if (!stream->Write(open)) {
        result.status = stream->Finish();
        return result;
    }

    const std::size_t n = plan.path.size();
    const std::size_t first = std::min(plan.first, plan.poses);
    const double period_s = plan.rate_hz > 0 ? 1.0 / plan.rate_hz : 0.0;
    const bool lock_step = plan.lock_step || plan.rate_hz <= 0;
    // Intended send time of each sequence number (1-based), for latency; written by the
    // sender before the request goes out.
    std::vector<Clock::time_point> intended(plan.poses + 1);
    std::atomic<std::uint64_t> last_received{0};
    std::mutex mutex;
    std::condition_variable frame_arrived;  // lock step only
    std::atomic<bool> reader_done{false};
    std::atomic<std::uint64_t> last_sent{0};

    std::thread sender([&] {
        const Clock::time_point t0 = Clock::now();
        for (std::size_t i = first; i < plan.poses && !stop && !reader_done; ++i) {
            // Sequence numbers follow the pose index, across reconnections too (a new session
            // accepts any increasing numbers).
            const std::uint64_t seq = i + 1;
            Clock::time_point when = Clock::now();
            if (lock_step && i > first) {
                std::unique_lock lock(mutex);
                frame_arrived.wait(lock, [&] { return last_received >= i || stop || reader_done; });
                when = Clock::now();
            }
            if (plan.rate_hz > 0) {
                // Open loop: latency counts from the scheduled time even when we are late.
                const Clock::time_point scheduled =
                    t0 + std::chrono::duration_cast<Clock::duration>(
                             std::chrono::duration<double>(static_cast<double>(i - first) * period_s));
                if (scheduled > when) std::this_thread::sleep_until(scheduled);
                if (scheduled > when || !lock_step) when = scheduled;
            }
            if (Clock::now() - start > plan.max_duration) break;
            const Camera& camera = plan.path[i % n];
            v1::StreamRequest request;
            v1::FrameRequest* f = request.mutable_frame();
            f->set_sequence(seq);
            *f->mutable_pose() = wire::to_proto(camera.pose);
            f->set_client_timestamp_us(micros(when, start));
            f->set_last_received_sequence(last_received);
            const Camera& next = plan.path[(i + 1) % n];
            const double dt = next.timestamp - camera.timestamp;
            if (plan.velocity && dt > 0 && (i + 1) % n != 0) {
                const auto a = camera_centre(camera.pose), b = camera_centre(next.pose);
                f->mutable_linear_velocity()->set_x((b[0] - a[0]) / dt);
                f->mutable_linear_velocity()->set_y((b[1] - a[1]) / dt);
                f->mutable_linear_velocity()->set_z((b[2] - a[2]) / dt);
            }
            for (int k = 1; k <= plan.flight_plan; ++k) {
                const Camera& future = plan.path[(i + k) % n];
                auto* planned = f->add_flight_plan();
                *planned->mutable_pose() = wire::to_proto(future.pose);
                const double ahead = plan.rate_hz > 0 ? k * period_s : future.timestamp - camera.timestamp;
                planned->set_client_timestamp_us(f->client_timestamp_us() + static_cast<std::int64_t>(ahead * 1e6));
            }
            {
                std::lock_guard lock(mutex);
                intended[seq] = when;
            }
            if (!stream->Write(request)) break;
            ++result.poses_sent;
            last_sent = seq;
        }
        stream->WritesDone();
    });

    v1::Frame frame;
    while (stream->Read(&frame)) {
        const Clock::time_point now = Clock::now();
        if (frame.has_error()) {
            ++result.frame_errors;
        } else {
            Clock::time_point sent;
            {
                std::lock_guard lock(mutex);
                sent = frame.sequence() < intended.size() ? intended[frame.sequence()] : now;
            }
            const double latency = ms_since(sent, now);
            result.latency.add(latency);
            ++result.frames;
            result.bytes += frame.data().size();
            if (result.time_to_first_frame_ms < 0) result.time_to_first_frame_ms = ms_since(start, now);
            result.server_poses_coalesced = frame.stats().poses_coalesced();
            result.server_frames_coalesced = frame.stats().frames_coalesced();
            if (on_frame) on_frame(frame, latency);
        }
        if (frame.has_error() && on_frame) on_frame(frame, 0);
        {
            std::lock_guard lock(mutex);
            last_received = std::max<std::uint64_t>(last_received, frame.sequence());
        }
        frame_arrived.notify_all();
    }
    reader_done = true;
    frame_arrived.notify_all();
    sender.join();
    result.status = stream->Finish();
    // Resume at the newest pose sent when it got no frame (the viewer is there now; older
    // unanswered poses would only be coalesced), else after it.
    const std::uint64_t sent = last_sent, received = last_received;
    result.next_index = sent == 0 ? first : (received >= sent ? sent : sent - 1);
    return result;
}

std::chrono::milliseconds backoff_delay(const RetryPolicy& policy, int attempt, double random01) {
    const double base = static_cast<double>(policy.backoff.count());
    const double cap = static_cast<double>(std::max(policy.max_backoff, policy.backoff).count());
    const double full = std::min(cap, base * std::pow(2.0, std::max(0, attempt - 1)));
    return std::chrono::milliseconds(static_cast<long>(std::lround(full * (0.5 + 0.5 * random01))));
}

StreamResult run_stream_with_retries(const std::shared_ptr<grpc::Channel>& channel, const StreamPlan& plan,
                                     const FrameCallback& on_frame, const std::atomic<bool>& stop,
                                     const RetryPolicy& policy, const std::function<void(const std::string&)>& log) {
    std::mt19937_64 random(policy.seed ? policy.seed
                                       : static_cast<std::uint64_t>(Clock::now().time_since_epoch().count()));
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    const Clock::time_point start = Clock::now();
    StreamResult total;
    StreamPlan attempt_plan = plan;
    int failures = 0;  // consecutive attempts that ended UNAVAILABLE without a frame
    for (;;) {
        const Clock::time_point attempt_start = Clock::now();
        attempt_plan.max_duration = plan.max_duration - (attempt_start - start);
        StreamResult r = run_stream(channel, attempt_plan, on_frame, stop);
        total.poses_sent += r.poses_sent;
        total.frames += r.frames;
        total.frame_errors += r.frame_errors;
        total.bytes += r.bytes;
        total.server_poses_coalesced += r.server_poses_coalesced;
        total.server_frames_coalesced += r.server_frames_coalesced;
        if (total.time_to_first_frame_ms < 0 && r.time_to_first_frame_ms >= 0)
            total.time_to_first_frame_ms =
                std::chrono::duration<double, std::milli>(attempt_start - start).count() + r.time_to_first_frame_ms;
        total.latency.merge(r.latency);
        total.status = r.status;
        total.next_index = r.next_index;
        const bool done = r.next_index >= plan.poses || Clock::now() - start >= plan.max_duration;
        if (r.status.error_code() != grpc::StatusCode::UNAVAILABLE || done || stop) break;
        failures = r.frames > 0 ? 1 : failures + 1;
        if (failures > policy.retries) break;
        const auto delay = backoff_delay(policy, failures, uniform(random));
        ++total.reconnects;
        if (log)
            log("stream: " + r.status.error_message() + " (UNAVAILABLE); reconnecting in " +
                std::to_string(delay.count()) + " ms, retry " + std::to_string(failures) + " of " +
                std::to_string(policy.retries) + ", resuming at pose " + std::to_string(r.next_index + 1));
        const Clock::time_point wake = Clock::now() + delay;
        while (!stop && Clock::now() < wake) std::this_thread::sleep_for(std::chrono::milliseconds(10));
        if (stop) break;
        attempt_plan.first = r.next_index;
    }
    return total;
}

}  // namespace catgs::client
