#include "catgs/server/encoder.hpp"

#include <mutex>
#include <thread>

#include "catgs/error.hpp"
#include "catgs/parallel.hpp"
#include "catgs/server/encode_methods.hpp"

namespace catgs::server {
namespace {

JpegEncoder resolve(JpegEncoder wanted) {
    switch (wanted) {
        case JpegEncoder::turbo:
            return JpegEncoder::turbo;
        case JpegEncoder::nvjpeg:
            if (const std::string why = nvjpeg_unusable_reason(); !why.empty())
                throw Error("--jpeg-encoder nvjpeg: " + why + " (use --jpeg-encoder turbo or auto)");
            return JpegEncoder::nvjpeg;
        case JpegEncoder::automatic:
            return nvjpeg_unusable_reason().empty() ? JpegEncoder::nvjpeg : JpegEncoder::turbo;
    }
    throw Error("encoder: unknown JPEG encoder " + std::to_string(static_cast<int>(wanted)));
}

// More helpers than this only add wake-ups: a 4K frame has 63 parts of kMinPartPixels.
constexpr int kMaxEncodeThreads = 256;

int thread_count(int wanted) {
    if (wanted < 0 || wanted > kMaxEncodeThreads)
        throw Error("--encode-threads " + std::to_string(wanted) + ": expected 0 (every core) to " +
                    std::to_string(kMaxEncodeThreads));
    return wanted == 0 ? default_thread_count() : wanted;
}

std::mutex& process_encoder_mutex() {
    static std::mutex mutex;
    return mutex;
}

// Shared, so that frames being encoded keep the encoder they started on when
// configure_encoder replaces it.
std::shared_ptr<FrameEncoder>& process_encoder_slot() {
    static std::shared_ptr<FrameEncoder> encoder;
    return encoder;
}

std::shared_ptr<FrameEncoder> process_encoder() {
    std::lock_guard lock(process_encoder_mutex());
    auto& slot = process_encoder_slot();
    if (!slot) slot = std::make_shared<FrameEncoder>();
    return slot;
}

}  // namespace

JpegEncoder parse_jpeg_encoder(const std::string& value, const std::string& flag) {
    if (value == "auto") return JpegEncoder::automatic;
    if (value == "turbo") return JpegEncoder::turbo;
    if (value == "nvjpeg") return JpegEncoder::nvjpeg;
    throw Error(flag + " '" + value + "': expected auto, turbo or nvjpeg");
}

const char* jpeg_encoder_name(JpegEncoder encoder) {
    switch (encoder) {
        case JpegEncoder::automatic:
            return "auto";
        case JpegEncoder::turbo:
            return "turbo";
        case JpegEncoder::nvjpeg:
            return "nvjpeg";
    }
    return "?";
}

FrameEncoder::FrameEncoder(const EncoderOptions& options)
    : jpeg_(resolve(options.jpeg)), pool_(std::make_unique<EncodePool>(thread_count(options.threads))) {}

FrameEncoder::~FrameEncoder() = default;

int FrameEncoder::threads() const {
    return pool_->threads();
}

void FrameEncoder::encode(const ImageRGB8& image, const EncodeSettings& settings, std::string& out) {
    const std::size_t expected = 3 * static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height);
    if (image.width <= 0 || image.height <= 0 || image.rgb.size() != expected)
        throw Error("encoder: image of " + std::to_string(image.width) + "x" + std::to_string(image.height) + " has " +
                    std::to_string(image.rgb.size()) + " bytes, expected " + std::to_string(expected));
    const int parts = jpeg_strip_count(image.width, image.height, pool_->threads());
    switch (settings.format) {
        case Format::jpeg:
            if (settings.jpeg_quality < 1 || settings.jpeg_quality > 100)
                throw Error("encoder: jpeg quality " + std::to_string(settings.jpeg_quality) + " is outside 1..100");
            if (jpeg_ == JpegEncoder::nvjpeg)
                return encode_jpeg_nvjpeg(image, settings.jpeg_quality, settings.jpeg_444, out);
            return encode_jpeg_strips(image, settings.jpeg_quality, settings.jpeg_444, parts, *pool_, out);
        case Format::png:
            if (parts >= kMinParallelPngParts)
                return encode_png_parallel(image, kPngFilter, kPngLevel, kPngStrategy, parts, *pool_, out);
            return encode_png_libdeflate(image, kPngFilter, kPngLevel, out);
        case Format::raw_rgb8:
            out.assign(reinterpret_cast<const char*>(image.rgb.data()), image.rgb.size());
            return;
    }
    throw Error("encoder: unknown format " + std::to_string(static_cast<int>(settings.format)));
}

void configure_encoder(const EncoderOptions& options) {
    auto encoder = std::make_shared<FrameEncoder>(options);
    std::lock_guard lock(process_encoder_mutex());
    process_encoder_slot() = std::move(encoder);
}

JpegEncoder configured_jpeg_encoder() {
    return process_encoder()->jpeg_encoder();
}

void encode_image(const ImageRGB8& image, const EncodeSettings& settings, std::string& out) {
    process_encoder()->encode(image, settings, out);
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
