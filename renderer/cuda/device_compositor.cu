#include "device_compositor.hpp"

#include <cuda_runtime_api.h>

#include <algorithm>
#include <map>
#include <string>
#include <utility>

#include "catgs/error.hpp"
#include "catgs/parallel.hpp"
#include "catgs/shard_plan.hpp"
#include "composite.cuh"
#include "cuda_check.hpp"
#include "device_buffer.hpp"
#include "frame_buffers.hpp"

namespace catgs::cuda {
namespace {

/// Bands the finished image is copied to the host in (copy_out): enough that the host's copy
/// of one overlaps the device's copy of the next, few enough that each copy is megabytes.
constexpr int kCopyBands = 8;

float event_ms(cudaEvent_t from, cudaEvent_t to) {
    float ms = 0;
    CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, from, to));
    return ms;
}

std::string size_of(const DevicePartialImage& p) {
    return std::to_string(p.width) + "x" + std::to_string(p.height);
}

/// The partials' shared size; throws catgs::Error naming the first that differs, is empty, or
/// lacks a buffer.
std::size_t check_partials(const std::vector<DevicePartialImage>& partials) {
    if (partials.empty()) throw Error("composite: no partial images to composite");
    if (partials.size() > static_cast<std::size_t>(kMaxShards))
        throw Error("composite: " + std::to_string(partials.size()) + " partials, more than the " +
                    std::to_string(kMaxShards) + " shards a frame may have");
    const DevicePartialImage& first = partials.front();
    for (std::size_t s = 0; s < partials.size(); ++s) {
        const DevicePartialImage& p = partials[s];
        if (p.width != first.width || p.height != first.height || p.width <= 0 || p.height <= 0)
            throw Error("composite: partial " + std::to_string(s) + " is " + size_of(p) + ", expected " +
                        (s == 0 ? "a positive size" : "the first partial's " + size_of(first)));
        if (!p.colour || !p.transmittance || !p.stopped || p.device < 0)
            throw Error("composite: partial " + std::to_string(s) +
                        " has no device buffers (not rendered by render_partial_on_device)");
    }
    return static_cast<std::size_t>(first.width) * static_cast<std::size_t>(first.height);
}

template <typename V>
void copy_from(V* destination, int device, const V* source, int source_device, std::size_t count, cudaStream_t s) {
    CATGS_CUDA_CHECK(cudaMemcpyPeerAsync(destination, device, source, source_device, count * sizeof(V), s));
}

}  // namespace

struct DeviceCompositor::Impl {
    /// One shard's partial copied from another device.
    struct Staged {
        DeviceArray<float> colour, transmittance;
        DeviceArray<std::uint8_t> stopped;
    };
    enum Mark { start, transferred, merged, copied, kMarks };

    explicit Impl(int index) : device(index) {}
    /// Whether `source`'s partials reach this device directly: the two are peers, and the
    /// source's memory pool (where renderers keep their buffers) is opened to this device,
    /// once per source.
    bool peer(int source);
    /// The pointers the composite reads for partial `index`: where it lies, or its staged copy.
    void gather(const DevicePartialImage& partial, std::size_t index, std::size_t pixels, CompositeTimes& times,
                const float** colour, const float** transmittance, const std::uint8_t** stopped);
    void copy_out(int width, int height, ImageF* rgb, ImageRGB8* rgb8);

    int device;
    cudaStream_t stream = nullptr;
    std::array<cudaEvent_t, kMarks> marks{};
    std::array<cudaEvent_t, kCopyBands> band_copied{};
    std::vector<std::unique_ptr<Staged>> staged;
    DeviceArray<std::uint8_t> image_rgb8;
    DeviceArray<float> image_rgb;
    PinnedArray<std::uint8_t> host_rgb8;
    PinnedArray<float> host_rgb;
    std::map<int, bool> peers;
};

/// The finished image to the caller, in bands of rows: each band's copy to pinned memory is
/// enqueued at once, and host threads take each band into the caller's image as it lands.
void DeviceCompositor::Impl::copy_out(int width, int height, ImageF* rgb, ImageRGB8* rgb8) {
    const std::size_t row = 3 * static_cast<std::size_t>(width);
    const int rows_per_band = (height + kCopyBands - 1) / kCopyBands;
    const int bands = (height + rows_per_band - 1) / rows_per_band;
    // Band b's first value and its count of values.
    auto span = [&](int band) {
        const int first_row = band * rows_per_band;
        return std::pair{row * static_cast<std::size_t>(first_row),
                         row * static_cast<std::size_t>(std::min(rows_per_band, height - first_row))};
    };
    for (int band = 0; band < bands; ++band) {
        const auto [first, count] = span(band);
        if (rgb8)
            CATGS_CUDA_CHECK(cudaMemcpyAsync(host_rgb8.data() + first, image_rgb8.data() + first, count,
                                             cudaMemcpyDeviceToHost, stream));
        if (rgb)
            CATGS_CUDA_CHECK(cudaMemcpyAsync(host_rgb.data() + first, image_rgb.data() + first, count * sizeof(float),
                                             cudaMemcpyDeviceToHost, stream));
        CATGS_CUDA_CHECK(cudaEventRecord(band_copied[static_cast<std::size_t>(band)], stream));
    }
    CATGS_CUDA_CHECK(cudaEventRecord(marks[copied], stream));
    const std::size_t values = row * static_cast<std::size_t>(height);
    if (rgb8) {
        rgb8->width = width;
        rgb8->height = height;
        rgb8->rgb.resize(values);
    }
    if (rgb) {
        rgb->width = width;
        rgb->height = height;
        rgb->rgb.resize(values);
    }
    // One host thread a band: a single thread's copy out of pinned memory (measured 3 ms for a
    // 4K frame's 25 MB on the H200 host) took six times the device's copy across PCIe.
    parallel_for(static_cast<std::size_t>(bands), 1, bands, [&](std::size_t band_begin, std::size_t band_end) {
        for (std::size_t band = band_begin; band < band_end; ++band) {
            CATGS_CUDA_CHECK(cudaEventSynchronize(band_copied[band]));
            const auto [first, count] = span(static_cast<int>(band));
            if (rgb8) std::copy_n(host_rgb8.data() + first, count, rgb8->rgb.data() + first);
            if (rgb) std::copy_n(host_rgb.data() + first, count, rgb->rgb.data() + first);
        }
    });
    CATGS_CUDA_CHECK(cudaEventSynchronize(marks[copied]));
}

DeviceCompositor::DeviceCompositor(int device) : impl_(std::make_unique<Impl>(device)) {
    int count = 0;
    if (cudaGetDeviceCount(&count) != cudaSuccess || device < 0 || device >= count) {
        cudaGetLastError();
        throw Error("composite: no CUDA device " + std::to_string(device) + " (" + std::to_string(count) + " present)");
    }
    CATGS_CUDA_CHECK(cudaSetDevice(device));
    CATGS_CUDA_CHECK(cudaStreamCreateWithFlags(&impl_->stream, cudaStreamNonBlocking));
    for (cudaEvent_t& e : impl_->marks) CATGS_CUDA_CHECK(cudaEventCreate(&e));
    for (cudaEvent_t& e : impl_->band_copied) CATGS_CUDA_CHECK(cudaEventCreateWithFlags(&e, cudaEventDisableTiming));
}

DeviceCompositor::~DeviceCompositor() {
    // Not checked: runs in a destructor. The buffers free themselves on this device.
    cudaSetDevice(impl_->device);
    if (impl_->stream) cudaStreamSynchronize(impl_->stream);
    for (cudaEvent_t e : impl_->marks)
        if (e) cudaEventDestroy(e);
    for (cudaEvent_t e : impl_->band_copied)
        if (e) cudaEventDestroy(e);
    cudaStream_t stream = impl_->stream;
    impl_.reset();  // its buffers are freed (stream-ordered) before their stream goes
    if (stream) cudaStreamDestroy(stream);
}

int DeviceCompositor::device() const {
    return impl_->device;
}

bool DeviceCompositor::Impl::peer(int source) {
    if (auto found = peers.find(source); found != peers.end()) return found->second;
    int can = 0;
    CATGS_CUDA_CHECK(cudaDeviceCanAccessPeer(&can, device, source));
    bool direct = false;
    if (can) {
        // Renderers allocate from their device's current pool (device_buffer.hpp), which
        // peer access (cudaDeviceEnablePeerAccess) does not open: the pool is opened instead.
        cudaMemPool_t pool = nullptr;
        CATGS_CUDA_CHECK(cudaDeviceGetMemPool(&pool, source));
        cudaMemAccessDesc access{};
        access.location.type = cudaMemLocationTypeDevice;
        access.location.id = device;
        access.flags = cudaMemAccessFlagsProtReadWrite;
        CATGS_CUDA_CHECK(cudaMemPoolSetAccess(pool, &access, 1));
        direct = true;
    }
    peers[source] = direct;
    return direct;
}

void DeviceCompositor::Impl::gather(const DevicePartialImage& p, std::size_t index, std::size_t pixels,
                                    CompositeTimes& times, const float** colour, const float** transmittance,
                                    const std::uint8_t** stopped) {
    if (p.device == device) {
        *colour = p.colour;
        *transmittance = p.transmittance;
        *stopped = p.stopped;
        return;
    }
    ++(peer(p.device) ? times.peer_direct : times.peer_staged);
    while (staged.size() <= index) staged.push_back(std::make_unique<Staged>());
    Staged& s = *staged[index];
    s.colour.reserve(3 * pixels, stream);
    s.transmittance.reserve(pixels, stream);
    s.stopped.reserve(pixels, stream);
    copy_from(s.colour.data(), device, p.colour, p.device, 3 * pixels, stream);
    copy_from(s.transmittance.data(), device, p.transmittance, p.device, pixels, stream);
    copy_from(s.stopped.data(), device, p.stopped, p.device, pixels, stream);
    *colour = s.colour.data();
    *transmittance = s.transmittance.data();
    *stopped = s.stopped.data();
}

CompositeTimes DeviceCompositor::composite(const std::vector<DevicePartialImage>& front_to_back,
                                           const std::array<float, 3>& background, ImageF* rgb, ImageRGB8* rgb8) {
    const std::size_t pixels = check_partials(front_to_back);
    Impl& c = *impl_;
    CATGS_CUDA_CHECK(cudaSetDevice(c.device));
    CompositeTimes times;
    CompositeArgs args{};
    args.pixels = pixels;
    args.shards = static_cast<int>(front_to_back.size());
    args.background = Vec3<float>{background[0], background[1], background[2]};
    if (rgb8) {
        c.image_rgb8.reserve(3 * pixels, c.stream);
        c.host_rgb8.reserve(3 * pixels);
    }
    if (rgb) {
        c.image_rgb.reserve(3 * pixels, c.stream);
        c.host_rgb.reserve(3 * pixels);
    }
    args.out = PixelOutputs{};
    args.out.rgb8 = rgb8 ? c.image_rgb8.data() : nullptr;
    args.out.rgb = rgb ? c.image_rgb.data() : nullptr;
    args.out.rows_per_copy_band = 1;

    CATGS_CUDA_CHECK(cudaEventRecord(c.marks[Impl::start], c.stream));
    for (std::size_t s = 0; s < front_to_back.size(); ++s)
        c.gather(front_to_back[s], s, pixels, times, &args.colour[s], &args.transmittance[s], &args.stopped[s]);
    CATGS_CUDA_CHECK(cudaEventRecord(c.marks[Impl::transferred], c.stream));
    composite_partials(args, c.stream);
    CATGS_CUDA_CHECK(cudaEventRecord(c.marks[Impl::merged], c.stream));
    c.copy_out(front_to_back.front().width, front_to_back.front().height, rgb, rgb8);
    times.transfer_ms = event_ms(c.marks[Impl::start], c.marks[Impl::transferred]);
    times.merge_ms = event_ms(c.marks[Impl::transferred], c.marks[Impl::merged]);
    times.copy_out_ms = event_ms(c.marks[Impl::merged], c.marks[Impl::copied]);
    times.total_ms = event_ms(c.marks[Impl::start], c.marks[Impl::copied]);
    return times;
}

}  // namespace catgs::cuda
