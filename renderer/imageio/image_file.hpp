// Image files through OpenImageIO. Kept out of catgs_core: GPU hosts lack OpenImageIO and its
// dependency closure is over 300 MB, so only tools that write files link this library.
#pragma once

#include <string>

#include "catgs/image.hpp"

namespace catgs {

/// 8-bit file; the format follows the extension (.png, .jpg, .tif, ...). Throws catgs::Error
/// naming the path and OpenImageIO's reason.
void write_image(const std::string& path, const ImageRGB8& image);
/// 32-bit float file (OpenEXR for .exr), unclamped values.
void write_image(const std::string& path, const ImageF& image);
/// Reads any 8-bit-convertible image as RGB8 (alpha dropped, grey expanded).
ImageRGB8 read_image_rgb8(const std::string& path);

}  // namespace catgs
