// Rendered images, row-major, RGB interleaved, top row first.
#pragma once

#include <cstdint>
#include <vector>

namespace catgs {

/// Float image: C + T * background per pixel, not clamped (EXR output keeps it as is).
struct ImageF {
    int width = 0, height = 0;
    std::vector<float> rgb;
    void resize(int w, int h) {
        width = w;
        height = h;
        rgb.assign(3 * static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0.0f);
    }
};

struct ImageRGB8 {
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgb;
};

/// Clamps to [0, 1] and rounds to 8 bits (catgs::quantize_8bit).
ImageRGB8 to_rgb8(const ImageF& image);

/// Image comparison against a reference: PSNR over 8-bit values (infinite when identical),
/// the largest absolute 8-bit difference, and the fraction of channel values that differ
/// by more than one level.
struct ImageError {
    double psnr = 0;
    int max_abs = 0;
    double fraction_over_one = 0;
};
ImageError compare(const ImageRGB8& image, const ImageRGB8& reference);

}  // namespace catgs
