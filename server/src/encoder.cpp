#include "catgs/server/encoder.hpp"

#include <png.h>
#include <turbojpeg.h>

#include <csetjmp>
#include <cstdio>
#include <cstring>

#include "catgs/error.hpp"

namespace catgs::server {
namespace {

/// zlib level for PNG. PNG is the lossless / debug path and the encoder runs per frame, so
/// speed matters more than the last percent of size: level 1 is several times faster than
/// zlib's default 6 on rendered images for files only slightly larger.
constexpr int kPngCompressionLevel = 1;

/// One TurboJPEG compressor per encoder thread: creating a handle per frame costs more than
/// encoding a small frame, and a handle must not be used by two threads at once.
class JpegHandle {
public:
    JpegHandle() : handle_(tjInitCompress()) {}
    ~JpegHandle() {
        if (handle_) tjDestroy(handle_);
    }
    JpegHandle(const JpegHandle&) = delete;
    JpegHandle& operator=(const JpegHandle&) = delete;
    tjhandle get() const { return handle_; }

private:
    tjhandle handle_;
};

void encode_jpeg(const ImageRGB8& image, const EncodeSettings& s, std::string& out) {
    thread_local JpegHandle handle;
    if (!handle.get()) throw Error("jpeg encoder: tjInitCompress failed");
    const int subsampling = s.jpeg_444 ? TJSAMP_444 : TJSAMP_420;
    // Compress straight into the output string, pre-sized to TurboJPEG's worst case so that it
    // never reallocates (TJFLAG_NOREALLOC), then trimmed.
    const unsigned long capacity = tjBufSize(image.width, image.height, subsampling);
    out.resize(capacity);
    auto* buffer = reinterpret_cast<unsigned char*>(out.data());
    unsigned long size = capacity;
    if (tjCompress2(handle.get(), image.rgb.data(), image.width, 0, image.height, TJPF_RGB, &buffer, &size, subsampling,
                    s.jpeg_quality, TJFLAG_NOREALLOC) != 0)
        throw Error(std::string("jpeg encoder: ") + tjGetErrorStr2(handle.get()));
    out.resize(size);
}

struct PngWriteState {
    std::string* out;
    char error[256];
};

void png_append(png_structp png, png_bytep data, png_size_t length) {
    auto* state = static_cast<PngWriteState*>(png_get_io_ptr(png));
    state->out->append(reinterpret_cast<const char*>(data), length);
}

void png_flush(png_structp) {}

[[noreturn]] void png_fail(png_structp png, png_const_charp message) {
    auto* state = static_cast<PngWriteState*>(png_get_error_ptr(png));
    std::snprintf(state->error, sizeof state->error, "%s", message);
    std::longjmp(png_jmpbuf(png), 1);
}

void png_warn(png_structp, png_const_charp) {}

// libpng reports errors by longjmp: nothing with a destructor may live in this function's
// frame between setjmp and the end (the output string is owned by the caller).
bool encode_png_raw(const ImageRGB8& image, PngWriteState& state) {
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, png_fail, png_warn);
    if (!png) return false;
    png_infop info = png_create_info_struct(png);
    if (!info) {
        png_destroy_write_struct(&png, nullptr);
        return false;
    }
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return false;
    }
    png_set_write_fn(png, &state, png_append, png_flush);
    png_set_compression_level(png, kPngCompressionLevel);
    png_set_IHDR(png, info, static_cast<png_uint_32>(image.width), static_cast<png_uint_32>(image.height), 8,
                 PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    const std::size_t stride = 3 * static_cast<std::size_t>(image.width);
    for (int y = 0; y < image.height; ++y)
        png_write_row(png, const_cast<png_bytep>(image.rgb.data() + static_cast<std::size_t>(y) * stride));
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    return true;
}

void encode_png(const ImageRGB8& image, std::string& out) {
    out.clear();
    // Rendered frames compress to roughly a third of raw; reserving that avoids most regrowth.
    out.reserve(image.rgb.size() / 3 + 1024);
    PngWriteState state{&out, "out of memory"};
    if (!encode_png_raw(image, state)) throw Error(std::string("png encoder: ") + state.error);
}

}  // namespace

void encode_image(const ImageRGB8& image, const EncodeSettings& settings, std::string& out) {
    const std::size_t expected = 3 * static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height);
    if (image.width <= 0 || image.height <= 0 || image.rgb.size() != expected)
        throw Error("encoder: image size does not match its width and height");
    switch (settings.format) {
        case Format::jpeg:
            encode_jpeg(image, settings, out);
            return;
        case Format::png:
            encode_png(image, out);
            return;
        case Format::raw_rgb8:
            out.assign(reinterpret_cast<const char*>(image.rgb.data()), image.rgb.size());
            return;
    }
    throw Error("encoder: unknown format");
}

const char* format_name(Format format) {
    switch (format) {
        case Format::jpeg:
            return "jpeg";
        case Format::png:
            return "png";
        case Format::raw_rgb8:
            return "raw";
    }
    return "?";
}

}  // namespace catgs::server
