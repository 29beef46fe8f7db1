#include "catgs/server/device_placement.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "catgs/device_list.hpp"
#include "catgs/error.hpp"

namespace catgs::server {

std::vector<int> parse_gpus(const std::string& value, std::optional<int> present) {
    return parse_device_list("--gpus", value, present, kMaxSimulatedDevices);
}

struct DevicePlacement::Seat::State {
    struct Residency {
        int sessions = 0, pooled = 0;
    };
    /// A decaying average of render seconds per second (kLoadTimeConstant).
    struct Load {
        double value = 0;  // as of `updated`
        Clock::time_point updated{};
    };
    struct Device {
        int index = 0;
        int sessions = 0;
        Load load;                                // every frame rendered there, by sessions open or closed
        std::map<std::string, Residency> scenes;  // only the resident ones
    };
    /// A session's own share of its device's load, and whether any frame has measured it.
    struct SessionLoad {
        int slot = 0;
        bool measured = false;
        Load load;
    };
    mutable std::mutex mutex;  // a leaf (lock order: server_core.hpp)
    std::vector<Device> devices;
    std::map<std::uint64_t, SessionLoad> sessions;  // the open ones, by seat id
    std::uint64_t next_seat = 0;
    /// The mean load of the measured open sessions when placement last saw some: what a new
    /// session is expected to cost while none is measured (0 before the first measurement).
    double expected_session_load = 0;
    int max_sessions = 1;
    double time_constant_s = 1;

    // mutex held. The load decayed to `now` (a time sampled before another thread's record
    // may lie before `updated`: no growth then).
    double load_at(const Load& l, Clock::time_point now) const {
        const double elapsed = std::max(0.0, std::chrono::duration<double>(now - l.updated).count());
        return l.value * std::exp(-elapsed / time_constant_s);
    }
    double load_at(const Device& d, Clock::time_point now) const { return load_at(d.load, now); }

    // mutex held. Each frame adds its seconds spread over the time constant: at a steady rate
    // the average converges to render seconds per second.
    void add(Load& l, double render_s, Clock::time_point now) const {
        l.value = load_at(l, now) + render_s / time_constant_s;
        l.updated = std::max(l.updated, now);
    }

    // mutex held. What placing one more session on each device would weigh against: the loads
    // of the sessions open there, each not yet measured counted at the mean of the measured
    // ones. Not the device's own average, which still holds closed sessions' frames for a few
    // time constants, and sees nothing of sessions opened in a burst until they render: both
    // sent a burst of new viewers to one GPU (2 x H200, 2026-12-04: 8 streams opened after a
    // 32-stream run all landed on device 1, 440 frames/s against 841 with 16 spread over both).
    std::vector<double> placement_costs(Clock::time_point now) {
        double measured_sum = 0;
        int measured = 0;
        for (const auto& [id, session] : sessions)
            if (session.measured) {
                measured_sum += load_at(session.load, now);
                ++measured;
            }
        if (measured > 0) expected_session_load = measured_sum / measured;
        std::vector<double> cost(devices.size(), 0.0);
        for (const auto& [id, session] : sessions)
            cost[static_cast<std::size_t>(session.slot)] +=
                session.measured ? load_at(session.load, now) : expected_session_load;
        return cost;
    }

    // mutex held.
    void hold(int slot, const std::string& scene_id, bool pooled) {
        Device& d = devices[static_cast<std::size_t>(slot)];
        auto [it, uploaded] = d.scenes.try_emplace(scene_id);
        (pooled ? it->second.pooled : it->second.sessions)++;
        if (uploaded) spdlog::info("scene {} resident on device {} (its first session there)", scene_id, d.index);
    }

    // mutex held.
    void release(int slot, const std::string& scene_id, bool pooled) {
        Device& d = devices[static_cast<std::size_t>(slot)];
        auto it = d.scenes.find(scene_id);
        if (it == d.scenes.end()) return;
        int& count = pooled ? it->second.pooled : it->second.sessions;
        if (count > 0) --count;
        if (it->second.sessions == 0 && it->second.pooled == 0) {
            d.scenes.erase(it);
            spdlog::info("scene {} released from device {} (no session or pooled renderer there holds it)", scene_id,
                         d.index);
        }
    }
};

DevicePlacement::DevicePlacement(std::vector<int> devices, int max_sessions_per_device,
                                 std::chrono::duration<double> load_time_constant)
    : devices_(std::move(devices)), state_(std::make_shared<Seat::State>()) {
    if (devices_.empty()) throw Error("device placement: no devices");
    state_->max_sessions = std::max(1, max_sessions_per_device);
    state_->time_constant_s = std::max(1e-3, load_time_constant.count());
    for (int index : devices_) state_->devices.push_back({index, 0, {}, {}});
}

DevicePlacement::Seat::Seat(std::shared_ptr<State> state, int slot, int device, std::string scene_id, std::uint64_t id)
    : state_(std::move(state)), slot_(slot), device_(device), scene_id_(std::move(scene_id)), id_(id) {}

DevicePlacement::Seat::~Seat() {
    std::lock_guard lock(state_->mutex);
    --state_->devices[static_cast<std::size_t>(slot_)].sessions;
    state_->sessions.erase(id_);
    state_->release(slot_, scene_id_, /*pooled=*/false);
}

void DevicePlacement::Seat::record_render(double render_ms, Clock::time_point now) const {
    if (!(render_ms > 0)) return;  // NaN or nothing measured: no information
    std::lock_guard lock(state_->mutex);
    state_->add(state_->devices[static_cast<std::size_t>(slot_)].load, render_ms / 1000.0, now);
    if (auto it = state_->sessions.find(id_); it != state_->sessions.end()) {
        state_->add(it->second.load, render_ms / 1000.0, now);
        it->second.measured = true;
    }
}

grpc::Status DevicePlacement::place(const std::string& scene_id, std::unique_ptr<Seat>* out, Clock::time_point now) {
    std::lock_guard lock(state_->mutex);
    const std::vector<double> costs = state_->placement_costs(now);
    int best = -1;
    double best_load = 0;
    for (int slot = 0; slot < static_cast<int>(state_->devices.size()); ++slot) {
        const Seat::State::Device& d = state_->devices[static_cast<std::size_t>(slot)];
        if (d.sessions >= state_->max_sessions) continue;
        const double load = costs[static_cast<std::size_t>(slot)];
        // Scanned in index order: a later device wins only with less load, or equal load and
        // fewer sessions.
        if (best < 0 || load < best_load ||
            (load == best_load && d.sessions < state_->devices[static_cast<std::size_t>(best)].sessions)) {
            best = slot;
            best_load = load;
        }
    }
    if (best < 0)
        return {grpc::StatusCode::RESOURCE_EXHAUSTED,
                "max-sessions: every device (" + std::to_string(state_->devices.size()) + ") already runs " +
                    std::to_string(state_->max_sessions) + " sessions; retry later or on another server"};
    Seat::State::Device& chosen = state_->devices[static_cast<std::size_t>(best)];
    ++chosen.sessions;
    state_->hold(best, scene_id, /*pooled=*/false);
    const std::uint64_t id = state_->next_seat++;
    state_->sessions[id] = Seat::State::SessionLoad{best, false, {}};
    out->reset(new Seat(state_, best, chosen.index, scene_id, id));
    return grpc::Status::OK;
}

void DevicePlacement::hold_pooled(int slot, const std::string& scene_id) {
    std::lock_guard lock(state_->mutex);
    state_->hold(slot, scene_id, /*pooled=*/true);
}

void DevicePlacement::release_pooled(int slot, const std::string& scene_id) {
    std::lock_guard lock(state_->mutex);
    state_->release(slot, scene_id, /*pooled=*/true);
}

std::vector<DevicePlacement::SceneOnDevice> DevicePlacement::residency(const std::string& scene_id,
                                                                       Clock::time_point now) const {
    std::lock_guard lock(state_->mutex);
    std::vector<SceneOnDevice> where;
    for (const Seat::State::Device& d : state_->devices) {
        auto it = d.scenes.find(scene_id);
        if (it == d.scenes.end()) continue;
        where.push_back({d.index, it->second.sessions, it->second.pooled, state_->load_at(d, now)});
    }
    return where;
}

std::vector<DevicePlacement::DeviceLoad> DevicePlacement::loads(Clock::time_point now) const {
    std::lock_guard lock(state_->mutex);
    std::vector<DeviceLoad> all;
    for (const Seat::State::Device& d : state_->devices) all.push_back({d.index, d.sessions, state_->load_at(d, now)});
    return all;
}

}  // namespace catgs::server
