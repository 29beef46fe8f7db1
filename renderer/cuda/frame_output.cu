// The frame's pixels from the kernels to the caller: where rasterize and merge write them,
// and copy_out (copy_out.cuh), each band of tile rows copied on the copy stream once its tiles
// are drawn and taken into the caller's image once it is on the host, while the rest of the
// frame is still drawn and copied.
#include <cuda_runtime_api.h>

#include <algorithm>
#include <cstddef>
#include <string>
#include <type_traits>

#include "catgs/error.hpp"
#include "copy_out.cuh"
#include "cuda_check.hpp"
#include "cuda_renderer.hpp"
#include "renderer_state.cuh"

namespace catgs::cuda {

template <typename T>
PixelOutputs CudaRenderer<T>::Impl::device_outputs(const Frame<T>& f, const HostOutputs& out) {
    PixelBuffers<T>& p = buffers.pixels;
    PixelOutputs device{out.rgb8 ? p.image_rgb8.data() : nullptr,
                        out.rgb || out.any_partial() ? p.image_float.data() : nullptr,
                        out.any_partial() ? p.image_transmittance.data() : nullptr,
                        out.any_partial() ? p.image_stopped.data() : nullptr,
                        copy_waits_on_counts() ? copy.tiles_drawn : nullptr,
                        rows_per_copy_band(f),
                        nullptr,
                        nullptr};
    if (heavy_pixels_to_host(f, out)) {  // begin_frame reserved them
        device.heavy_rgb8 = host.heavy_rgb8.device();
        device.heavy_tiles = host.heavy_tiles.device();
    }
    return device;
}

template <typename T>
CopyOutArgs CudaRenderer<T>::Impl::copy_out_args(const Frame<T>& f, const HostOutputs& out) {
    PixelOutputs device = device_outputs(f, out);
    // A partial left on the device for a compositor is not copied.
    if (!out.rgb && !out.partial) device.rgb = nullptr;
    if (!out.partial) {
        device.transmittance = nullptr;
        device.stopped = nullptr;
    }
    return CopyOutArgs{f.view.width, device.rgb8,     device.rgb,          device.transmittance, device.stopped,
                       &host.rgb8,   &host.rgb_float, &host.transmittance, &host.stopped};
}

/// The copy bands whose tile rows lie below `rows_end`, now that the pass drawing them is
/// enqueued: each waits on its tile count, or, without stream memory waits, on an event after
/// the pass. Waits come only after the launches that satisfy them, so no stream can block a
/// launch its own wait needs.
template <typename T>
void CudaRenderer<T>::Impl::copy_drawn_rows(const Frame<T>& f, int rows_end, const HostOutputs& out) {
    const int per_band = rows_per_copy_band(f);
    const CopyOutArgs args = copy_out_args(f, out);
    bool after_pass = false;  // the fallback's event is recorded once a pass
    for (; copied_copy_bands * per_band < f.view.tiles_y; ++copied_copy_bands) {
        const int band = copied_copy_bands;
        const int begin = band * per_band, end = std::min(begin + per_band, f.view.tiles_y);
        if (end > rows_end) break;
        const cudaStream_t s = copy.band[band];
        CATGS_CUDA_CHECK(cudaStreamWaitEvent(s, copy.ready, 0));
        const unsigned int tiles = static_cast<unsigned int>((end - begin) * f.view.tiles_x);
        const bool counted = copy_waits_on_counts();
        if (!counted || !wait_for_count(s, &copy.tiles_drawn[band], tiles)) {
            if (counted) copy_waits = false;  // the driver refused: later frames count nothing
            if (!after_pass) CATGS_CUDA_CHECK(cudaEventRecord(copy.drawn, stream));
            after_pass = true;
            CATGS_CUDA_CHECK(cudaStreamWaitEvent(s, copy.drawn, 0));
        }
        cuda::copy_out(args, begin * kTileSize, std::min(end * kTileSize, f.view.height), s);
        CATGS_CUDA_CHECK(cudaEventRecord(copy.copied[band], s));
    }
}

/// The renderer's stream waits for the last copy; copy_out's time runs from the last pass's
/// merge mark, so it is the part of the copy the drawing did not hide.
template <typename T>
void CudaRenderer<T>::Impl::end_copies() {
    for (int band = 0; band < copied_copy_bands; ++band)
        CATGS_CUDA_CHECK(cudaStreamWaitEvent(stream, copy.copied[band], 0));
    events.record(Event::copy_out, stream);
    CATGS_CUDA_CHECK(cudaMemcpyAsync(host.counters.data(), buffers.window.counters.data(), sizeof(Counters),
                                     cudaMemcpyDeviceToHost, stream));
}

/// The heavy lists' pixels, which rasterize wrote to host memory, into `image` (over what the
/// copy bands brought of their tiles), once the frame's counters are on the host.
template <typename T>
void CudaRenderer<T>::Impl::take_heavy_pixels(const Frame<T>& f, ImageRGB8& image) {
    if (!f.heavy_used) return;
    const std::uint64_t listed = std::min<std::uint64_t>(host.counters.data()->tasks.heavy_tiles, heavy_room());
    const int width = f.view.width, height = f.view.height;
    for (std::uint64_t i = 0; i < listed; ++i) {
        const std::uint32_t tile = host.heavy_tiles.data()[i];
        if (tile >= f.tiles)
            throw Error("cuda renderer: heavy list " + std::to_string(i) + " names tile " + std::to_string(tile) +
                        " of " + std::to_string(f.tiles));
        const int x0 = static_cast<int>(tile % f.view.tiles_x) * kTileSize;
        const int y0 = static_cast<int>(tile / f.view.tiles_x) * kTileSize;
        const int columns = std::min(kTileSize, width - x0), rows = std::min(kTileSize, height - y0);
        const std::uint8_t* pixels = host.heavy_rgb8.data() + i * 3 * kTilePixels;
        for (int r = 0; r < rows; ++r)
            std::copy_n(pixels + 3 * r * kTileSize, 3 * columns,
                        image.rgb.data() + 3 * (static_cast<std::size_t>(y0 + r) * width + x0));
    }
}

/// The image into the caller's buffers, each copy band as soon as it is on the host (the rest
/// are still being drawn or copied), then the frame's counters (end_copies enqueued them) and
/// the heavy lists' pixels, when they came through host memory.
template <typename T>
void CudaRenderer<T>::Impl::copy_out(const Frame<T>& f, const HostOutputs& out, const PixelOutputs& device) {
    const int width = f.view.width, height = f.view.height;
    // Sized, not cleared: every value is overwritten below, and a stream of frames reuses them.
    if (out.rgb8) {
        out.rgb8->width = width;
        out.rgb8->height = height;
        out.rgb8->rgb.resize(3 * f.pixels);
    }
    if (out.rgb) {
        out.rgb->width = width;
        out.rgb->height = height;
        out.rgb->rgb.resize(3 * f.pixels);
    }
    if (out.partial) {
        PartialImage& p = *out.partial;
        p.width = width;
        p.height = height;
        p.colour.resize(3 * f.pixels);
        p.transmittance.resize(f.pixels);
        p.stopped.resize(f.pixels);
    }
    const int per_band = rows_per_copy_band(f) * kTileSize;
    // Large images are taken by the copier's threads, each band as it lands; the guard waits
    // for them before anything else reads the image, also when a CUDA call below throws.
    const bool spread = 3 * f.pixels >= kSpreadCopyBytes;
    HostCopiesDone taken(host_copier);
    for (int band = 0; band * per_band < height; ++band) {
        CATGS_CUDA_CHECK(cudaEventSynchronize(copy.copied[band]));
        const std::size_t first = static_cast<std::size_t>(band) * per_band * width;
        const std::size_t count = static_cast<std::size_t>(std::min(per_band, height - band * per_band)) * width;
        auto take = [&](auto* host_values, auto& values, std::size_t channels) {
            const auto* source = host_values + channels * first;
            auto* target = values.data() + channels * first;
            static_assert(std::is_same_v<std::remove_cv_t<std::remove_pointer_t<decltype(source)>>,
                                         std::remove_pointer_t<decltype(target)>>,
                          "the staging holds the caller's value type");
            if (spread)
                host_copier.copy(target, source, channels * count * sizeof(*source));
            else
                std::copy_n(source, channels * count, target);
        };
        if (out.rgb8) take(host.rgb8.data(), out.rgb8->rgb, 3);
        if (out.rgb) take(host.rgb_float.data(), out.rgb->rgb, 3);
        if (out.partial) {
            take(host.rgb_float.data(), out.partial->colour, 3);
            take(host.transmittance.data(), out.partial->transmittance, 1);
            take(host.stopped.data(), out.partial->stopped, 1);
        }
    }
    CATGS_CUDA_CHECK(cudaStreamSynchronize(stream));
    host_copier.wait();  // the heavy lists' pixels go over what the bands brought
    if (device.heavy_rgb8) take_heavy_pixels(f, *out.rgb8);
    events.add(Stage::copy_out, Event::rasterize, Event::copy_out);
    if (out.device_partial) {
        DevicePartialImage& d = *out.device_partial;
        CATGS_CUDA_CHECK(cudaGetDevice(&d.device));
        d.width = width;
        d.height = height;
        d.colour = buffers.pixels.image_float.data();
        d.transmittance = buffers.pixels.image_transmittance.data();
        d.stopped = buffers.pixels.image_stopped.data();
    }
}

template PixelOutputs CudaRenderer<float>::Impl::device_outputs(const Frame<float>&, const HostOutputs&);
template PixelOutputs CudaRenderer<double>::Impl::device_outputs(const Frame<double>&, const HostOutputs&);
template CopyOutArgs CudaRenderer<float>::Impl::copy_out_args(const Frame<float>&, const HostOutputs&);
template CopyOutArgs CudaRenderer<double>::Impl::copy_out_args(const Frame<double>&, const HostOutputs&);
template void CudaRenderer<float>::Impl::copy_drawn_rows(const Frame<float>&, int, const HostOutputs&);
template void CudaRenderer<double>::Impl::copy_drawn_rows(const Frame<double>&, int, const HostOutputs&);
template void CudaRenderer<float>::Impl::end_copies();
template void CudaRenderer<double>::Impl::end_copies();
template void CudaRenderer<float>::Impl::take_heavy_pixels(const Frame<float>&, ImageRGB8&);
template void CudaRenderer<double>::Impl::take_heavy_pixels(const Frame<double>&, ImageRGB8&);
template void CudaRenderer<float>::Impl::copy_out(const Frame<float>&, const HostOutputs&, const PixelOutputs&);
template void CudaRenderer<double>::Impl::copy_out(const Frame<double>&, const HostOutputs&, const PixelOutputs&);

}  // namespace catgs::cuda
