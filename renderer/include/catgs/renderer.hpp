// The backend-neutral renderer interface that tools and the server use. A renderer holds one
// scene (uploaded once on the GPU) and renders frames of it; each instance owns its stage
// buffers, so one instance serves one stream at a time.
#pragma once

#include <memory>
#include <string>

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
    /// Forgets the inter-frame cache and pose history (a new stream on the same renderer).
    virtual void reset_cache() = 0;
    virtual std::string name() const = 0;
};

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
