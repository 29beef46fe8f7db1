// PNG: libpng (adaptive filters, the old server path, and fixed filters), libspng, and two
// encoders that filter the rows here and write the few chunks PNG needs: libdeflate over the
// whole image, and zlib over row chunks at once (the pigz way). docs/encoders.md has the
// measured times and sizes that chose FrameEncoder's.
#include <libdeflate.h>
#include <png.h>
#include <spng.h>
#include <zlib.h>

#include <algorithm>
#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "catgs/error.hpp"
#include "encode_buffer.hpp"
#include "catgs/server/encode_methods.hpp"

namespace catgs::server {
static_assert(kPngStrategy == Z_DEFAULT_STRATEGY || kPngStrategy == Z_RLE || kPngStrategy == Z_FILTERED);

namespace {

constexpr int kBytesPerPixel = 3;  // 8-bit RGB
constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
constexpr int kPngColorTruecolor = 2;
constexpr std::size_t kMaxChunkLength = 0x7FFFFFFF;  // PNG spec 5.3
// zlib's deflate parameters for raw deflate chunks: a 32 KiB window (the largest, what the
// zlib header below declares) and zlib's default memory level.
constexpr int kRawDeflateWindowBits = -15;
constexpr int kDeflateMemLevel = 8;
// The zlib stream header for a 32 KiB window at the fastest levels (RFC 1950: CMF 0x78,
// FLEVEL 0, FCHECK making the pair a multiple of 31).
constexpr unsigned char kZlibHeader[2] = {0x78, 0x01};

std::size_t row_bytes(const ImageRGB8& image) {
    return kBytesPerPixel * static_cast<std::size_t>(image.width);
}

unsigned char paeth(int a, int b, int c) {
    const int p = a + b - c;
    const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
    if (pa <= pb && pa <= pc) return static_cast<unsigned char>(a);
    return static_cast<unsigned char>(pb <= pc ? b : c);
}

// Row y of `image`, filtered, into out[0 .. 1 + row_bytes): the filter type byte, then bytes.
void filter_row(const ImageRGB8& image, int y, PngFilter filter, unsigned char* out) {
    const std::size_t n = row_bytes(image);
    const unsigned char* row = image.rgb.data() + n * static_cast<std::size_t>(y);
    const unsigned char* above = y > 0 ? row - n : nullptr;
    out[0] = static_cast<unsigned char>(filter);
    unsigned char* f = out + 1;
    const int bpp = kBytesPerPixel;
    switch (filter) {
        case PngFilter::none:
            std::memcpy(f, row, n);
            return;
        case PngFilter::sub:
            for (std::size_t i = 0; i < n; ++i)
                f[i] = static_cast<unsigned char>(row[i] - (i >= bpp ? row[i - bpp] : 0));
            return;
        case PngFilter::up:
            if (above) {
                for (std::size_t i = 0; i < n; ++i) f[i] = static_cast<unsigned char>(row[i] - above[i]);
            } else {
                std::memcpy(f, row, n);
            }
            return;
        case PngFilter::average:
            for (std::size_t i = 0; i < n; ++i) {
                const int left = i >= bpp ? row[i - bpp] : 0, up = above ? above[i] : 0;
                f[i] = static_cast<unsigned char>(row[i] - (left + up) / 2);
            }
            return;
        case PngFilter::paeth:
            for (std::size_t i = 0; i < n; ++i) {
                const int left = i >= bpp ? row[i - bpp] : 0, up = above ? above[i] : 0;
                const int corner = (above && i >= bpp) ? above[i - bpp] : 0;
                f[i] = static_cast<unsigned char>(row[i] - paeth(left, up, corner));
            }
            return;
    }
    throw Error("png encoder: unknown filter " + std::to_string(static_cast<int>(filter)));
}

// Rows [y0, y1) filtered into `out` (resized).
void filter_rows(const ImageRGB8& image, int y0, int y1, PngFilter filter, std::vector<unsigned char>& out) {
    const std::size_t stride = 1 + row_bytes(image);
    out.resize(stride * static_cast<std::size_t>(y1 - y0));
    for (int y = y0; y < y1; ++y) filter_row(image, y, filter, out.data() + stride * static_cast<std::size_t>(y - y0));
}

void append_u32(std::string& out, std::uint32_t value) {
    const char bytes[4] = {static_cast<char>(value >> 24), static_cast<char>(value >> 16),
                           static_cast<char>(value >> 8), static_cast<char>(value)};
    out.append(bytes, 4);
}

// A chunk whose data is already in `out` after its 8 bytes of length and type: writes the
// length and the CRC (of the type and data).
void close_chunk(std::string& out, std::size_t chunk_start) {
    const std::size_t length = out.size() - chunk_start - 8;
    if (length > kMaxChunkLength)
        throw Error("png encoder: a chunk of " + std::to_string(length) + " bytes is over PNG's limit of 2^31-1");
    const auto* type_and_data = reinterpret_cast<const Bytef*>(out.data() + chunk_start + 4);
    const uLong crc = crc32(0, type_and_data, static_cast<uInt>(length + 4));
    for (int i = 0; i < 4; ++i)
        out[chunk_start + static_cast<std::size_t>(i)] = static_cast<char>(length >> (24 - 8 * i));
    append_u32(out, static_cast<std::uint32_t>(crc));
}

void open_chunk(std::string& out, const char type[4]) {
    out.append(4, '\0');
    out.append(type, 4);
}

// Signature, IHDR and the opening of IDAT; the caller appends the zlib stream.
std::size_t begin_png(const ImageRGB8& image, std::string& out) {
    out.clear();
    out.append(reinterpret_cast<const char*>(kPngSignature), sizeof kPngSignature);
    std::size_t chunk = out.size();
    open_chunk(out, "IHDR");
    append_u32(out, static_cast<std::uint32_t>(image.width));
    append_u32(out, static_cast<std::uint32_t>(image.height));
    const char rest[5] = {8, kPngColorTruecolor, 0, 0, 0};  // depth, colour, deflate, filters, no interlace
    out.append(rest, sizeof rest);
    close_chunk(out, chunk);
    chunk = out.size();
    open_chunk(out, "IDAT");
    return chunk;
}

void end_png(std::string& out, std::size_t idat) {
    close_chunk(out, idat);
    const std::size_t iend = out.size();
    open_chunk(out, "IEND");
    close_chunk(out, iend);
}

// --- libpng

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

struct LibpngSettings {
    int filters = -1;  // PNG_FILTER_* mask; -1 leaves libpng's adaptive default
    int level = 1;
    int strategy = Z_DEFAULT_STRATEGY;
};

// libpng reports errors by longjmp: nothing with a destructor may live in this function's
// frame between setjmp and the end (the output string is owned by the caller).
bool encode_png_raw(const ImageRGB8& image, const LibpngSettings& settings, PngWriteState& state) {
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
    png_set_compression_level(png, settings.level);
    png_set_compression_strategy(png, settings.strategy);
    if (settings.filters >= 0) png_set_filter(png, PNG_FILTER_TYPE_BASE, settings.filters);
    png_set_IHDR(png, info, static_cast<png_uint_32>(image.width), static_cast<png_uint_32>(image.height), 8,
                 PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (int y = 0; y < image.height; ++y)
        png_write_row(png, const_cast<png_bytep>(image.rgb.data() + static_cast<std::size_t>(y) * row_bytes(image)));
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    return true;
}

void encode_libpng(const ImageRGB8& image, const LibpngSettings& settings, std::string& out) {
    out.clear();
    // Rendered frames compress to roughly a third of raw; reserving that avoids most regrowth.
    out.reserve(image.rgb.size() / 3 + 1024);
    PngWriteState state{&out, "out of memory"};
    if (!encode_png_raw(image, settings, state)) throw Error(std::string("png encoder (libpng): ") + state.error);
}

int libpng_filter_flag(PngFilter filter) {
    switch (filter) {
        case PngFilter::none:
            return PNG_FILTER_NONE;
        case PngFilter::sub:
            return PNG_FILTER_SUB;
        case PngFilter::up:
            return PNG_FILTER_UP;
        case PngFilter::average:
            return PNG_FILTER_AVG;
        case PngFilter::paeth:
            return PNG_FILTER_PAETH;
    }
    throw Error("png encoder: unknown filter " + std::to_string(static_cast<int>(filter)));
}

// --- zlib chunks

// One thread's raw-deflate stream, kept between frames: deflateInit allocates some 300 KiB
// that deflateReset reuses.
class Deflater {
public:
    ~Deflater() {
        if (ready_) deflateEnd(&stream_);
    }
    z_stream& start(int level, int strategy) {
        if (ready_ && (level != level_ || strategy != strategy_)) {
            deflateEnd(&stream_);
            ready_ = false;
        }
        if (!ready_) {
            stream_ = {};
            if (deflateInit2(&stream_, level, Z_DEFLATED, kRawDeflateWindowBits, kDeflateMemLevel, strategy) != Z_OK)
                throw Error("png encoder: deflateInit2 failed (level " + std::to_string(level) + ")");
            ready_ = true;
            level_ = level;
            strategy_ = strategy;
        } else {
            deflateReset(&stream_);
        }
        return stream_;
    }

private:
    z_stream stream_{};
    bool ready_ = false;
    int level_ = 0, strategy_ = 0;
};

struct DeflatedChunk {
    ScratchBuffer data;
    std::size_t size = 0;
    uLong adler = 0;  // of the filtered bytes
    std::size_t raw_size = 0;
};

// Rows [y0, y1) filtered and raw-deflated; a sync flush ends all but the last chunk on a byte
// boundary with no final block, so the chunks concatenate into one deflate stream.
void deflate_rows(const ImageRGB8& image, int y0, int y1, PngFilter filter, int level, int strategy, bool last,
                  DeflatedChunk& chunk) {
    thread_local std::vector<unsigned char> filtered;
    thread_local Deflater deflater;
    filter_rows(image, y0, y1, filter, filtered);
    if (filtered.size() > kMaxChunkLength)  // zlib counts in 32 bits; PNG could not hold it anyway
        throw Error("png encoder: rows " + std::to_string(y0) + ".." + std::to_string(y1 - 1) + " are " +
                    std::to_string(filtered.size()) + " bytes, over PNG's limit");
    chunk.raw_size = filtered.size();
    chunk.adler = adler32(adler32(0, nullptr, 0), filtered.data(), static_cast<uInt>(filtered.size()));
    z_stream& z = deflater.start(level, strategy);
    // deflateBound covers a finished stream; a sync flush adds an empty stored block.
    const std::size_t bound = deflateBound(&z, static_cast<uLong>(filtered.size())) + 16;
    z.next_in = filtered.data();
    z.avail_in = static_cast<uInt>(filtered.size());
    z.next_out = chunk.data.reserve(bound);
    z.avail_out = static_cast<uInt>(bound);
    const int result = deflate(&z, last ? Z_FINISH : Z_SYNC_FLUSH);
    if (result != (last ? Z_STREAM_END : Z_OK) || z.avail_in != 0)
        throw Error("png encoder: deflate failed on rows " + std::to_string(y0) + ".." + std::to_string(y1 - 1) +
                    " (zlib " + std::to_string(result) + ")");
    chunk.size = bound - z.avail_out;
}

}  // namespace

void encode_png_libpng_adaptive(const ImageRGB8& image, std::string& out) {
    encode_libpng(image, LibpngSettings{}, out);
}

void encode_png_libpng(const ImageRGB8& image, PngFilter filter, int level, int zlib_strategy, std::string& out) {
    encode_libpng(image, LibpngSettings{libpng_filter_flag(filter), level, zlib_strategy}, out);
}

void encode_png_spng(const ImageRGB8& image, PngFilter filter, int level, std::string& out) {
    std::unique_ptr<spng_ctx, void (*)(spng_ctx*)> ctx(spng_ctx_new(SPNG_CTX_ENCODER), spng_ctx_free);
    if (!ctx) throw Error("png encoder (libspng): out of memory");
    auto check = [](int error, const char* step) {
        if (error) throw Error(std::string("png encoder (libspng): ") + step + ": " + spng_strerror(error));
    };
    check(spng_set_option(ctx.get(), SPNG_ENCODE_TO_BUFFER, 1), "buffer output");
    spng_ihdr ihdr{};
    ihdr.width = static_cast<std::uint32_t>(image.width);
    ihdr.height = static_cast<std::uint32_t>(image.height);
    ihdr.bit_depth = 8;
    ihdr.color_type = SPNG_COLOR_TYPE_TRUECOLOR;
    check(spng_set_ihdr(ctx.get(), &ihdr), "IHDR");
    // SPNG_FILTER_CHOICE_* are one bit per filter, from NONE (8) upwards.
    check(spng_set_option(ctx.get(), SPNG_FILTER_CHOICE, SPNG_FILTER_CHOICE_NONE << static_cast<int>(filter)),
          "filter");
    check(spng_set_option(ctx.get(), SPNG_IMG_COMPRESSION_LEVEL, level), "compression level");
    check(spng_encode_image(ctx.get(), image.rgb.data(), image.rgb.size(), SPNG_FMT_PNG, SPNG_ENCODE_FINALIZE),
          "encode");
    std::size_t size = 0;
    int error = 0;
    std::unique_ptr<void, void (*)(void*)> png(spng_get_png_buffer(ctx.get(), &size, &error), std::free);
    check(error, "output");
    out.assign(static_cast<const char*>(png.get()), size);
}

void encode_png_libdeflate(const ImageRGB8& image, PngFilter filter, int level, std::string& out) {
    struct Compressor {
        libdeflate_compressor* c = nullptr;
        int level = 0;
        ~Compressor() { libdeflate_free_compressor(c); }
    };
    thread_local Compressor compressor;
    thread_local std::vector<unsigned char> filtered;
    thread_local ScratchBuffer deflated;
    if (!compressor.c || compressor.level != level) {
        libdeflate_free_compressor(compressor.c);
        compressor.c = libdeflate_alloc_compressor(level);
        compressor.level = level;
        if (!compressor.c) throw Error("png encoder (libdeflate): no compressor for level " + std::to_string(level));
    }
    filter_rows(image, 0, image.height, filter, filtered);
    const std::size_t bound = libdeflate_zlib_compress_bound(compressor.c, filtered.size());
    const std::size_t size =
        libdeflate_zlib_compress(compressor.c, filtered.data(), filtered.size(), deflated.reserve(bound), bound);
    if (size == 0) throw Error("png encoder (libdeflate): output larger than its bound");
    const std::size_t idat = begin_png(image, out);
    out.append(reinterpret_cast<const char*>(deflated.data()), size);
    end_png(out, idat);
}

void encode_png_parallel(const ImageRGB8& image, PngFilter filter, int level, int zlib_strategy, int chunks,
                         EncodePool& pool, std::string& out) {
    const int count = std::clamp(chunks, 1, image.height);
    const int rows_per_chunk = (image.height + count - 1) / count;
    const int used = (image.height + rows_per_chunk - 1) / rows_per_chunk;
    // The caller's chunks, reused frame after frame (named by reference: inside the lambda a
    // thread_local's name would mean the helper's own).
    thread_local std::vector<DeflatedChunk> caller_chunks;
    auto& parts = caller_chunks;
    if (parts.size() < static_cast<std::size_t>(used)) parts.resize(static_cast<std::size_t>(used));
    pool.run(used, [&](int i) {
        const int y0 = i * rows_per_chunk, y1 = std::min(image.height, y0 + rows_per_chunk);
        deflate_rows(image, y0, y1, filter, level, zlib_strategy, i == used - 1, parts[static_cast<std::size_t>(i)]);
    });
    const std::size_t idat = begin_png(image, out);
    std::size_t total = 0;
    for (int i = 0; i < used; ++i) total += parts[static_cast<std::size_t>(i)].size;
    out.reserve(out.size() + sizeof kZlibHeader + total + 4 + 24);
    out.append(reinterpret_cast<const char*>(kZlibHeader), sizeof kZlibHeader);
    uLong adler = adler32(0, nullptr, 0);
    for (int i = 0; i < used; ++i) {
        const DeflatedChunk& part = parts[static_cast<std::size_t>(i)];
        out.append(reinterpret_cast<const char*>(part.data.data()), part.size);
        adler = adler32_combine(adler, part.adler, static_cast<z_off_t>(part.raw_size));
    }
    append_u32(out, static_cast<std::uint32_t>(adler));
    end_png(out, idat);
}

}  // namespace catgs::server
