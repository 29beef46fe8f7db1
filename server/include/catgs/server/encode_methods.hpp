// The encoders one by one, under FrameEncoder (encoder.hpp): what tests compare and what
// catgs-encode-bench times. Every function replaces `out` and throws catgs::Error on failure.
#pragma once

#include <condition_variable>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "catgs/image.hpp"

namespace catgs::server {

/// Threads that help one caller through the parts of one frame. The caller works too and
/// claims parts itself, so a frame never waits for a busy pool: with every helper taken by
/// other frames it simply encodes all of its parts alone.
class EncodePool {
public:
    /// `threads` counts the caller: threads - 1 helpers are started (none for 1).
    explicit EncodePool(int threads);
    ~EncodePool();
    EncodePool(const EncodePool&) = delete;
    EncodePool& operator=(const EncodePool&) = delete;

    int threads() const { return static_cast<int>(helpers_.size()) + 1; }

    /// Calls part(0..parts-1), each once, on the caller and the helpers; returns when all are
    /// done. The first exception a part throws is rethrown here after every part has ended.
    void run(int parts, const std::function<void(int)>& part);

private:
    struct Batch;
    void help();
    // Takes the next part of `batch`, or -1; called with mutex_ held.
    int claim(Batch& batch);
    void finish(Batch& batch, std::exception_ptr error);

    std::mutex mutex_;
    std::condition_variable wake_;  // helpers: a batch was queued, or stopping
    std::condition_variable done_;  // callers: a part of some batch finished
    std::deque<Batch*> batches_;    // batches with unclaimed parts, oldest first
    bool stopping_ = false;
    std::vector<std::thread> helpers_;
};

// --- JPEG

/// TurboJPEG, the whole frame on the calling thread (baseline, standard Huffman tables).
void encode_jpeg_turbo(const ImageRGB8& image, int quality, bool chroma_444, std::string& out);

/// TurboJPEG over horizontal strips of whole MCU rows, encoded at once on `pool` and stitched
/// into one baseline JPEG: the first strip's headers, a DRI marker whose interval is one
/// strip's MCUs, and an RSTn marker between strips. Every strip carries the same tables, so the
/// decoded image equals encode_jpeg_turbo's. `strips` is clamped to what the image allows (its
/// MCU rows, the 16-bit restart interval); 1 is the single-threaded encode.
void encode_jpeg_strips(const ImageRGB8& image, int quality, bool chroma_444, int strips, EncodePool& pool,
                        std::string& out);

/// The strip count FrameEncoder uses for an image on `threads` threads: one per thread, but
/// none smaller than kMinPartPixels (waking a helper costs more than encoding a tiny strip).
int jpeg_strip_count(int width, int height, int threads);

/// Pixels below which a frame part is not worth handing to another thread.
inline constexpr int kMinPartPixels = 1 << 17;

/// Whether nvJPEG was built in (CATGS_NVJPEG).
bool nvjpeg_built();
/// Why nvJPEG cannot encode here ("" when it can): not built in, no CUDA device, or the
/// library failed to start, with CUDA's or nvJPEG's own words.
std::string nvjpeg_unusable_reason();
/// nvJPEG on the current CUDA device: uploads through a pinned staging buffer and encodes on
/// a stream of this thread's own (state, buffers and stream are kept per thread and reused).
void encode_jpeg_nvjpeg(const ImageRGB8& image, int quality, bool chroma_444, std::string& out);

// --- PNG (8-bit RGB, no interlace)

/// PNG row filters (PNG spec section 9). Up and Paeth suit rendered images: smooth in y.
enum class PngFilter { none = 0, sub = 1, up = 2, average = 3, paeth = 4 };

/// libpng as the server used it before the parallel encoder: zlib level 1 with libpng's
/// adaptive choice among all five filters per row (the baseline in the bench).
void encode_png_libpng_adaptive(const ImageRGB8& image, std::string& out);
/// libpng with one fixed filter, zlib level `level` and strategy `zlib_strategy` (Z_DEFAULT_STRATEGY, Z_RLE...).
void encode_png_libpng(const ImageRGB8& image, PngFilter filter, int level, int zlib_strategy, std::string& out);
/// libspng with one fixed filter at zlib level `level`.
void encode_png_spng(const ImageRGB8& image, PngFilter filter, int level, std::string& out);
/// Rows filtered here, deflated whole by libdeflate at `level` (1..12), on the calling thread.
void encode_png_libdeflate(const ImageRGB8& image, PngFilter filter, int level, std::string& out);
/// Rows filtered and deflated in `chunks` row chunks at once on `pool` (zlib at `level`, raw
/// deflate ended by a sync flush), joined into one zlib stream with adler32_combine: the
/// pigz way. chunks is clamped to the rows; 1 is one zlib stream on the calling thread.
void encode_png_parallel(const ImageRGB8& image, PngFilter filter, int level, int zlib_strategy, int chunks,
                         EncodePool& pool, std::string& out);

/// What FrameEncoder uses (measured in docs/encoders.md): the Up filter (Paeth costs a third
/// more CPU for no smaller file at these levels) at the fastest level of zlib or libdeflate.
inline constexpr PngFilter kPngFilter = PngFilter::up;
inline constexpr int kPngLevel = 1;
inline constexpr int kPngStrategy = 0;  // Z_DEFAULT_STRATEGY (checked in encode_png.cpp)
/// libdeflate deflates about twice as fast per core as zlib (1080p: 40 against 77 ms of CPU)
/// but cannot end a chunk without a final block, so it cannot be split: zlib's chunks win
/// from three parts on.
inline constexpr int kMinParallelPngParts = 3;

}  // namespace catgs::server
