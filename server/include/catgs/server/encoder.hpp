// Frame encoders: JPEG (TurboJPEG, cut into restart-interval strips encoded on several cores, or
// nvJPEG on the GPU when built with CATGS_NVJPEG), PNG (filtered rows deflated in parallel
// chunks into one zlib stream) and raw RGB8. Safe to call from several threads at once.
// No OpenImageIO: the server must run on bare GPU hosts.
//
// The individual methods, for tests and catgs-encode-bench, are in encode_methods.hpp.
#pragma once

#include <memory>
#include <string>

#include "catgs/image.hpp"

namespace catgs::server {

enum class Format { jpeg, png, raw_rgb8 };

struct EncodeSettings {
    Format format = Format::jpeg;
    int jpeg_quality = 85;  ///< 1..100
    bool jpeg_444 = false;  ///< 4:4:4 chroma instead of 4:2:0
};

/// Which library encodes JPEG. `automatic` picks nvJPEG when it is built in and a CUDA
/// device is usable, else TurboJPEG.
enum class JpegEncoder { automatic, turbo, nvjpeg };

/// "auto" | "turbo" | "nvjpeg"; throws catgs::Error naming `flag` and the value otherwise.
JpegEncoder parse_jpeg_encoder(const std::string& value, const std::string& flag = "--jpeg-encoder");
const char* jpeg_encoder_name(JpegEncoder encoder);

struct EncoderOptions {
    JpegEncoder jpeg = JpegEncoder::automatic;
    /// Threads one frame may be cut over (TurboJPEG strips, PNG deflate chunks), the calling
    /// thread included; 0 = every hardware thread.
    int threads = 0;
};

class EncodePool;

/// The encoders with their thread pool and the JPEG library chosen once. One per process in
/// the server (see configure_encoder); tests and the bench make their own.
class FrameEncoder {
public:
    /// Throws catgs::Error when `options.jpeg` is nvjpeg and nvJPEG is not built in or no
    /// device is usable (the message says which), or when threads is outside 0..256.
    explicit FrameEncoder(const EncoderOptions& options = {});
    ~FrameEncoder();
    FrameEncoder(const FrameEncoder&) = delete;
    FrameEncoder& operator=(const FrameEncoder&) = delete;

    /// Encodes `image` into `out` (replacing its contents). Throws catgs::Error on failure.
    void encode(const ImageRGB8& image, const EncodeSettings& settings, std::string& out);

    /// The JPEG library in use: turbo or nvjpeg, never automatic.
    JpegEncoder jpeg_encoder() const { return jpeg_; }
    int threads() const;

private:
    JpegEncoder jpeg_;
    std::unique_ptr<EncodePool> pool_;
};

/// Replaces the process-wide encoder that encode_image uses (by default: automatic JPEG
/// library, every hardware thread). Frames being encoded finish on the previous one. Throws
/// like FrameEncoder's constructor; the previous encoder stays on failure.
void configure_encoder(const EncoderOptions& options);
/// The process-wide encoder's JPEG library (turbo or nvjpeg) and threads, for logs.
JpegEncoder configured_jpeg_encoder();

/// Encodes `image` into `out` (replacing its contents) with the process-wide encoder. Throws
/// catgs::Error on failure.
void encode_image(const ImageRGB8& image, const EncodeSettings& settings, std::string& out);

const char* format_name(Format format);

}  // namespace catgs::server
