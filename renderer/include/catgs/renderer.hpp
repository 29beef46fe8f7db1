// The backend-neutral renderer interface that tools and the server use. A renderer holds one
// scene (uploaded once on the GPU) and renders frames of it; each instance owns its stage
// buffers, so one instance serves one stream at a time.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/error.hpp"
#include "catgs/image.hpp"
#include "catgs/partial_image.hpp"
#include "catgs/render_options.hpp"
#include "catgs/scene.hpp"

namespace catgs {

enum class Precision { single, double_ };

/// "float" or "double"; throws catgs::Error otherwise.
Precision parse_precision(const std::string& name);

class Renderer {
public:
    virtual ~Renderer() = default;
    /// Makes `scene` the one rendered by the following frames (the GPU backend uploads it).
    virtual void set_scene(std::shared_ptr<const Scene> scene) = 0;
    /// `hints` (optional) carry the client's flight plan or velocity for the CaT-GS cache.
    virtual FrameStats render(const Camera& camera, const RenderOptions& options, ImageF& out,
                              const FrameHints* hints = nullptr) = 0;
    /// 8-bit output; the GPU backend quantises on the device and copies a quarter of the bytes.
    virtual FrameStats render_rgb8(const Camera& camera, const RenderOptions& options, ImageRGB8& out,
                                   const FrameHints* hints = nullptr);
    /// The frame without its background (partial_image.hpp): one shard's share of a sharded
    /// frame (sharded_renderer.hpp). The same pipeline as render, stopped before the
    /// background is added. Throws catgs::Error where the backend has no partial output.
    virtual FrameStats render_partial(const Camera& camera, const RenderOptions& options, PartialImage& out,
                                      const FrameHints* hints = nullptr) {
        (void)camera, (void)options, (void)out, (void)hints;
        throw Error("render_partial: not supported by backend " + name());
    }
    /// render_partial without the copy to the host: the partial stays in the renderer's device
    /// buffers (valid until its next frame, complete when this returns), for a
    /// PartialCompositor to merge with other shards' on a GPU. Throws catgs::Error where the
    /// backend has no device memory (the CPU).
    virtual FrameStats render_partial_on_device(const Camera& camera, const RenderOptions& options,
                                                DevicePartialImage& out, const FrameHints* hints = nullptr) {
        (void)camera, (void)options, (void)out, (void)hints;
        throw Error("render_partial_on_device: not supported by backend " + name());
    }
    /// Forgets the inter-frame cache and pose history (a new stream on the same renderer).
    virtual void reset_cache() = 0;
    virtual std::string name() const = 0;
};

/// Where a sharded frame's composite spent its time (CUDA events on the compositing device).
struct CompositeTimes {
    double transfer_ms = 0;  ///< the other devices' partials copied to the compositing device
    double merge_ms = 0;     ///< the front-to-back composite and the background
    double copy_out_ms = 0;  ///< the finished image to host memory
    double total_ms = 0;
    int peer_direct = 0;  ///< partials copied device to device (peer access: NVLink or PCIe)
    int peer_staged = 0;  ///< partials the driver staged through host memory (no peer access)
};

/// Composites shards' partials that lie in GPU memory (render_partial_on_device) on one GPU:
/// copies those of other devices over (CUDA peer copies), merges front to back with the
/// split merge's operation (merge_shard_partial), adds the background, and copies the image
/// to the host. One instance serves one frame at a time.
class PartialCompositor {
public:
    virtual ~PartialCompositor() = default;
    /// `front_to_back`: one partial per shard, all of one size, in visibility order. Either
    /// output may be null. Throws catgs::Error naming the partial whose size differs from the
    /// first's, or when there is none.
    virtual CompositeTimes composite(const std::vector<DevicePartialImage>& front_to_back,
                                     const std::array<float, 3>& background, ImageF* rgb, ImageRGB8* rgb8) = 0;
    /// The device it composites on.
    virtual int device() const = 0;
};

/// A compositor on `device` of `backend`. Throws catgs::Error for a backend without device
/// memory ("cpu": its shards composite on the host, composite_partials) or one not built in.
std::unique_ptr<PartialCompositor> make_partial_compositor(const std::string& backend, int device = 0);

/// Backends compiled into this binary, e.g. "cpu" or "cpu, cuda".
std::string available_backends();

/// backend: "cpu" or "cuda". threads: CPU worker threads (<= 0: all). device: the CUDA device
/// the renderer and its scene copy live on (the renderer selects it around each call, so one
/// thread may drive renderers of several devices); the CPU backend ignores it. Throws
/// catgs::Error for an unknown backend, one not built in, or (CUDA) when no device is usable.
std::unique_ptr<Renderer> make_renderer(const std::string& backend, Precision precision, int threads = 0,
                                        int device = 0);

/// Devices `backend` renders on: the CUDA devices present (0 when none, or CUDA is not built
/// in); 1 for the CPU backend (the host).
int device_count(const std::string& backend);

}  // namespace catgs
