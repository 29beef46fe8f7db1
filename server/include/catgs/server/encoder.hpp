// Frame encoders: JPEG (TurboJPEG), PNG (libpng) and raw RGB8. Pure functions of the image,
// safe to call from several threads at once (each thread keeps its own TurboJPEG handle).
// No OpenImageIO: the server must run on bare GPU hosts.
#pragma once

#include <string>

#include "catgs/image.hpp"

namespace catgs::server {

enum class Format { jpeg, png, raw_rgb8 };

struct EncodeSettings {
    Format format = Format::jpeg;
    int jpeg_quality = 85;  ///< 1..100
    bool jpeg_444 = false;  ///< 4:4:4 chroma instead of 4:2:0
};

/// Encodes `image` into `out` (replacing its contents). Throws catgs::Error on failure.
void encode_image(const ImageRGB8& image, const EncodeSettings& settings, std::string& out);

const char* format_name(Format format);

}  // namespace catgs::server
