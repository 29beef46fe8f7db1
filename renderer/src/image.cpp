#include "catgs/image.hpp"

#include <cmath>
#include <cstdlib>
#include <limits>

#include "catgs/error.hpp"
#include "catgs/stages/blend.hpp"

namespace catgs {

ImageRGB8 to_rgb8(const ImageF& image) {
    ImageRGB8 out;
    out.width = image.width;
    out.height = image.height;
    out.rgb.resize(image.rgb.size());
    for (std::size_t i = 0; i < image.rgb.size(); ++i) out.rgb[i] = quantize_8bit(image.rgb[i]);
    return out;
}

ImageError compare(const ImageRGB8& image, const ImageRGB8& reference) {
    if (image.width != reference.width || image.height != reference.height || image.rgb.size() != reference.rgb.size())
        throw Error("compare: image sizes differ");
    ImageError e;
    double squared = 0;
    std::size_t over = 0;
    for (std::size_t i = 0; i < image.rgb.size(); ++i) {
        int d = std::abs(static_cast<int>(image.rgb[i]) - static_cast<int>(reference.rgb[i]));
        squared += static_cast<double>(d) * d;
        if (d > e.max_abs) e.max_abs = d;
        if (d > 1) ++over;
    }
    const double n = image.rgb.empty() ? 1.0 : static_cast<double>(image.rgb.size());
    const double mse = squared / n;
    e.psnr = mse == 0 ? std::numeric_limits<double>::infinity() : 10.0 * std::log10(255.0 * 255.0 / mse);
    e.fraction_over_one = static_cast<double>(over) / n;
    return e;
}

}  // namespace catgs
