// Sessions across the devices of one host (catgs-server --gpus, docs/multi-gpu.md): which
// devices the server renders on, where each scene is resident, how loaded each device is,
// and on which device a new session is placed.
//
// - A session is placed when it opens and keeps its device: its renderer (and, on CUDA, its
//   arenas and the scene copy it shares) lives there.
// - A scene is resident on a device while a session there renders it or an idle pooled
//   renderer there still holds it; the first such holder uploads it (on CUDA), the last one
//   releases it (renderer_factory.cpp keeps one copy per scene and device).
// - A device's load is its measured render time per second: each frame's FrameStats::total_ms
//   (GPU event time on CUDA) feeds an exponentially decaying average.
// - A new session goes to the device whose open sessions weigh least (each its own measured
//   load, one not yet measured at the mean of those measured) and that still has room below
//   --max-sessions (a per-device limit); ties go to the fewest sessions, then the lowest index.
//
// Thread safety: every member may be called from any thread. The mutex is a leaf (lock
// order: server_core.hpp); Seat destructors and record_render take it briefly.
#pragma once

#include <grpcpp/support/status.h>

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace catgs::server {

/// The CPU backend's simulated devices are bookkeeping only (they share the host's cores and
/// its scene copy); more than this is a typing error, not a configuration.
inline constexpr int kMaxSimulatedDevices = 64;
/// The load average's time constant: long enough that the frames of a few seconds smooth out
/// one slow key frame, short enough that a device freed by closed sessions is seen as idle
/// within seconds.
inline constexpr std::chrono::milliseconds kLoadTimeConstant{2000};

/// The device indices `--gpus VALUE` names, in increasing order: "all" (every device present),
/// N (devices 0..N-1) or a comma-separated list of distinct indices ("0,2").
/// `present`: the devices the backend has (CUDA: catgs::device_count), or nullopt for the CPU
/// backend's simulated devices, where "all" is one device (the host) and N up to
/// kMaxSimulatedDevices. Throws catgs::Error whose message starts "--gpus: ", naming the value
/// or the device at fault.
std::vector<int> parse_gpus(const std::string& value, std::optional<int> present);

class DevicePlacement {
public:
    using Clock = std::chrono::steady_clock;

    /// devices: the backend's device indices (parse_gpus), at least one.
    /// max_sessions_per_device: --max-sessions.
    DevicePlacement(std::vector<int> devices, int max_sessions_per_device,
                    std::chrono::duration<double> load_time_constant = kLoadTimeConstant);

    /// One session's place on one device; releases it (and its hold on the scene there) when
    /// destroyed.
    class Seat {
    public:
        ~Seat();
        Seat(const Seat&) = delete;
        Seat& operator=(const Seat&) = delete;
        /// The device index as the backend numbers it (what make_renderer takes).
        int device() const { return device_; }
        /// The device's position in the placement's list (what hold_pooled takes).
        int slot() const { return slot_; }
        const std::string& scene_id() const { return scene_id_; }
        /// Feeds one frame's measured render time into the device's load.
        void record_render(double render_ms, Clock::time_point now = Clock::now()) const;

    private:
        friend class DevicePlacement;
        struct State;
        Seat(std::shared_ptr<State> state, int slot, int device, std::string scene_id, std::uint64_t id);
        std::shared_ptr<State> state_;
        int slot_, device_;
        std::string scene_id_;
        std::uint64_t id_;
    };

    /// Places a session rendering `scene_id` on the device with room whose open sessions weigh
    /// least (see the header comment), and makes the scene resident there. RESOURCE_EXHAUSTED naming max-sessions when
    /// every device is full.
    grpc::Status place(const std::string& scene_id, std::unique_ptr<Seat>* out, Clock::time_point now = Clock::now());

    /// An idle pooled renderer of device `slot` starts or stops holding `scene_id`.
    void hold_pooled(int slot, const std::string& scene_id);
    void release_pooled(int slot, const std::string& scene_id);

    struct SceneOnDevice {
        int device = 0;
        int sessions = 0;          ///< sessions placed there rendering the scene
        int pooled_renderers = 0;  ///< idle pooled renderers there still holding it
        double load = 0;           ///< the device's render seconds per second
    };
    /// The devices `scene_id` is resident on, in device order.
    std::vector<SceneOnDevice> residency(const std::string& scene_id, Clock::time_point now = Clock::now()) const;

    struct DeviceLoad {
        int device = 0;
        int sessions = 0;  ///< sessions placed there, every scene
        double load = 0;   ///< render seconds per second
    };
    std::vector<DeviceLoad> loads(Clock::time_point now = Clock::now()) const;
    const std::vector<int>& devices() const { return devices_; }

private:
    std::vector<int> devices_;
    std::shared_ptr<Seat::State> state_;
};

}  // namespace catgs::server
