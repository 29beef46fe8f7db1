#include "stream_runner.hpp"

#include <condition_variable>
#include <thread>

namespace catgs::client {

v1::Pose to_pose(const Camera& camera) {
    v1::Pose p;
    const auto c = camera_centre(camera.pose);
    const auto q = camera_to_world_quaternion(camera.pose);
    p.mutable_position()->set_x(c[0]);
    p.mutable_position()->set_y(c[1]);
    p.mutable_position()->set_z(c[2]);
    p.mutable_orientation()->set_w(q[0]);
    p.mutable_orientation()->set_x(q[1]);
    p.mutable_orientation()->set_y(q[2]);
    p.mutable_orientation()->set_z(q[3]);
    return p;
}

namespace {

double ms_since(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

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
    const Clock::time_point start = Clock::now();
    auto stream = stub->Stream(&context);
    v1::StreamRequest open;
    *open.mutable_open() = plan.config;
    if (!stream->Write(open)) {
        result.status = stream->Finish();
        return result;
    }

    const std::size_t n = plan.path.size();
    const double period_s = plan.rate_hz > 0 ? 1.0 / plan.rate_hz : 0.0;
    // Intended send time of each sequence number (1-based), for latency; written by the
    // sender before the request goes out.
    std::vector<Clock::time_point> intended(plan.poses + 1);
    std::atomic<std::uint64_t> last_received{0};
    std::mutex mutex;
    std::condition_variable frame_arrived;  // lock step only
    std::atomic<bool> reader_done{false};

    std::thread sender([&] {
        const Clock::time_point t0 = Clock::now();
        for (std::size_t i = 0; i < plan.poses && !stop && !reader_done; ++i) {
            const std::uint64_t seq = i + 1;
            Clock::time_point when = Clock::now();
            if (plan.rate_hz > 0) {
                when = t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(i * period_s));
                std::this_thread::sleep_until(when);
            } else if (i > 0) {
                std::unique_lock lock(mutex);
                frame_arrived.wait(lock, [&] { return last_received >= i || stop || reader_done; });
                when = Clock::now();
            }
            if (Clock::now() - start > plan.max_duration) break;
            const Camera& camera = plan.path[i % n];
            v1::StreamRequest request;
            v1::FrameRequest* f = request.mutable_frame();
            f->set_sequence(seq);
            *f->mutable_pose() = to_pose(camera);
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
                *planned->mutable_pose() = to_pose(future);
                const double ahead = plan.rate_hz > 0 ? k * period_s : future.timestamp - camera.timestamp;
                planned->set_client_timestamp_us(f->client_timestamp_us() + static_cast<std::int64_t>(ahead * 1e6));
            }
            {
                std::lock_guard lock(mutex);
                intended[seq] = when;
            }
            if (!stream->Write(request)) break;
            ++result.poses_sent;
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
    return result;
}

}  // namespace catgs::client
