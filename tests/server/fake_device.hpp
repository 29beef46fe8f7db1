// A simulated GPU for the CPU backend (ServerOptions::renderer_factory): renderers that render
// on the CPU but account "device memory" the way the CUDA backend holds it (one shared copy of
// each scene, plus each renderer's grow-only arenas, proportional to the largest image it drew,
// held until it is destroyed) and fail the way it fails when that memory runs out
// (catgs::OutOfMemoryError naming cudaErrorMemoryAllocation).
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <mutex>

#include "catgs/error.hpp"
#include "catgs/renderer.hpp"

namespace catgs::test {

class FakeDevice : public std::enable_shared_from_this<FakeDevice> {
public:
    /// capacity: device bytes; arena_bytes_per_pixel: what each session's arenas take per pixel.
    FakeDevice(std::uint64_t capacity, std::uint64_t arena_bytes_per_pixel)
        : capacity_(capacity), per_pixel_(arena_bytes_per_pixel) {}

    std::function<std::unique_ptr<Renderer>()> factory() {
        return [device = shared_from_this()] { return std::unique_ptr<Renderer>(new DeviceRenderer(device)); };
    }
    std::uint64_t used() const {
        std::lock_guard lock(mutex_);
        return used_;
    }

private:
    /// Like shared_device_scene: one copy per scene while any renderer holds it.
    void upload(const Scene* scene, std::uint64_t bytes) {
        std::lock_guard lock(mutex_);
        auto& entry = scenes_[scene];
        if (entry.holders == 0) {
            if (used_ + bytes > capacity_) {
                scenes_.erase(scene);
                throw OutOfMemoryError(
                    "CUDA error in cudaMalloc(&scene->positions) at device_buffer.hpp:48: "
                    "cudaErrorMemoryAllocation: out of memory");
            }
            used_ += bytes;
            entry.bytes = bytes;
        }
        ++entry.holders;
    }
    /// A renderer's arenas grow to `bytes` (never shrink), or it runs out of memory.
    void grow_arenas(std::uint64_t& held, std::uint64_t bytes) {
        std::lock_guard lock(mutex_);
        if (bytes <= held) return;
        if (used_ + (bytes - held) > capacity_)
            throw OutOfMemoryError(
                "CUDA error in cudaMallocAsync(&data_, target, stream) at device_buffer.hpp:39: "
                "cudaErrorMemoryAllocation: out of memory");
        used_ += bytes - held;
        held = bytes;
    }
    void free_arenas(std::uint64_t held) {
        std::lock_guard lock(mutex_);
        used_ -= held;
    }
    void release(const Scene* scene) {
        std::lock_guard lock(mutex_);
        auto it = scenes_.find(scene);
        if (it == scenes_.end()) return;
        if (--it->second.holders == 0) {
            used_ -= it->second.bytes;
            scenes_.erase(it);
        }
    }

    class DeviceRenderer final : public Renderer {
    public:
        explicit DeviceRenderer(std::shared_ptr<FakeDevice> device)
            : device_(std::move(device)), inner_(make_renderer("cpu", Precision::single, 1)) {}
        ~DeviceRenderer() override {
            if (scene_) device_->release(scene_.get());
            device_->free_arenas(arenas_);
        }
        void set_scene(std::shared_ptr<const Scene> scene) override {
            device_->upload(scene.get(), scene->bytes());
            if (scene_) device_->release(scene_.get());
            scene_ = scene;
            inner_->set_scene(std::move(scene));
        }
        FrameStats render(const Camera& camera, const RenderOptions& options, ImageF& out,
                          const FrameHints* hints) override {
            device_->grow_arenas(arenas_, arena(camera));
            FrameStats stats = inner_->render(camera, options, out, hints);
            stats.arena_bytes = arenas_;
            return stats;
        }
        FrameStats render_rgb8(const Camera& camera, const RenderOptions& options, ImageRGB8& out,
                               const FrameHints* hints) override {
            device_->grow_arenas(arenas_, arena(camera));
            FrameStats stats = inner_->render_rgb8(camera, options, out, hints);
            stats.arena_bytes = arenas_;
            return stats;
        }
        void reset_cache() override { inner_->reset_cache(); }
        std::string name() const override { return "fake-device/" + inner_->name(); }

    private:
        std::uint64_t arena(const Camera& camera) const {
            return device_->per_pixel_ * static_cast<std::uint64_t>(camera.intrinsics.width) *
                   static_cast<std::uint64_t>(camera.intrinsics.height);
        }
        std::shared_ptr<FakeDevice> device_;
        std::unique_ptr<Renderer> inner_;
        std::shared_ptr<const Scene> scene_;
        std::uint64_t arenas_ = 0;  // device bytes of its arenas
    };

    struct Uploaded {
        std::uint64_t bytes = 0;
        int holders = 0;
    };
    const std::uint64_t capacity_, per_pixel_;
    mutable std::mutex mutex_;
    std::map<const Scene*, Uploaded> scenes_;
    std::uint64_t used_ = 0;
};

}  // namespace catgs::test
