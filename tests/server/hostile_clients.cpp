#include "hostile_clients.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <random>

#include "server_test_util.hpp"

namespace catgs::test {
namespace {

using Clock = std::chrono::steady_clock;

/// Long enough for every test that uses these clients; a hung call still ends.
constexpr std::chrono::seconds kCallDeadline{120};
/// Poses on each client's path: enough to keep the views changing (a repeated pose is
/// answered unrendered).
constexpr int kPathPoses = 240;
/// The churner's small sessions: cheap to render, so its cost is the churn itself.
constexpr int kChurnWidth = 160, kChurnHeight = 90;
/// Requests in one pose flood: beyond the burst of the default pose-rate limit (240/s), so the
/// server postpones reads, yet small enough (~30 KB) that the writes never block on HTTP/2
/// flow control.
constexpr int kFloodRequests = 300;

Clock::duration period_of(double per_second) {
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / per_second));
}

std::vector<Camera> path_for(const v1::SessionConfig& config) {
    return uav_path(kPathPoses, static_cast<int>(config.width()), static_cast<int>(config.height()));
}

}  // namespace

double StreamMeasurement::latency_quantile(double q) const {
    if (latency_ms.empty()) return 0;
    std::vector<double> sorted = latency_ms;
    std::sort(sorted.begin(), sorted.end());
    const auto index = static_cast<std::size_t>(q * static_cast<double>(sorted.size() - 1) + 0.5);
    return sorted[std::min(index, sorted.size() - 1)];
}

// ---------------------------------------------------------------------------------------

PacedViewer::PacedViewer(int port, v1::SessionConfig config, double poses_per_second)
    : poses_per_second_(poses_per_second), call_(channel_to(port), "", kCallDeadline) {
    call_.open(config);
    reader_ = std::thread([this] { read_loop(); });
    sender_ = std::thread([this, path = path_for(config)] {
        std::uint64_t sequence = 0;
        auto next = Clock::now();
        while (!stop_) {
            ++sequence;
            {
                std::lock_guard lock(mutex_);
                sent_at_.push_back(Clock::now());
            }
            if (!call_.send(frame_request(sequence, path[sequence % path.size()], last_received_))) break;
            next += period_of(poses_per_second_);
            std::this_thread::sleep_until(next);
        }
        call_.stream->WritesDone();
    });
}

PacedViewer::~PacedViewer() {
    stop();
}

void PacedViewer::read_loop() {
    for (v1::Frame frame; call_.stream->Read(&frame);) {
        const auto now = Clock::now();
        if (frame.has_error()) {
            ++error_frames_;
            std::lock_guard lock(mutex_);
            if (first_error_.empty()) first_error_ = frame.error().message();
            continue;
        }
        last_received_ = frame.sequence();
        std::lock_guard lock(mutex_);
        if (!measuring_ || frame.sequence() == 0 || frame.sequence() > sent_at_.size()) continue;
        ++window_.frames;
        window_.render_ms += frame.timings().render_ms();
        window_.queue_ms += frame.timings().queue_ms();
        window_.encode_ms += frame.timings().encode_ms();
        window_.latency_ms.push_back(
            std::chrono::duration<double, std::milli>(now - sent_at_[frame.sequence() - 1]).count());
    }
}

void PacedViewer::start_measuring() {
    std::lock_guard lock(mutex_);
    measuring_ = true;
    window_ = {};
    window_start_ = Clock::now();
}

StreamMeasurement PacedViewer::measurement() const {
    std::lock_guard lock(mutex_);
    StreamMeasurement m = window_;
    m.seconds = measuring_ ? std::chrono::duration<double>(Clock::now() - window_start_).count() : 0;
    return m;
}

std::string PacedViewer::first_error() const {
    std::lock_guard lock(mutex_);
    return first_error_;
}

grpc::Status PacedViewer::stop() {
    if (stopped_) return status_;
    stopped_ = true;
    stop_ = true;
    sender_.join();  // it half-closes: the server answers the last pose and ends the stream
    reader_.join();
    status_ = call_.stream->Finish();
    return status_;
}

// ---------------------------------------------------------------------------------------

AckButNeverRead::AckButNeverRead(int port, v1::SessionConfig config, double poses_per_second)
    : call_(channel_to(port), "", kCallDeadline) {
    call_.open(config);
    sender_ = std::thread([this, path = path_for(config), period = period_of(poses_per_second)] {
        auto next = Clock::now();
        for (std::uint64_t sequence = 1; !stop_; ++sequence) {
            // The lie: every frame sent so far acknowledged, none read.
            if (!call_.send(frame_request(sequence, path[sequence % path.size()], sequence - 1))) break;
            ++sent_;
            next += period;
            std::this_thread::sleep_until(next);
        }
    });
}

AckButNeverRead::~AckButNeverRead() {
    stop();
}

void AckButNeverRead::stop() {
    if (stop_.exchange(true)) return;
    call_.context.TryCancel();  // also unblocks a write stuck in flow control
    sender_.join();
    call_.finish();
}

// ---------------------------------------------------------------------------------------

GreedyViewer::GreedyViewer(int port, v1::SessionConfig config, double poses_per_second)
    : call_(channel_to(port), "", kCallDeadline) {
    call_.open(config);
    reader_ = std::thread([this] {
        for (v1::Frame frame; call_.stream->Read(&frame);) {
            if (frame.has_error()) continue;
            last_received_ = frame.sequence();
            ++frames_;
        }
    });
    sender_ = std::thread([this, path = path_for(config), period = period_of(poses_per_second)] {
        auto next = Clock::now();
        for (std::uint64_t sequence = 1; !stop_; ++sequence) {
            if (!call_.send(frame_request(sequence, path[sequence % path.size()], last_received_))) break;
            next += period;
            std::this_thread::sleep_until(next);
        }
    });
}

GreedyViewer::~GreedyViewer() {
    stop();
}

void GreedyViewer::stop() {
    if (stop_.exchange(true)) return;
    call_.context.TryCancel();
    sender_.join();
    reader_.join();
    call_.stream->Finish();
}

// ---------------------------------------------------------------------------------------

Churner::Churner(int port, std::uint64_t seed, std::chrono::milliseconds pause)
    : port_(port), seed_(seed), pause_(pause), channel_(channel_to(port)) {
    thread_ = std::thread([this] { run(); });
}

Churner::~Churner() {
    stop();
}

void Churner::stop() {
    if (stop_.exchange(true)) return;
    thread_.join();
}

void Churner::run() {
    /// Every this many acts the churner reconnects: connection set-up is part of the churn.
    constexpr int kActsPerChannel = 12;
    for (int act = 0; !stop_; ++act) {
        if (act % kActsPerChannel == 0) channel_ = channel_to(port_);
        switch (act % 6) {
            case 0:
                refused_open(act / 6);
                break;
            case 1:
                cancel_after_first_pose();
                break;
            case 2:
                tcp_junk();
                break;
            case 3:
                pose_flood();
                break;
            case 4:
                never_opens();
                break;
            default:
                refused_open(act / 6 + 1);
                break;
        }
        ++acts_;
        std::this_thread::sleep_for(pause_);
    }
}

void Churner::refused_open(int variant) {
    StreamClient call(channel_, "", kCallDeadline);
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG, 80);
    if (variant % 2)
        config.set_scene_id("no-such-scene");
    else
        config.set_width(0);
    call.open(config);
    call.close();
}

void Churner::cancel_after_first_pose() {
    StreamClient call(channel_, "", kCallDeadline);
    v1::SessionConfig config = session_config(v1::ENCODING_PNG);
    call.open(config);
    call.send(frame_request(1, uav_path(2, kChurnWidth, kChurnHeight)[1], 0));
    call.context.TryCancel();
    call.finish();
}

void Churner::tcp_junk() {
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) return;
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<std::uint16_t>(port_));
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0) {
        std::mt19937_64 random(seed_ + static_cast<std::uint64_t>(acts_));
        // Half the time behind the HTTP/2 preface, so the junk reaches the frame parser.
        std::string bytes = acts_ % 2 ? std::string("PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n") : std::string();
        const std::size_t junk = 4096;
        for (std::size_t i = 0; i < junk; ++i) bytes.push_back(static_cast<char>(random() & 0xff));
        [[maybe_unused]] const ssize_t sent = send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
    }
    close(fd);
}

void Churner::pose_flood() {
    StreamClient call(channel_, "", kCallDeadline);
    v1::SessionConfig config = session_config(v1::ENCODING_JPEG, 80);
    call.open(config);
    const auto path = uav_path(kPathPoses, kChurnWidth, kChurnHeight);
    std::uint64_t sequence = 0;
    for (int i = 0; i < kFloodRequests; ++i) {
        // Every tenth repeats the previous sequence number: an error frame each.
        if (i % 10 != 9) ++sequence;
        if (!call.send(frame_request(sequence, path[sequence % path.size()], 0))) break;
    }
    call.context.TryCancel();
    call.finish();
}

void Churner::never_opens() {
    StreamClient call(channel_, "", kCallDeadline);
    std::this_thread::sleep_for(pause_);
    call.context.TryCancel();
    call.finish();
}

}  // namespace catgs::test
