// Sessions across devices (catgs-server --gpus, docs/multi-gpu.md) on the CPU backend's
// simulated devices: the placement rule on fed loads, the load's decay, the tie-breaks, the
// scenes' residency per device, per-device admission, --gpus parsing, and a server with two
// devices whose sessions land on different ones.
#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <limits>

#include "catgs/error.hpp"
#include "catgs/server/device_placement.hpp"
#include "process_util.hpp"
#include "server_test_util.hpp"

namespace catgs::test {
namespace {

using server::DevicePlacement;
using std::chrono::milliseconds;
using Seat = std::unique_ptr<DevicePlacement::Seat>;

const DevicePlacement::Clock::time_point kStart{};

Seat place(DevicePlacement& placement, const std::string& scene = "city",
           DevicePlacement::Clock::time_point now = kStart) {
    Seat seat;
    const grpc::Status status = placement.place(scene, &seat, now);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return seat;
}

double load_of(const DevicePlacement& placement, int device, DevicePlacement::Clock::time_point now) {
    for (const auto& d : placement.loads(now))
        if (d.device == device) return d.load;
    ADD_FAILURE() << "no device " << device;
    return -1;
}

TEST(DevicePlacement, LeastMeasuredLoadWinsOverFewerSessions) {
    DevicePlacement placement({0, 1}, 8);
    Seat a = place(placement), b = place(placement), c = place(placement);
    // Nothing measured yet: the fewest sessions, then the lowest index.
    EXPECT_EQ(a->device(), 0);
    EXPECT_EQ(b->device(), 1);
    EXPECT_EQ(c->device(), 0);
    // Device 1's one session renders heavy frames, device 0's two light ones.
    a->record_render(20, kStart);
    c->record_render(20, kStart);
    b->record_render(300, kStart);
    Seat d = place(placement);
    EXPECT_EQ(d->device(), 0) << "device 0 has more sessions but less measured render time per second";
    EXPECT_LT(load_of(placement, 0, kStart), load_of(placement, 1, kStart));
}

TEST(DevicePlacement, LoadIsRenderSecondsPerSecondAndDecays) {
    const auto tau = milliseconds(2000);
    DevicePlacement placement({0, 1}, 8, tau);
    Seat a = place(placement), b = place(placement);
    // A steady 10 ms every 40 ms converges to a quarter of a second per second.
    DevicePlacement::Clock::time_point now = kStart;
    for (int frame = 0; frame < 500; ++frame, now += milliseconds(40)) a->record_render(10, now);
    // The discrete sum runs ahead of the rate by the share of one frame interval (40 / 2000 / 2).
    EXPECT_NEAR(load_of(placement, 0, now), 0.25, 0.25 * 0.02);
    // Idle for one time constant: down by e.
    const double before = load_of(placement, 0, now);
    EXPECT_NEAR(load_of(placement, 0, now + tau), before / std::exp(1.0), 1e-9);
    // Device 1 renders lightly now; device 0, busy long ago, has decayed below it.
    b->record_render(50, now + 5 * tau);
    EXPECT_GT(load_of(placement, 0, now), load_of(placement, 1, now + 5 * tau));
    EXPECT_LT(load_of(placement, 0, now + 5 * tau), load_of(placement, 1, now + 5 * tau));
    EXPECT_EQ(place(placement, "city", now + 5 * tau)->device(), 0);
    EXPECT_EQ(place(placement, "city", now)->device(), 1);
}

TEST(DevicePlacement, TiesGoToFewestSessionsThenLowestIndex) {
    DevicePlacement placement({0, 2, 5}, 8);
    std::vector<Seat> seats;
    for (int i = 0; i < 4; ++i) seats.push_back(place(placement));
    EXPECT_EQ(seats[0]->device(), 0);
    EXPECT_EQ(seats[1]->device(), 2);
    EXPECT_EQ(seats[2]->device(), 5);
    EXPECT_EQ(seats[3]->device(), 0);
    // Equal measured loads on 2 and 5, device 0 busier: 2 and 5 tie on load and sessions.
    seats[0]->record_render(100, kStart);
    seats[1]->record_render(30, kStart);
    seats[2]->record_render(30, kStart);
    Seat next = place(placement);
    EXPECT_EQ(next->device(), 2);
    // Now 2 has two sessions, 5 one, at the same load: 5.
    EXPECT_EQ(place(placement)->device(), 5);
}

// A burst of sessions opened before any of them renders: each new one weighs what the measured
// open sessions weigh on average, and sessions that closed weigh nothing, however recently they
// rendered. The device's own average still shows their frames, as GetScene reports it. (On two
// H200s, 8 streams opened right after a 32-stream run all landed on one GPU by the device
// averages: its 440 frames/s against 841 for 16 streams spread over both.)
TEST(DevicePlacement, ABurstOfNewSessionsSpreadsOverTheDevices) {
    DevicePlacement placement({0, 1}, 8);
    {
        // Device 0 served a heavy session that has just closed; device 1 a lighter one.
        Seat heavy = place(placement), light = place(placement);
        ASSERT_EQ(heavy->device(), 0);
        heavy->record_render(900, kStart);
        light->record_render(300, kStart);
    }
    EXPECT_GT(load_of(placement, 0, kStart), load_of(placement, 1, kStart)) << "the devices still show the frames";
    std::vector<Seat> burst;
    for (int i = 0; i < 4; ++i) burst.push_back(place(placement));
    int on_device_0 = 0;
    for (const Seat& seat : burst) on_device_0 += seat->device() == 0;
    EXPECT_EQ(on_device_0, 2) << "closed sessions weigh nothing: the burst alternates";

    // One of them measures 100 ms (0.05 s/s at tau 2 s): the other three, unmeasured, each weigh
    // as much, so both devices weigh 0.1 and the next goes by sessions, then index.
    burst[0]->record_render(100, kStart);  // device 0
    Seat fifth = place(placement);
    EXPECT_EQ(fifth->device(), 0);
    // Device 0 now weighs 0.15 against 0.1: device 1.
    EXPECT_EQ(place(placement)->device(), 1);
}

TEST(DevicePlacement, AdmissionCountsPerDevice) {
    DevicePlacement placement({0, 1}, 1);
    Seat a = place(placement);
    a->record_render(1000, kStart);  // device 0 is busy, but it is device 1 that is empty
    Seat b;
    ASSERT_TRUE(placement.place("city", &b, kStart).ok());
    EXPECT_EQ(b->device(), 1);
    // Both full: refused, naming the limit; a full device is never chosen, however idle.
    Seat c;
    const grpc::Status full = placement.place("city", &c, kStart);
    EXPECT_EQ(full.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    EXPECT_EQ(full.error_message(),
              "max-sessions: every device (2) already runs 1 sessions; retry later or on another server");
    a.reset();
    ASSERT_TRUE(placement.place("city", &c, kStart).ok());
    EXPECT_EQ(c->device(), 0);
}

TEST(DevicePlacement, SceneResidentFromFirstSessionToLastHolder) {
    DevicePlacement placement({0, 1}, 8);
    EXPECT_TRUE(placement.residency("city").empty());
    Seat a = place(placement, "city");
    Seat b = place(placement, "city");
    Seat c = place(placement, "park");  // device 0: fewest sessions tie, lowest index
    auto city = placement.residency("city");
    ASSERT_EQ(city.size(), 2u);
    EXPECT_EQ(city[0].device, 0);
    EXPECT_EQ(city[0].sessions, 1);
    EXPECT_EQ(city[1].device, 1);
    EXPECT_EQ(city[1].sessions, 1);
    ASSERT_EQ(placement.residency("park").size(), 1u);
    EXPECT_EQ(c->device(), 0);
    b.reset();  // the last city session on device 1: released there
    city = placement.residency("city");
    ASSERT_EQ(city.size(), 1u);
    EXPECT_EQ(city[0].device, 0);
    // An idle pooled renderer keeps the scene resident after its last session ends.
    placement.hold_pooled(a->slot(), "city");
    a.reset();
    city = placement.residency("city");
    ASSERT_EQ(city.size(), 1u);
    EXPECT_EQ(city[0].sessions, 0);
    EXPECT_EQ(city[0].pooled_renderers, 1);
    placement.release_pooled(0, "city");
    EXPECT_TRUE(placement.residency("city").empty());
    EXPECT_EQ(placement.residency("park").size(), 1u);
}

/// A ServerCore on two simulated devices, no gRPC: the renderer pool and scene unloads.
TEST(DevicePlacement, UnloadWhileADeviceHoldsTheScene) {
    server::ServerOptions o = test_options();
    o.devices = {0, 1};
    server::ServerCore core(o);
    ASSERT_TRUE(core.scenes().load("doomed", kTestScene, false, true, nullptr).ok());
    std::unique_ptr<server::SceneRegistry::Lease> lease;
    ASSERT_TRUE(core.scenes().acquire("doomed", &lease).ok());
    Seat on0 = place(core.placement(), "doomed"), on1 = place(core.placement(), "doomed");
    ASSERT_EQ(on1->device(), 1);
    // A unary render on device 1 leaves its renderer pooled there, holding the scene.
    core.release_renderer(core.acquire_renderer(lease->scene(), *on1), lease->scene(), *on1);
    on1.reset();
    auto where = core.placement().residency("doomed");
    ASSERT_EQ(where.size(), 2u);
    EXPECT_EQ(where[1].device, 1);
    EXPECT_EQ(where[1].sessions, 0);
    EXPECT_EQ(where[1].pooled_renderers, 1);
    EXPECT_EQ(core.stats().pooled_renderers, 1);

    // Unloaded while device 0's session renders it: the pooled renderer lets go at once, the
    // session keeps its copy until it ends.
    server::SceneSummary summary;
    bool freed = true;
    ASSERT_TRUE(core.scenes().unload("doomed", &summary, &freed).ok());
    EXPECT_FALSE(freed);
    where = core.placement().residency("doomed");
    ASSERT_EQ(where.size(), 1u);
    EXPECT_EQ(where[0].device, 0);
    EXPECT_EQ(where[0].sessions, 1);
    EXPECT_EQ(core.stats().pooled_renderers, 0);
    on0.reset();
    lease.reset();
    EXPECT_TRUE(core.placement().residency("doomed").empty());
    EXPECT_EQ(core.scenes().get("doomed", &summary).error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST(DevicePlacement, PooledRenderersStayOnTheirDevice) {
    server::ServerOptions o = test_options();
    o.devices = {0, 1};
    server::ServerCore core(o);
    std::unique_ptr<server::SceneRegistry::Lease> lease;
    ASSERT_TRUE(core.scenes().load("city", kTestScene, false, true, nullptr).ok());
    ASSERT_TRUE(core.scenes().acquire("city", &lease).ok());
    Seat on0 = place(core.placement()), on1 = place(core.placement());
    auto renderer = core.acquire_renderer(lease->scene(), *on0);
    Renderer* made_on0 = renderer.get();
    core.release_renderer(std::move(renderer), lease->scene(), *on0);
    // Device 1 makes its own; device 0 gets its pooled one back.
    auto other = core.acquire_renderer(lease->scene(), *on1);
    EXPECT_NE(other.get(), made_on0);
    EXPECT_EQ(core.stats().pooled_renderers, 1);
    auto again = core.acquire_renderer(lease->scene(), *on0);
    EXPECT_EQ(again.get(), made_on0);
    EXPECT_EQ(core.stats().pooled_renderers, 0);
}

TEST(DevicePlacement, TheLargestMaxSessionsOnSeveralDevicesSaturates) {
    server::ServerOptions o = test_options();
    o.devices = {0, 1, 2};
    o.limits.max_sessions = std::numeric_limits<int>::max();
    o.encode_workers = 0;  // auto: at most --max-sessions times the devices
    server::ServerCore core(o);
    EXPECT_EQ(core.options().encode_workers, server::kMinEncodeWorkers) << "the CPU backend's encoders";
    std::unique_ptr<server::Admission::Ticket> ticket;
    EXPECT_TRUE(core.admission().admit(&ticket).ok());
    EXPECT_EQ(place(core.placement())->device(), 0);
}

TEST(ParseGpus, AllCountsAndLists) {
    using server::parse_gpus;
    EXPECT_EQ(parse_gpus("all", 4), (std::vector<int>{0, 1, 2, 3}));
    EXPECT_EQ(parse_gpus("all", std::nullopt), (std::vector<int>{0}));  // the CPU backend: the host
    EXPECT_EQ(parse_gpus("2", 4), (std::vector<int>{0, 1}));
    EXPECT_EQ(parse_gpus("3", std::nullopt), (std::vector<int>{0, 1, 2}));
    EXPECT_EQ(parse_gpus("0,2", 4), (std::vector<int>{0, 2}));
    EXPECT_EQ(parse_gpus("3,1", 4), (std::vector<int>{1, 3}));
    EXPECT_EQ(parse_gpus("7,9", std::nullopt), (std::vector<int>{7, 9}));
}

std::string gpus_error(const std::string& value, std::optional<int> present) {
    try {
        server::parse_gpus(value, present);
    } catch (const Error& e) {
        return e.what();
    }
    return "(accepted)";
}

TEST(ParseGpus, BadValuesNameTheFlagAndTheProblem) {
    const std::string expected = "expected all, a device count N or a comma-separated list of device indices (0,2)";
    EXPECT_EQ(gpus_error("", 2), "--gpus: '': empty; " + expected);
    EXPECT_EQ(gpus_error("two", 2), "--gpus: 'two': " + expected);
    EXPECT_EQ(gpus_error("-1", 2), "--gpus: '-1': " + expected);
    EXPECT_EQ(gpus_error("0", 2), "--gpus: '0': a device count must be at least 1");
    EXPECT_EQ(gpus_error("3", 2), "--gpus: '3': 3 devices asked for, but 2 CUDA devices are present (0..1)");
    EXPECT_EQ(gpus_error("0,3", 2), "--gpus: '0,3': device 3 does not exist: 2 CUDA devices are present (0..1)");
    EXPECT_EQ(gpus_error("0,1", 1), "--gpus: '0,1': device 1 does not exist: 1 CUDA device is present (0..0)");
    EXPECT_EQ(gpus_error("all", 0), "--gpus: 'all': no CUDA device is present");
    EXPECT_EQ(gpus_error("0,0", 2), "--gpus: '0,0': device 0 is named twice");
    EXPECT_EQ(gpus_error("0,,1", 2), "--gpus: '0,,1': '' is not a device index; " + expected);
    EXPECT_EQ(gpus_error("0, 1", 2), "--gpus: '0, 1': ' 1' is not a device index; " + expected);
    EXPECT_EQ(gpus_error("99999999999", std::nullopt), "--gpus: '99999999999': " + expected);
    EXPECT_EQ(gpus_error("65", std::nullopt),
              "--gpus: '65': 65 devices asked for, but the CPU backend simulates at most 64 devices");
    EXPECT_EQ(gpus_error("1,64", std::nullopt),
              "--gpus: '1,64': device 64 does not exist: the CPU backend simulates at most 64 devices");
}

TEST(ParseGpus, TheServerRefusesABadValue) {
    Child server({CATGS_SERVER_BINARY, "--address", "127.0.0.1:0", "--backend", "cpu", "--gpus", "0,x"});
    EXPECT_EQ(server.wait(std::chrono::seconds(20)).value_or(-1), 2) << server.output();
    EXPECT_NE(server.output().find("--gpus: '0,x': 'x' is not a device index"), std::string::npos) << server.output();
}

/// Collects the server's log lines for the test's length (nothing else logs meanwhile: the
/// sink list is changed only while no server runs).
class LogCapture {
public:
    LogCapture() : sink_(std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(kLines)) {
        spdlog::default_logger()->sinks().push_back(sink_);
    }
    ~LogCapture() {
        auto& sinks = spdlog::default_logger()->sinks();
        sinks.erase(std::remove(sinks.begin(), sinks.end(), sink_), sinks.end());
    }
    bool contains(const std::string& text) const {
        for (const std::string& line : sink_->last_formatted())
            if (line.find(text) != std::string::npos) return true;
        return false;
    }

private:
    static constexpr std::size_t kLines = 512;  // a test's server logs a few dozen lines
    std::shared_ptr<spdlog::sinks::ringbuffer_sink_mt> sink_;
};

grpc::Status get_scene(const std::shared_ptr<grpc::Channel>& channel, const std::string& id, v1::SceneInfo* info) {
    auto stub = v1::SceneService::NewStub(channel);
    grpc::ClientContext context;
    v1::GetSceneRequest request;
    request.set_scene_id(id);
    return stub->GetScene(&context, request, info);
}

TEST(MultiDeviceServer, SessionsLandOnDifferentDevicesAndGetSceneShowsThem) {
    LogCapture log;
    {
        server::ServerOptions o = test_options();
        o.devices = {0, 1};
        o.limits.max_sessions = 1;  // per device: two sessions in all
        auto s = start_server(o);
        auto channel = channel_to(s->port());
        const auto path = uav_path(2);
        std::vector<std::unique_ptr<StreamClient>> clients;
        for (int i = 0; i < 2; ++i) {
            clients.push_back(std::make_unique<StreamClient>(channel));
            ASSERT_TRUE(clients.back()->open(session_config(v1::ENCODING_JPEG)));
            ASSERT_TRUE(clients.back()->send(frame_request(1, path[0], 0)));
            v1::Frame frame;
            ASSERT_TRUE(clients.back()->stream->Read(&frame));
            ASSERT_FALSE(frame.has_error()) << frame.error().message();
        }
        v1::SceneInfo info;
        ASSERT_TRUE(get_scene(channel, "city", &info).ok());
        EXPECT_EQ(info.sessions(), 2u);
        ASSERT_EQ(info.devices_size(), 2);
        for (int d = 0; d < 2; ++d) {
            EXPECT_EQ(info.devices(d).device(), d);
            EXPECT_EQ(info.devices(d).sessions(), 1u);
            EXPECT_GT(info.devices(d).render_load(), 0) << "each device rendered a frame";
        }
        EXPECT_EQ(info.device_bytes(), 0u) << "the CPU backend holds no device memory";
        // The third session: both devices are full, so the server is.
        StreamClient third(channel);
        ASSERT_TRUE(third.open(session_config(v1::ENCODING_JPEG)));
        const grpc::Status refused = third.finish();
        EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
        EXPECT_NE(refused.error_message().find("max-sessions: the server already runs 2 of 2 sessions"),
                  std::string::npos)
            << refused.error_message();
        for (auto& client : clients) EXPECT_TRUE(client->close().ok());
        // The closed sessions' renderers wait in the pool, each keeping the scene on its device.
        const auto each_device_holds_one_idle = [&] {
            return get_scene(channel, "city", &info).ok() && info.devices_size() == 2 &&
                   info.devices(0).pooled_renderers() == 1 && info.devices(1).pooled_renderers() == 1 &&
                   info.devices(0).sessions() == 0 && info.devices(1).sessions() == 0;
        };
        EXPECT_TRUE(eventually(each_device_holds_one_idle));

        // A unary render is placed too; it takes a pooled renderer of its device and gives it back.
        v1::Frame frame;
        ASSERT_TRUE(render_once(channel,
                                render_request(session_config(v1::ENCODING_JPEG), frame_request(1, path[0], 0)), &frame)
                        .ok());
        EXPECT_TRUE(eventually(each_device_holds_one_idle));
    }
    EXPECT_TRUE(log.contains("scene city on device 0"));
    EXPECT_TRUE(log.contains("scene city on device 1"));
}

TEST(MultiDeviceServer, DefaultIsOneDevice) {
    const server::ServerOptions o = test_options();
    EXPECT_EQ(o.devices, std::vector<int>{0});
    auto s = start_server(o);
    EXPECT_EQ(s->core().placement().devices(), std::vector<int>{0});
    // Today's worker counts; each further GPU adds its own render workers.
    const server::WorkerCounts one = server::auto_worker_counts("cuda", 16, 8);
    EXPECT_EQ(one.render, server::kRenderWorkersPerGpu);
    EXPECT_EQ(server::auto_worker_counts("cuda", 16, 8, 2).render, 2 * one.render);
    EXPECT_EQ(server::auto_worker_counts("cpu", 16, 8, 4).render, server::auto_worker_counts("cpu", 16, 8).render)
        << "simulated devices share the host's cores";
}

}  // namespace
}  // namespace catgs::test
