// Clients for the fairness tests, each on its own threads against a server on 127.0.0.1:port:
// a well-behaved viewer that measures what it gets, and the hostile ones of issue 15's trials
// (a client that acknowledges every frame but never reads, a greedy viewer, a churner).
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "catgs/v1/catgs.grpc.pb.h"
#include "server_test_util.hpp"

namespace catgs::test {

/// What a viewer received over a measuring window.
struct StreamMeasurement {
    int frames = 0;
    double seconds = 0;
    std::vector<double> latency_ms;                     ///< pose sent to frame received, per frame
    double render_ms = 0, queue_ms = 0, encode_ms = 0;  ///< sums of the frames' ServerTimings
    double fps() const { return seconds > 0 ? frames / seconds : 0; }
    /// The q-quantile (0..1) of latency_ms; 0 without frames.
    double latency_quantile(double q) const;
};

/// A viewer in the shape of a real one: poses at a fixed rate (not as fast as the server
/// answers), every frame read on its own thread and acknowledged in the next request.
class PacedViewer {
public:
    PacedViewer(int port, v1::SessionConfig config, double poses_per_second);
    ~PacedViewer();
    /// Starts a measuring window (frames and latencies before it are not counted).
    void start_measuring();
    /// The window so far.
    StreamMeasurement measurement() const;
    /// Half-closes and waits for the end; returns the stream's status.
    grpc::Status stop();
    int error_frames() const { return error_frames_; }
    std::string first_error() const;

private:
    void send_loop();
    void read_loop();

    const double poses_per_second_;
    StreamClient call_;
    std::atomic<bool> stop_{false};
    std::atomic<std::uint64_t> last_received_{0};
    std::atomic<int> error_frames_{0};
    mutable std::mutex mutex_;                                    // guards the fields below
    std::vector<std::chrono::steady_clock::time_point> sent_at_;  // by sequence - 1
    std::chrono::steady_clock::time_point window_start_;
    bool measuring_ = false;
    StreamMeasurement window_;
    std::string first_error_;
    std::thread sender_, reader_;
    bool stopped_ = false;
    grpc::Status status_;
};

/// Opens `config`, then sends poses at `poses_per_second`, each acknowledging every frame
/// sent so far, and never reads one.
class AckButNeverRead {
public:
    AckButNeverRead(int port, v1::SessionConfig config, double poses_per_second);
    ~AckButNeverRead();
    void stop();
    std::uint64_t poses_sent() const { return sent_; }

private:
    StreamClient call_;
    std::atomic<bool> stop_{false};
    std::atomic<std::uint64_t> sent_{0};
    std::thread sender_;
};

/// Reads and acknowledges every frame, and asks for a new pose whenever it can: at
/// `poses_per_second` (meant to be at or beyond the server's pose-rate limit).
class GreedyViewer {
public:
    GreedyViewer(int port, v1::SessionConfig config, double poses_per_second);
    ~GreedyViewer();
    void stop();
    int frames() const { return frames_; }

private:
    StreamClient call_;
    std::atomic<bool> stop_{false};
    std::atomic<std::uint64_t> last_received_{0};
    std::atomic<int> frames_{0};
    std::thread sender_, reader_;
};

/// Misbehaves in turn, `pause` between acts: opens that are refused (unknown scene, a zero
/// width), sessions cancelled right after their first pose, raw TCP junk on the gRPC port,
/// pose floods (hundreds of requests at once, some with repeated sequence numbers, none read)
/// ended by a cancel, and calls that never open.
class Churner {
public:
    Churner(int port, std::uint64_t seed, std::chrono::milliseconds pause);
    ~Churner();
    void stop();
    int acts() const { return acts_; }

private:
    void run();
    void refused_open(int variant);
    void cancel_after_first_pose();
    void tcp_junk();
    void pose_flood();
    void never_opens();

    const int port_;
    const std::uint64_t seed_;
    const std::chrono::milliseconds pause_;
    std::shared_ptr<grpc::Channel> channel_;
    std::atomic<bool> stop_{false};
    std::atomic<int> acts_{0};
    std::thread thread_;
};

}  // namespace catgs::test
