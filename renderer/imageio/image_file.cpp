#include "image_file.hpp"

#include <OpenImageIO/imageio.h>

#include "catgs/error.hpp"

namespace catgs {
namespace {

template <typename Pixel>
void write_pixels(const std::string& path, int width, int height, OIIO::TypeDesc type, const Pixel* data) {
    auto out = OIIO::ImageOutput::create(path);
    if (!out) throw Error(path + ": cannot write image: " + OIIO::geterror());
    OIIO::ImageSpec spec(width, height, 3, type);
    if (!out->open(path, spec)) throw Error(path + ": cannot write image: " + out->geterror());
    if (!out->write_image(type, data) || !out->close()) throw Error(path + ": cannot write image: " + out->geterror());
}

}  // namespace

void write_image(const std::string& path, const ImageRGB8& image) {
    write_pixels(path, image.width, image.height, OIIO::TypeDesc::UINT8, image.rgb.data());
}

void write_image(const std::string& path, const ImageF& image) {
    write_pixels(path, image.width, image.height, OIIO::TypeDesc::FLOAT, image.rgb.data());
}

ImageRGB8 read_image_rgb8(const std::string& path) {
    auto in = OIIO::ImageInput::open(path);
    if (!in) throw Error(path + ": cannot read image: " + OIIO::geterror());
    const OIIO::ImageSpec& spec = in->spec();
    ImageRGB8 image;
    image.width = spec.width;
    image.height = spec.height;
    std::vector<std::uint8_t> all(static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels);
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, all.data()))
        throw Error(path + ": cannot read image: " + in->geterror());
    image.rgb.resize(static_cast<std::size_t>(spec.width) * spec.height * 3);
    for (std::size_t p = 0; p < image.rgb.size() / 3; ++p)
        for (int c = 0; c < 3; ++c) image.rgb[3 * p + c] = all[p * spec.nchannels + (spec.nchannels >= 3 ? c : 0)];
    return image;
}

}  // namespace catgs
