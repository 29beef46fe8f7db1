#include <map>
#include <mutex>

#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "catgs/renderer.hpp"

#if CATGS_HAVE_CUDA
#include "cuda_check.hpp"
#include "cuda_renderer.hpp"
#include "device_compositor.hpp"
#endif

namespace catgs {
namespace {

template <typename T>
class CpuBackend final : public Renderer {
public:
    explicit CpuBackend(int threads) : renderer_(threads) {}
    void set_scene(std::shared_ptr<const Scene> scene) override {
        scene_ = std::move(scene);
        renderer_.reset_cache();
    }
    FrameStats render(const Camera& camera, const RenderOptions& options, ImageF& out,
                      const FrameHints* hints) override {
        if (!scene_) throw Error("cpu renderer: no scene set");
        return renderer_.render(*scene_, camera, options, out, hints);
    }
    FrameStats render_partial(const Camera& camera, const RenderOptions& options, PartialImage& out,
                              const FrameHints* hints) override {
        if (!scene_) throw Error("cpu renderer: no scene set");
        return renderer_.render_partial(*scene_, camera, options, out, hints);
    }
    void reset_cache() override { renderer_.reset_cache(); }
    std::string name() const override { return sizeof(T) == 4 ? "cpu/float" : "cpu/double"; }

private:
    CpuRenderer<T> renderer_;
    std::shared_ptr<const Scene> scene_;
};

#if CATGS_HAVE_CUDA
/// One copy per host scene and device, shared by every renderer of that device that renders
/// it (a server's sessions there): the entry lives as long as some renderer holds the device
/// scene, and each such renderer also holds the host scene, so its address cannot be reused
/// meanwhile. The caller has made `device` current.
std::shared_ptr<const cuda::DeviceScene> shared_device_scene(const std::shared_ptr<const Scene>& scene, int device,
                                                             cudaStream_t stream) {
    static std::mutex mutex;
    static std::map<std::pair<int, const Scene*>, std::weak_ptr<const cuda::DeviceScene>> uploaded;
    std::lock_guard lock(mutex);
    for (auto it = uploaded.begin(); it != uploaded.end();) it = it->second.expired() ? uploaded.erase(it) : ++it;
    const std::pair<int, const Scene*> key{device, scene.get()};
    if (auto found = uploaded.find(key); found != uploaded.end())
        if (auto copy = found->second.lock()) return copy;
    auto copy = std::make_shared<const cuda::DeviceScene>(*scene, stream);
    uploaded[key] = copy;
    return copy;
}

/// Makes `device` current on the calling thread before a renderer's CUDA calls: renderers of
/// several devices share the server's worker threads, and CUDA acts on the current device.
struct DeviceSelection {
    explicit DeviceSelection(int index) : device(index) { select(); }
    void select() const { CATGS_CUDA_CHECK(cudaSetDevice(device)); }
    int device;
};

template <typename T>
class CudaBackend final : public Renderer {
public:
    explicit CudaBackend(int device) : selection_(device) {}
    ~CudaBackend() override {
        // The members free their device memory and stream on the device they were made on.
        cudaSetDevice(selection_.device);
    }
    void set_scene(std::shared_ptr<const Scene> scene) override {
        selection_.select();
        renderer_.set_scene(shared_device_scene(scene, selection_.device, renderer_.stream()));
        scene_ = std::move(scene);
    }
    FrameStats render(const Camera& camera, const RenderOptions& options, ImageF& out,
                      const FrameHints* hints) override {
        selection_.select();
        return renderer_.render(camera, options, nullptr, &out, hints);
    }
    FrameStats render_rgb8(const Camera& camera, const RenderOptions& options, ImageRGB8& out,
                           const FrameHints* hints) override {
        selection_.select();
        return renderer_.render(camera, options, &out, nullptr, hints);
    }
    FrameStats render_partial(const Camera& camera, const RenderOptions& options, PartialImage& out,
                              const FrameHints* hints) override {
        selection_.select();
        return renderer_.render_partial(camera, options, out, hints);
    }
    FrameStats render_partial_on_device(const Camera& camera, const RenderOptions& options, DevicePartialImage& out,
                                        const FrameHints* hints) override {
        selection_.select();
        return renderer_.render_partial_on_device(camera, options, out, hints);
    }
    void reset_cache() override {
        selection_.select();
        renderer_.reset_cache();
    }
    std::string name() const override { return sizeof(T) == 4 ? "cuda/float" : "cuda/double"; }

private:
    DeviceSelection selection_;  // first: made current before renderer_ is constructed
    cuda::CudaRenderer<T> renderer_;
    std::shared_ptr<const Scene> scene_;  // keeps the shared device copy's key alive
};
#endif

/// Throws catgs::Error unless `backend` is "cuda", built in, with a usable device: naming an
/// unknown backend, one not built into this binary, or why no device is usable.
void require_cuda_backend(const std::string& backend) {
    if (backend != "cuda") throw Error("unknown backend '" + backend + "' (available: " + available_backends() + ")");
#if CATGS_HAVE_CUDA
    std::string reason;
    if (!cuda::device_available(&reason)) throw Error("backend 'cuda': no usable CUDA device (" + reason + ")");
#else
    throw Error("backend 'cuda' is not built into this binary (available: " + available_backends() + ")");
#endif
}

}  // namespace

FrameStats Renderer::render_rgb8(const Camera& camera, const RenderOptions& options, ImageRGB8& out,
                                 const FrameHints* hints) {
    ImageF image;
    FrameStats stats = render(camera, options, image, hints);
    out = to_rgb8(image);
    return stats;
}

Precision parse_precision(const std::string& name) {
    if (name == "float") return Precision::single;
    if (name == "double") return Precision::double_;
    throw Error("unknown precision '" + name + "' (expected float or double)");
}

std::string available_backends() {
#if CATGS_HAVE_CUDA
    return "cpu, cuda";
#else
    return "cpu";
#endif
}

int device_count(const std::string& backend) {
    if (backend == "cpu") return 1;
#if CATGS_HAVE_CUDA
    if (backend == "cuda") {
        int count = 0;
        if (cudaGetDeviceCount(&count) != cudaSuccess) {
            cudaGetLastError();  // clear the error state for later calls
            return 0;
        }
        return count;
    }
#endif
    return 0;
}

std::unique_ptr<Renderer> make_renderer(const std::string& backend, Precision precision, int threads, int device) {
    if (backend == "cpu") {
        if (precision == Precision::double_) return std::make_unique<CpuBackend<double>>(threads);
        return std::make_unique<CpuBackend<float>>(threads);
    }
    require_cuda_backend(backend);
#if CATGS_HAVE_CUDA
    if (precision == Precision::double_) return std::make_unique<CudaBackend<double>>(device);
    return std::make_unique<CudaBackend<float>>(device);
#else
    (void)device;
    return nullptr;  // not reached: require_cuda_backend threw
#endif
}

std::unique_ptr<PartialCompositor> make_partial_compositor(const std::string& backend, int device) {
    if (backend == "cpu")
        throw Error("backend 'cpu' has no device compositor: its shards composite on the host (composite_partials)");
    require_cuda_backend(backend);
#if CATGS_HAVE_CUDA
    return std::make_unique<cuda::DeviceCompositor>(device);
#else
    (void)device;
    return nullptr;  // not reached: require_cuda_backend threw
#endif
}

}  // namespace catgs
