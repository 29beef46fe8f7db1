// Fairness (issue 15): the worker pools' scheduling rule (worker_pool.hpp), and a well-behaved
// viewer that keeps its frame rate while hostile clients run on the same machine.
//
// The viewer is paced like a real one (30 poses/s, or a third of what the machine can render
// for it when that is less; every frame read and acknowledged), not a client that asks again
// the moment a frame arrives: on the CPU backend a render already takes every core, so a
// client in lock step wants the whole machine, and no fair rule could leave it its solo rate
// beside anyone else.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <latch>

#include "hostile_clients.hpp"
#include "server_test_util.hpp"

namespace catgs::test {
namespace {

using namespace std::chrono_literals;
using server::WorkerPool;

// ---------------------------------------------------------------------------------------
// The rule, on a pool of its own.
// ---------------------------------------------------------------------------------------

/// Records the order tasks ran in.
class Order {
public:
    std::function<void()> task(std::string name, std::chrono::milliseconds cost = 0ms) {
        return [this, name = std::move(name), cost] {
            std::this_thread::sleep_for(cost);
            std::lock_guard lock(mutex_);
            names_.push_back(name);
        };
    }
    std::vector<std::string> names() const {
        std::lock_guard lock(mutex_);
        return names_;
    }

private:
    mutable std::mutex mutex_;
    std::vector<std::string> names_;
};

/// Holds the pool's only worker until released, so that a test can queue tasks behind it.
class Gate {
public:
    explicit Gate(WorkerPool& pool) {
        EXPECT_TRUE(pool.post([this] {
            entered_.count_down();
            released_.wait();
        }));
        entered_.wait();
    }
    ~Gate() { release(); }  // a failed test must not leave the worker held
    void release() {
        if (!released_.try_wait()) released_.count_down();
    }

private:
    std::latch entered_{1}, released_{1};
};

/// Waits until `count` tasks have run. (Polling, not a task of its own: any task would move
/// the pool's virtual time.)
void wait_for(const Order& order, std::size_t count) {
    ASSERT_TRUE(eventually([&] { return order.names().size() >= count; }, 10s)) << order.names().size();
}

/// A small flow's tasks go ahead of the backlog of a flow that has used more worker time;
/// FIFO order would run the backlog first.
TEST(WorkerPoolFairness, SmallFlowGoesAheadOfALargerFlowsBacklog) {
    Order order;  // outlives the pool, whose tasks record into it
    WorkerPool pool("test", 1);
    WorkerPool::Flow large = pool.open_flow(), small = pool.open_flow();
    ASSERT_TRUE(pool.post(large, order.task("large-1", 30ms)));
    wait_for(order, 1);
    Gate gate(pool);
    ASSERT_TRUE(pool.post(large, order.task("large-2")));
    ASSERT_TRUE(pool.post(large, order.task("large-3")));
    ASSERT_TRUE(pool.post(small, order.task("small-1")));
    ASSERT_TRUE(pool.post(small, order.task("small-2")));
    gate.release();
    wait_for(order, 5);
    EXPECT_EQ(order.names(), (std::vector<std::string>{"large-1", "small-1", "small-2", "large-2", "large-3"}));
}

/// An idle flow comes back at the pool's virtual time: it gets its turn at once, but not a
/// burst that repays the time it was idle.
TEST(WorkerPoolFairness, AnIdleFlowBanksNoCredit) {
    Order order;  // outlives the pool, whose tasks record into it
    WorkerPool pool("test", 1);
    WorkerPool::Flow busy = pool.open_flow(), idle = pool.open_flow();
    for (int i = 1; i <= 5; ++i) ASSERT_TRUE(pool.post(busy, order.task("busy-" + std::to_string(i), 10ms)));
    wait_for(order, 5);
    Gate gate(pool);
    ASSERT_TRUE(pool.post(busy, order.task("busy-6", 10ms)));
    for (int i = 1; i <= 3; ++i) ASSERT_TRUE(pool.post(idle, order.task("idle-" + std::to_string(i), 40ms)));
    gate.release();
    wait_for(order, 9);
    const auto names = order.names();
    ASSERT_EQ(names.size(), 9u);
    // busy has used 50 ms; idle enters at the start of busy's last task (40 ms), runs once
    // (now at 80 ms), and then busy (at 50 ms) goes first. Had idle kept its 0, it would have run
    // twice before busy.
    EXPECT_EQ(names[5], "idle-1");
    EXPECT_EQ(names[6], "busy-6");
}

/// A flow runs one task at a time, in the order posted, however many workers are free; tasks
/// without a flow run side by side.
TEST(WorkerPoolFairness, AFlowRunsOneTaskAtATimeInOrder) {
    constexpr int kWorkers = 4, kTasks = 20;
    WorkerPool pool("test", kWorkers);
    WorkerPool::Flow flow = pool.open_flow();
    std::atomic<int> running{0}, most{0};
    std::mutex mutex;
    std::vector<int> ran;
    std::latch done(kTasks);
    for (int i = 0; i < kTasks; ++i)
        ASSERT_TRUE(pool.post(flow, [&, i] {
            most = std::max(most.load(), ++running);
            std::this_thread::sleep_for(1ms);
            {
                std::lock_guard lock(mutex);
                ran.push_back(i);
            }
            --running;
            done.count_down();
        }));
    done.wait();
    EXPECT_EQ(most, 1);
    std::vector<int> expected(kTasks);
    for (int i = 0; i < kTasks; ++i) expected[static_cast<std::size_t>(i)] = i;
    EXPECT_EQ(ran, expected);

    // One-task flows: all four workers at once (each waits for the others, bounded).
    std::latch together(kWorkers);
    std::atomic<int> met{0};
    for (int i = 0; i < kWorkers; ++i)
        ASSERT_TRUE(pool.post([&] {
            together.count_down();
            const auto end = std::chrono::steady_clock::now() + 10s;
            while (!together.try_wait() && std::chrono::steady_clock::now() < end) std::this_thread::sleep_for(1ms);
            if (together.try_wait()) ++met;
        }));
    pool.stop();
    EXPECT_EQ(met, kWorkers);
}

/// stop() runs what was queued, in every flow, and refuses what comes after.
TEST(WorkerPoolFairness, StopRunsTheQueuedTasksThenRefuses) {
    WorkerPool pool("test", 2);
    std::atomic<int> ran{0};
    {
        WorkerPool::Flow a = pool.open_flow(), b = pool.open_flow();
        for (int i = 0; i < 5; ++i) {
            ASSERT_TRUE(pool.post(a, [&] { ++ran; }));
            ASSERT_TRUE(pool.post(b, [&] { ++ran; }));
            ASSERT_TRUE(pool.post([&] { ++ran; }));
        }
    }  // the flows close with work queued: it still runs
    pool.stop();
    EXPECT_EQ(ran, 15);
    EXPECT_FALSE(pool.post([&] { ++ran; }));
    EXPECT_EQ(ran, 15);
}

/// 0 stands for counts sized from the machine.
TEST(WorkerPoolFairness, AutoWorkerCountsFollowTheMachine) {
    using server::auto_worker_counts;
    EXPECT_EQ(auto_worker_counts("cpu", 2, 8).render, 2);
    EXPECT_EQ(auto_worker_counts("cpu", 1, 8).render, 1);
    EXPECT_EQ(auto_worker_counts("cpu", 64, 8).render, 2);
    EXPECT_EQ(auto_worker_counts("cpu", 64, 8).encode, server::kMinEncodeWorkers);
    EXPECT_EQ(auto_worker_counts("cuda", 16, 8).render, server::kRenderWorkersPerGpu);
    EXPECT_EQ(auto_worker_counts("cuda", 16, 32).encode, 15);
    EXPECT_EQ(auto_worker_counts("cuda", 16, 8).encode, 8);  // one encode per session at a time
    EXPECT_EQ(auto_worker_counts("cuda", 2, 8).encode, server::kMinEncodeWorkers);
    EXPECT_EQ(auto_worker_counts("cpu", 0, 8).render, 1);  // unknown core count
    // What the server starts with.
    server::ServerOptions o = test_options();
    o.render_workers = o.encode_workers = 0;
    auto s = start_server(o);
    const auto expected = auto_worker_counts("cpu", static_cast<int>(std::thread::hardware_concurrency()), 8);
    EXPECT_EQ(s->core().options().render_workers, expected.render);
    EXPECT_EQ(s->core().options().encode_workers, expected.encode);
    EXPECT_EQ(s->core().render_pool().threads(), expected.render);
}

// ---------------------------------------------------------------------------------------
// The hostile mix of issue 15, on the CPU backend with the server's default workers.
// ---------------------------------------------------------------------------------------

/// Counts the renders of each size the sessions ask for.
struct RenderCounts {
    std::atomic<int> full_hd{0}, all{0};
};

class CountingRenderer final : public Renderer {
public:
    CountingRenderer(std::unique_ptr<Renderer> inner, RenderCounts& counts)
        : inner_(std::move(inner)), counts_(counts) {}
    void set_scene(std::shared_ptr<const Scene> scene) override { inner_->set_scene(std::move(scene)); }
    FrameStats render(const Camera& camera, const RenderOptions& options, ImageF& out,
                      const FrameHints* hints) override {
        count(camera);
        return inner_->render(camera, options, out, hints);
    }
    FrameStats render_rgb8(const Camera& camera, const RenderOptions& options, ImageRGB8& out,
                           const FrameHints* hints) override {
        count(camera);
        return inner_->render_rgb8(camera, options, out, hints);
    }
    void reset_cache() override { inner_->reset_cache(); }
    std::string name() const override { return inner_->name(); }

private:
    void count(const Camera& camera) {
        ++counts_.all;
        if (camera.intrinsics.width >= kFullHdWidth) ++counts_.full_hd;
    }
    static constexpr int kFullHdWidth = 1920;
    std::unique_ptr<Renderer> inner_;
    RenderCounts& counts_;
};

v1::SessionConfig sized(v1::Encoding encoding, int width, int height, int quality = 0) {
    v1::SessionConfig c = session_config(encoding, quality);
    c.set_width(width);
    c.set_height(height);
    return c;
}

void print(const char* what, const StreamMeasurement& m) {
    const double frames = std::max(m.frames, 1);
    std::printf(
        "%s: %d frames in %.1f s = %.1f frames/s; latency p50 %.1f, p90 %.1f, max %.1f ms; server queue %.1f, "
        "render %.1f, encode %.1f ms (means)\n",
        what, m.frames, m.seconds, m.fps(), m.latency_quantile(0.5), m.latency_quantile(0.9), m.latency_quantile(1.0),
        m.queue_ms / frames, m.render_ms / frames, m.encode_ms / frames);
}

/// The well-behaved viewer's pose rate: a typical viewer's, lowered on a machine too slow to
/// render it thrice over (kViewerShareOfCapacity).
constexpr double kViewerPosesPerSecond = 30;
/// Well-behaved means asking for at most this share of the frames the machine could give the
/// viewer alone: its fair share beside two heavy clients. (It then keeps its rate only if the
/// server is fair; asking for more, it would be CPU-bound and no rule could keep its rate.)
constexpr double kViewerShareOfCapacity = 1.0 / 3;
/// Poses per second that measure that capacity: more than any CPU render of 320x240 answers,
/// under the default pose-rate limit (240/s).
constexpr double kCapacityPosesPerSecond = 200;
/// The share of its solo frame rate the viewer must keep beside the hostile clients (issue 15).
constexpr double kRequiredShare = 0.7;
/// How long each phase warms up and then measures: long enough for a few hundred frames.
constexpr std::chrono::milliseconds kWarmUp = 1500ms, kMeasure = 5000ms;
/// Renders the never-reading client may cost: the frames the transport's windows take before
/// gRPC stops accepting writes, one waiting, and one more for windows that open wide.
constexpr int kMaxNeverReadRenders = 4;

/// The backend of the measurement: the CPU in CI; CATGS_FAIRNESS_BACKEND=cuda repeats it on a
/// GPU host (issue 15 asks for the H200's numbers too).
std::string fairness_backend() {
    const char* backend = std::getenv("CATGS_FAIRNESS_BACKEND");
    return backend && *backend ? backend : "cpu";
}

TEST(FairnessUnderHostileClients, WellBehavedViewerKeepsItsFrameRate) {
    RenderCounts counts;
    const std::string backend = fairness_backend();
    std::printf("backend %s\n", backend.c_str());
    server::ServerOptions o = test_options();
    o.render_workers = o.encode_workers = 0;  // the defaults: what a deployment gets
    o.render_threads = 0;
    o.backend = backend;  // worker counts are sized for it
    o.renderer_factory = [&counts, backend] {
        return std::make_unique<CountingRenderer>(make_renderer(backend, Precision::single, 0), counts);
    };
    auto server = start_server(o);
    const int port = server->port();
    const v1::SessionConfig viewer_config = sized(v1::ENCODING_JPEG, 320, 240, 80);

    // What the machine can give the viewer alone, and the rate it asks for.
    double rate = kViewerPosesPerSecond;
    {
        PacedViewer viewer(port, viewer_config, kCapacityPosesPerSecond);
        std::this_thread::sleep_for(kWarmUp);
        viewer.start_measuring();
        std::this_thread::sleep_for(kWarmUp);
        const StreamMeasurement capacity = viewer.measurement();
        EXPECT_TRUE(viewer.stop().ok());
        print("capacity", capacity);
        rate = std::min(rate, kViewerShareOfCapacity * capacity.fps());
        ASSERT_GT(rate, 0);
        std::printf("the viewer asks for %.1f poses/s\n", rate);
    }

    // Alone.
    StreamMeasurement alone;
    {
        PacedViewer viewer(port, viewer_config, rate);
        std::this_thread::sleep_for(kWarmUp);
        viewer.start_measuring();
        std::this_thread::sleep_for(kMeasure);
        alone = viewer.measurement();
        EXPECT_TRUE(viewer.stop().ok());
        EXPECT_EQ(viewer.error_frames(), 0) << viewer.first_error();
    }
    print("alone", alone);
    ASSERT_GT(alone.frames, 0);

    // Beside the hostile clients.
    const long rss_before = rss_kb();
    StreamMeasurement beside;
    int greedy_frames = 0, churn_acts = 0, never_read_renders = 0;
    {
        const int full_hd_before = counts.full_hd;
        AckButNeverRead never_reads(port, sized(v1::ENCODING_RAW_RGB8, 1920, 1080), 60);
        GreedyViewer greedy(port, sized(v1::ENCODING_PNG, 1280, 720), 240);
        Churner churner(port, 15, 20ms);
        PacedViewer viewer(port, viewer_config, rate);
        std::this_thread::sleep_for(kWarmUp);
        viewer.start_measuring();
        std::this_thread::sleep_for(kMeasure);
        beside = viewer.measurement();
        never_read_renders = counts.full_hd - full_hd_before;
        EXPECT_TRUE(viewer.stop().ok());
        EXPECT_EQ(viewer.error_frames(), 0) << viewer.first_error();
        churner.stop();
        greedy.stop();
        never_reads.stop();
        greedy_frames = greedy.frames();
        churn_acts = churner.acts();
    }
    print("beside the hostile clients", beside);
    const double share = beside.fps() / alone.fps();
    const auto stats = server->stats();
    std::printf(
        "share kept %.2f; the never-reading 1080p client cost %d renders; greedy 720p PNG viewer got %d frames; "
        "churner %d acts; %d renders in all; peak %lld frames held by one session; RSS +%ld kB\n",
        share, never_read_renders, greedy_frames, churn_acts, counts.all.load(),
        static_cast<long long>(stats.peak_session_buffered), rss_kb() - rss_before);

    if (kTimingSlack == 1) {
        EXPECT_GE(share, kRequiredShare) << "alone " << alone.fps() << " frames/s, beside " << beside.fps();
    }
    // Never rendered what it could not send.
    EXPECT_LE(never_read_renders, kMaxNeverReadRenders);
    EXPECT_GT(never_read_renders, 0) << "the never-reading client did not open";
    // Fair is not starved: the greedy viewer got frames too.
    EXPECT_GT(greedy_frames, 0);
    EXPECT_GT(churn_acts, 0);
    // Bounded memory: two frames per session, and the process did not grow with the frames it
    // could not send (a 1080p raw frame is 6 MB).
    // (Error frames queue apart, at most 8: the churner's floods fill that queue.)
    EXPECT_LE(stats.peak_session_buffered, 2 + 8);
    EXPECT_LT(rss_kb() - rss_before, 256 * 1024);
    // And the server is whole: every session gone, still serving.
    EXPECT_TRUE(eventually([&] { return server->stats().sessions_active == 0; }));
    EXPECT_TRUE(serving(port));
    expect_one_frame(channel_to(port));
}

}  // namespace
}  // namespace catgs::test
