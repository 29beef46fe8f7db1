// A frame rendered without its background: what one shard of a sharded frame contributes
// (sharded_renderer.hpp). The per-pixel quantities are those of the split-tile merge
// (stages/split.hpp): colour R (premultiplied) and transmittance A, so that partials compose
// front to back as (R1, A1) o (R2, A2) = (R1 + A1 R2, A1 A2) and the pixel is R + A * background.
// Float whatever the backend's precision: partials travel between GPUs, and a float's
// rounding is the image's.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace catgs {

struct PartialImage {
    int width = 0, height = 0;
    std::vector<float> colour;         ///< 3 per pixel, row-major, top row first
    std::vector<float> transmittance;  ///< 1 per pixel
    /// 1 where the pixel's blend stopped (graphdeco's stop below kMinTransmittance): the
    /// unsharded blend stops there too, so the shards behind add nothing.
    std::vector<std::uint8_t> stopped;

    void resize(int w, int h) {
        width = w;
        height = h;
        const std::size_t pixels = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
        colour.assign(3 * pixels, 0.0f);
        transmittance.assign(pixels, 1.0f);
        stopped.assign(pixels, 0);
    }
};

/// A partial frame left in a GPU's memory (Renderer::render_partial_on_device), laid out as
/// PartialImage: device pointers into the renderer's own buffers, valid until that renderer's
/// next frame. A PartialCompositor (renderer.hpp) reads them, on their device or another.
struct DevicePartialImage {
    int device = -1;  ///< the CUDA device holding the buffers
    int width = 0, height = 0;
    const float* colour = nullptr;  ///< 3 per pixel
    const float* transmittance = nullptr;
    const std::uint8_t* stopped = nullptr;
};

}  // namespace catgs
