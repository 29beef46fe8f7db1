// Niantic .spz, written from the format's public description and reference loader
// (github.com/nianticlabs/spz: README "File Format", src/cc/load-spz.cc):
// - versions 2 and 3: one gzip stream holding a 16-byte header and then each attribute of
//   every Gaussian in turn (positions, alphas, colours, scales, rotations, SH);
// - version 4 (what splat-transform 3.7 and Niantic's library write by default): a plain
//   32-byte header, optional extension records, a table of contents of (compressed,
//   decompressed) sizes, and then each of those attribute blocks as its own ZSTD stream.
// Both decode into the same packed layout, so one decoder serves every version.
//
// Memory: the streams are decompressed into one packed buffer that grows with what actually
// arrives (so a lying count costs only the bytes the streams really hold) and never past what
// the header's count needs (so a decompression bomb stops there). The scene is allocated only
// once the packed data is complete, and the packed buffer (about a quarter of the scene's
// size) is released before the scene is finished.

#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <climits>
#include <cstring>
#include <memory>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "catgs/scene_io.hpp"
#include "scene_io_detail.hpp"

namespace catgs {

namespace {

using io::fail;

constexpr std::uint32_t kSpzMagic = 0x5053474e;  ///< "NGSP" read as a little-endian uint32
constexpr std::size_t kHeaderBytes = 16;
constexpr std::uint32_t kFirstVersion = 2, kLastGzipVersion = 3;
/// Version 4 left gzip for a plain header, a table of contents and one ZSTD stream per block.
constexpr std::uint32_t kZstdVersion = 4;
constexpr std::size_t kZstdHeaderBytes = 32;
/// Header byte 15 counts the streams, bytes 16..19 locate the table of contents.
constexpr std::size_t kStreamCountOffset = 15, kTocOffsetOffset = 16;
/// A table of contents entry: the stream's compressed and decompressed sizes, u64 each.
constexpr std::size_t kTocEntryBytes = 16;
/// Version 3 replaced version 2's (x, y, z) bytes by the smallest-three encoding.
constexpr std::uint32_t kSmallestThreeVersion = 3;
constexpr std::uint8_t kFlagExtensions = 0x2;  ///< extension records follow the SH block

constexpr std::size_t kPositionBytes = 9;  ///< 3 x 24-bit fixed point
constexpr std::size_t kColourBytes = 3, kScaleBytes = 3;
/// Colour bytes are 255 * (0.5 + kColourScale * f_dc): the format's own scale, not SH_C0.
constexpr double kColourScale = 0.15;
/// Scale bytes are 16 * (log(scale) + 10): 1/16 steps of log scale from -10.
constexpr double kLogScaleStep = 1.0 / 16.0, kLogScaleOffset = -10.0;
/// SH bytes are 128 + 128 * coefficient.
constexpr double kShBias = 128.0;
/// Version 2 rotation bytes are 127.5 * (1 + q) for x, y, z of the quaternion with w >= 0.
constexpr double kFirstThreeHalfRange = 127.5;
/// Version 3: each of the three smallest components is a sign bit and a 9-bit magnitude in
/// units of sqrt(1/2) / 511 (no component but the largest can exceed sqrt(1/2)).
constexpr unsigned kSmallestThreeMagnitudeBits = 9;
constexpr std::uint32_t kSmallestThreeMagnitudeMask = (1u << kSmallestThreeMagnitudeBits) - 1;
constexpr double kSqrtHalf = 0.70710678118654752440;
/// The squared smallest three of a unit quaternion sum to at most 3/4 (the largest is at
/// least 1/2); rounding adds well under this, so a larger sum is a corrupt record.
constexpr double kMaxSmallestThreeNorm2 = 1.0;

/// deflate cannot inflate more than 1032 bytes per input byte (a 258-byte match per 2 bits
/// at best); a header whose count needs more than that from this file is a lying count.
constexpr std::uint64_t kMaxDeflateRatio = 1032;
/// A ZSTD block holds at most 128 KiB and an RLE block takes 4 bytes (a 3-byte header and the
/// byte): no stream can decompress to more than 32768 times its size.
constexpr std::uint64_t kMaxZstdRatio = 32768;
/// Extension records (flag 0x2) are skipped; more than this after the SH block is not one.
constexpr std::size_t kMaxExtensionBytes = std::size_t{1} << 20;
/// Compressed input is handed to zlib in blocks of this size.
constexpr std::size_t kInputBlockBytes = std::size_t{1} << 20;
/// The packed buffer grows as data arrives: first by 64 KiB, then doubling, by at most a chunk.
constexpr std::size_t kFirstGrowBytes = std::size_t{64} << 10, kMaxGrowBytes = io::kChunkBytes;

constexpr io::Encoding kSpzEncoding{.log_scale = true, .logit_opacity = false, .noun = "field", .nouns = "fields"};

/// Which real SH basis functions change sign when y and z flip (RUB <-> RDF, a half turn
/// about x): those of odd total degree in y and z. The basis polynomials, in the file's (and
/// graphdeco's) coefficient order after the DC term:
///   l=1: y, z, x
///   l=2: xy, yz, 3z^2-1, xz, x^2-y^2
///   l=3: y(3x^2-y^2), xyz, y(5z^2-1), z(5z^2-3), x(5z^2-1), z(x^2-y^2), x(x^2-3y^2)
constexpr std::array<bool, 15> kOddInYZ = {true, true,  false, true, false, false, true, false,
                                           true, false, true,  true, false, true,  false};

struct SpzHeader {
    std::uint32_t version = 0;
    std::uint64_t count = 0;
    int sh_degree = 0;
    int fractional_bits = 0;
    std::uint8_t flags = 0;
};

/// One attribute block of the packed payload: in a version 4 file, one ZSTD stream.
struct Block {
    const char* name;
    std::uint64_t begin;
    std::size_t stride;  ///< bytes per Gaussian
};

/// Where each attribute block starts in the payload (after the header).
struct Layout {
    std::size_t rotation_bytes = 0, sh_bytes = 0;
    std::uint64_t alphas = 0, colours = 0, scales = 0, rotations = 0, sh = 0, end = 0;
    /// Version 4: each block is its own ZSTD stream, so offsets are within a stream.
    bool zstd_streams = false;

    explicit Layout(const SpzHeader& h) : zstd_streams(h.version >= kZstdVersion) {
        rotation_bytes = h.version >= kSmallestThreeVersion ? 4 : 3;
        sh_bytes = 3 * static_cast<std::size_t>(sh_coefficient_count(h.sh_degree) - 1);
        alphas = h.count * kPositionBytes;
        colours = alphas + h.count;
        scales = colours + h.count * kColourBytes;
        rotations = scales + h.count * kScaleBytes;
        sh = rotations + h.count * rotation_bytes;
        end = sh + h.count * sh_bytes;
    }
    /// The blocks in the file's order; a version 4 file has one stream for each but an empty
    /// SH block (SH degree 0).
    std::vector<Block> blocks() const {
        std::vector<Block> all = {{"positions", 0, kPositionBytes},
                                  {"alphas", alphas, 1},
                                  {"colors", colours, kColourBytes},
                                  {"scales", scales, kScaleBytes},
                                  {"rotations", rotations, rotation_bytes}};
        if (sh_bytes > 0) all.push_back({"sh", sh, sh_bytes});
        return all;
    }
    std::uint64_t block_end(std::size_t k) const {
        const std::vector<Block> all = blocks();
        return k + 1 < all.size() ? all[k + 1].begin : end;
    }
    /// "the <attribute> block, Gaussian i" for a payload offset.
    std::string where(std::uint64_t offset) const {
        const std::vector<Block> all = blocks();
        for (auto b = all.rbegin(); b != all.rend(); ++b)
            if (offset >= b->begin) {
                const std::string gaussian = ", Gaussian " + std::to_string((offset - b->begin) / b->stride);
                if (zstd_streams)
                    return "the " + std::string(b->name) + " stream" + gaussian + ", decompressed byte offset " +
                           std::to_string(offset - b->begin) + " of the stream";
                return "the " + std::string(b->name) + " block" + gaussian + ", decompressed byte offset " +
                       std::to_string(kHeaderBytes + offset);
            }
        return "decompressed byte offset " + std::to_string(kHeaderBytes + offset);
    }
};

/// The file's gzip stream, inflated on demand through zlib.
class GzipStream {
public:
    explicit GzipStream(io::FileReader& in) : in_(in) {
        if (inflateInit2(&z_, 16 + MAX_WBITS) != Z_OK) fail(in.path(), "cannot initialise zlib", "");
    }
    ~GzipStream() { inflateEnd(&z_); }
    GzipStream(const GzipStream&) = delete;
    GzipStream& operator=(const GzipStream&) = delete;

    /// Inflates up to n bytes into out; fewer only when the stream ends (ended()) or the file
    /// does first (truncated).
    std::size_t read(unsigned char* out, std::size_t n) {
        std::size_t done = 0;
        while (done < n && !ended_) {
            if (z_.avail_in == 0 && !refill()) break;
            z_.next_out = out + done;
            z_.avail_out = static_cast<uInt>(std::min<std::size_t>(n - done, UINT_MAX));
            const uInt before = z_.avail_out;
            const int status = inflate(&z_, Z_NO_FLUSH);
            done += before - z_.avail_out;
            if (status == Z_STREAM_END) {
                ended_ = true;
            } else if (status != Z_OK && status != Z_BUF_ERROR) {
                fail(in_.path(), std::string("corrupt gzip data: ") + (z_.msg ? z_.msg : zError(status)),
                     io::at_offset(compressed_offset()));
            }
        }
        return done;
    }
    bool ended() const { return ended_; }
    /// The reader stays at the start of the block zlib is given (refill consumes it only when
    /// handing over the next), so zlib's position is that start plus what it has taken.
    std::uint64_t compressed_offset() const { return in_.offset() + block_ - z_.avail_in; }

private:
    /// Hands zlib the next block of the file; false at its end.
    bool refill() {
        in_.consume(block_);
        block_ = static_cast<std::size_t>(std::min<std::uint64_t>(in_.remaining(), kInputBlockBytes));
        if (block_ == 0 || !in_.require(block_)) {
            // Nothing was handed over: compressed_offset must not count the block.
            block_ = 0;
            return false;
        }
        z_.next_in = const_cast<Bytef*>(in_.data());
        z_.avail_in = static_cast<uInt>(block_);
        return true;
    }

    io::FileReader& in_;
    z_stream z_{};
    std::size_t block_ = 0;
    bool ended_ = false;
};

/// The header's first 16 bytes, the same in every version. `zstd_file`: read from a version 4
/// file's plain header rather than from inside a gzip stream.
SpzHeader parse_header(const std::string& path, const unsigned char* h, bool zstd_file) {
    SpzHeader header;
    const std::string at = zstd_file ? "byte offset " : "decompressed byte offset ";
    const auto magic = io::load_scalar<std::uint32_t>(h, false);
    if (magic != kSpzMagic) {
        char text[16];
        std::snprintf(text, sizeof(text), "0x%08x", magic);
        fail(path, std::string("not an SPZ stream: magic ") + text + ", expected 0x5053474e ('NGSP')", at + "0");
    }
    header.version = io::load_scalar<std::uint32_t>(h + 4, false);
    if (zstd_file && header.version != kZstdVersion)
        fail(path,
             "SPZ version " + std::to_string(header.version) +
                 " is not supported in a plain (not gzipped) file: that is version 4, with ZSTD streams",
             at + "4");
    if (!zstd_file && (header.version < kFirstVersion || header.version > kLastGzipVersion))
        fail(path,
             "SPZ version " + std::to_string(header.version) +
                 " is not supported in a gzip stream (versions 2 and 3 are; version 4 files are not gzipped" +
                 (header.version == 1 ? "; version 1's float16 positions were never released)" : ")"),
             at + "4");
    header.count = io::load_scalar<std::uint32_t>(h + 8, false);
    if (header.count == 0) fail(path, "no Gaussians: the header's count is 0", at + "8");
    header.sh_degree = h[12];
    if (header.sh_degree > kMaxShDegree)
        fail(path,
             "SH degree " + std::to_string(header.sh_degree) + " is not supported (0.." + std::to_string(kMaxShDegree) +
                 ")",
             at + "12");
    header.fractional_bits = h[13];
    header.flags = h[14];
    return header;
}

std::vector<std::string> spz_field_names(int sh_degree) {
    std::vector<std::string> names = {"x",     "y",     "z",     "scale_x", "scale_y", "scale_z", "alpha",
                                      "rot_w", "rot_x", "rot_y", "rot_z",   "color_r", "color_g", "color_b"};
    const char* channels[] = {"r", "g", "b"};
    for (int k = 1; k < sh_coefficient_count(sh_degree); ++k)
        for (const char* c : channels) names.push_back("sh_" + std::to_string(k) + "_" + c);
    return names;
}

/// Inflates the payload after the header, growing the buffer only as data arrives.
std::vector<unsigned char> inflate_payload(const std::string& path, GzipStream& gzip, const SpzHeader& header,
                                           const Layout& layout) {
    std::vector<unsigned char> packed;
    while (packed.size() < layout.end) {
        const std::size_t have = packed.size();
        // Doubling from a small start: a count the stream does not back costs little.
        const std::size_t grow = std::clamp(have, kFirstGrowBytes, kMaxGrowBytes);
        const std::size_t step = static_cast<std::size_t>(std::min<std::uint64_t>(layout.end - have, grow));
        packed.resize(have + step);
        const std::size_t got = gzip.read(packed.data() + have, step);
        if (got < step)
            fail(path,
                 "data ends early: the stream " + std::string(gzip.ended() ? "ends" : "is cut off") + " after " +
                     std::to_string(kHeaderBytes + have + got) + " of the " +
                     std::to_string(kHeaderBytes + layout.end) + " decompressed bytes that " +
                     std::to_string(header.count) + " Gaussians need",
                 layout.where(have + got));
    }
    // What follows the SH block: nothing, or extension records when the header says so.
    unsigned char scratch[4096];
    std::size_t extra = 0;
    for (;;) {
        const std::size_t got = gzip.read(scratch, sizeof(scratch));
        extra += got;
        if (got == 0) break;
        if (!(header.flags & kFlagExtensions) || extra > kMaxExtensionBytes)
            fail(path,
                 "the stream holds more than the header's " + std::to_string(header.count) +
                     " Gaussians need (a count that is too small" +
                     (header.flags & kFlagExtensions ? ", or extensions beyond 1 MiB)" : ")"),
                 "decompressed byte offset " + std::to_string(kHeaderBytes + layout.end));
    }
    if (!gzip.ended())
        fail(path, "truncated gzip stream: the file ends before the stream's end marker",
             io::at_offset(gzip.compressed_offset()));
    return packed;
}

void decode_rotation(const unsigned char* r, bool smallest_three, double* q_xyzw) {
    if (!smallest_three) {
        double norm2 = 0.0;
        for (int c = 0; c < 3; ++c) {
            q_xyzw[c] = r[c] / kFirstThreeHalfRange - 1.0;
            norm2 += q_xyzw[c] * q_xyzw[c];
        }
        q_xyzw[3] = std::sqrt(std::max(0.0, 1.0 - norm2));
        return;
    }
    std::uint32_t bits = io::load_scalar<std::uint32_t>(r, false);
    const int largest = static_cast<int>(bits >> 30);
    double norm2 = 0.0;
    // Packed most significant first in x, y, z, w order, so the last component is lowest.
    for (int c = 3; c >= 0; --c) {
        if (c == largest) continue;
        const double magnitude = kSqrtHalf * (bits & kSmallestThreeMagnitudeMask) / kSmallestThreeMagnitudeMask;
        q_xyzw[c] = (bits >> kSmallestThreeMagnitudeBits) & 1u ? -magnitude : magnitude;
        norm2 += q_xyzw[c] * q_xyzw[c];
        bits >>= kSmallestThreeMagnitudeBits + 1;
    }
    // Beyond a unit quaternion the largest component is the square root of a negative: NaN,
    // which SceneBuilder reports (or drops) like any non-finite value.
    q_xyzw[largest] = norm2 > kMaxSmallestThreeNorm2 ? std::nan("") : std::sqrt(1.0 - norm2);
}

class SpzDecoder {
public:
    SpzDecoder(const SpzHeader& header, const Layout& layout, const unsigned char* payload, SpzAxes axes)
        : header_(header),
          layout_(layout),
          payload_(payload),
          flip_(axes == SpzAxes::rub),
          position_step_(std::ldexp(1.0, -header.fractional_bits)) {}

    void decode(std::uint64_t i, double* v) const {
        const unsigned char* p = payload_ + i * kPositionBytes;
        for (int a = 0; a < 3; ++a, p += 3) {
            std::int32_t fixed = p[0] | (p[1] << 8) | (p[2] << 16);
            if (fixed & 0x800000) fixed -= 0x1000000;  // sign of the 24-bit value
            v[io::kFieldX + a] = fixed * position_step_;
        }
        v[io::kFieldOpacity] = payload_[layout_.alphas + i] / 255.0;
        const unsigned char* colour = payload_ + layout_.colours + i * kColourBytes;
        const unsigned char* scale = payload_ + layout_.scales + i * kScaleBytes;
        for (int c = 0; c < 3; ++c) {
            v[io::kFieldSh + c] = (colour[c] / 255.0 - 0.5) / kColourScale;
            v[io::kFieldScale + c] = scale[c] * kLogScaleStep + kLogScaleOffset;
        }
        double q[4];
        decode_rotation(payload_ + layout_.rotations + i * layout_.rotation_bytes,
                        header_.version >= kSmallestThreeVersion, q);
        v[io::kFieldRot] = q[3];
        for (int c = 0; c < 3; ++c) v[io::kFieldRot + 1 + c] = q[c];
        const unsigned char* sh = payload_ + layout_.sh + i * layout_.sh_bytes;
        for (std::size_t k = 0; k < layout_.sh_bytes; ++k) v[io::kFieldSh + 3 + k] = (sh[k] - kShBias) / kShBias;
        if (flip_) flip_rub_to_rdf(v);
    }

private:
    /// A half turn about x: y and z negate in positions, in the quaternion's axis (its w stays),
    /// and in the SH basis functions odd in y and z.
    void flip_rub_to_rdf(double* v) const {
        for (int a : {1, 2}) {
            v[io::kFieldX + a] = -v[io::kFieldX + a];
            v[io::kFieldRot + 1 + a] = -v[io::kFieldRot + 1 + a];
        }
        const std::size_t coefficients = layout_.sh_bytes / 3;
        for (std::size_t k = 0; k < coefficients; ++k)
            if (kOddInYZ[k])
                for (int c = 0; c < 3; ++c) v[io::kFieldSh + 3 * (k + 1) + c] = -v[io::kFieldSh + 3 * (k + 1) + c];
    }

    const SpzHeader& header_;
    const Layout& layout_;
    const unsigned char* payload_;
    bool flip_;
    double position_step_;
};

/// Refuses a header whose count needs more than `ratio` times the file's `size` once
/// decompressed, or more records than the caller allows, before anything is decompressed.
struct Codec {
    const char* file;   ///< "gzip": what the file is
    const char* bound;  ///< why a file of its size can hold no more
    std::uint64_t ratio;
    std::size_t header_bytes;  ///< counted with the payload
};
constexpr Codec kGzip{"gzip", "deflate inflates at most 1032:1", kMaxDeflateRatio, kHeaderBytes};
constexpr Codec kZstd{"ZSTD", "ZSTD expands at most 32768:1", kMaxZstdRatio, kZstdHeaderBytes};

void check_count(const std::string& path, const SpzHeader& header, const Layout& layout, std::uint64_t size,
                 const Codec& codec, const std::string& where, const LoadOptions& options) {
    std::uint64_t most;
    if (!io::checked_mul(size, codec.ratio, most) || layout.end > most)
        fail(path,
             "the header's count of " + std::to_string(header.count) + " Gaussians needs " +
                 std::to_string(codec.header_bytes + layout.end) + " decompressed bytes, more than a " +
                 std::to_string(size) + "-byte " + codec.file + " file can hold (" + codec.bound + ")",
             where);
    io::check_limits(path, header.count, header.sh_degree, options);
}

/// Versions 2 and 3: the header and the payload inside one gzip stream.
std::vector<unsigned char> read_gzip_payload(io::FileReader& in, const LoadOptions& options, SpzHeader& header) {
    const std::string& path = in.path();
    if (!in.require(2) || in.data()[0] != 0x1f || in.data()[1] != 0x8b)
        fail(path, "not an SPZ file: no gzip signature (1f 8b) and no 'NGSP' (version 4)", io::at_offset(0));
    GzipStream gzip(in);
    unsigned char raw_header[kHeaderBytes];
    if (gzip.read(raw_header, kHeaderBytes) < kHeaderBytes)
        fail(path, "data ends early: the stream ends inside the 16-byte SPZ header", "decompressed byte offset 0");
    header = parse_header(path, raw_header, false);
    const Layout layout(header);
    check_count(path, header, layout, in.size(), kGzip, "decompressed byte offset 8", options);
    return inflate_payload(path, gzip, header, layout);
}

/// A version 4 stream's sizes from the table of contents.
struct TocEntry {
    std::uint64_t compressed = 0, decompressed = 0;
};

/// Version 4: the table of contents after the 32-byte header (and the extension records,
/// which are skipped), checked against the blocks the count needs and the file's size.
std::vector<TocEntry> read_toc(io::FileReader& in, const unsigned char* raw_header, const Layout& layout) {
    const std::string& path = in.path();
    const std::vector<Block> blocks = layout.blocks();
    const unsigned streams = raw_header[kStreamCountOffset];
    if (streams != blocks.size())
        fail(path,
             "the header names " + std::to_string(streams) + " ZSTD streams, but a file of this SH degree has " +
                 std::to_string(blocks.size()) + " (positions, alphas, colors, scales, rotations" +
                 (blocks.size() > 5 ? ", sh)" : ")"),
             io::at_offset(kStreamCountOffset));
    const std::uint64_t toc = io::load_scalar<std::uint32_t>(raw_header + kTocOffsetOffset, false);
    const std::uint64_t toc_end = toc + streams * kTocEntryBytes;
    if (toc < kZstdHeaderBytes || toc_end > in.size())
        fail(path,
             "the table of contents at byte " + std::to_string(toc) + " (" + std::to_string(toc_end - toc) +
                 " bytes) does not lie between the 32-byte header and the file's end at " + std::to_string(in.size()),
             io::at_offset(kTocOffsetOffset));
    in.consume(kZstdHeaderBytes);
    in.skip(toc - kZstdHeaderBytes);  // extension records: nothing catgs renders
    if (!in.require(static_cast<std::size_t>(toc_end - toc)))
        fail(path, "data ends early inside the table of contents", io::at_offset(in.offset()));
    std::vector<TocEntry> entries(streams);
    std::uint64_t compressed = 0;
    for (unsigned k = 0; k < streams; ++k) {
        const unsigned char* e = in.data() + k * kTocEntryBytes;
        entries[k] = {io::load_scalar<std::uint64_t>(e, false), io::load_scalar<std::uint64_t>(e + 8, false)};
        const std::uint64_t needed = layout.block_end(k) - blocks[k].begin;
        if (entries[k].decompressed != needed)
            fail(path,
                 "the " + std::string(blocks[k].name) + " stream decompresses to " +
                     std::to_string(entries[k].decompressed) + " bytes by the table of contents, but the header's " +
                     std::to_string(needed / blocks[k].stride) + " Gaussians need " + std::to_string(needed),
                 io::at_offset(toc + k * kTocEntryBytes + 8));
        if (entries[k].compressed > in.size() - compressed)
            fail(path,
                 "the " + std::string(blocks[k].name) + " stream's compressed size " +
                     std::to_string(entries[k].compressed) + " is larger than the file",
                 io::at_offset(toc + k * kTocEntryBytes));
        compressed += entries[k].compressed;
    }
    if (compressed != in.size() - toc_end)
        fail(path,
             "the table of contents' streams take " + std::to_string(compressed) + " bytes, but " +
                 std::to_string(in.size() - toc_end) + " follow it",
             io::at_offset(toc_end));
    in.consume(static_cast<std::size_t>(toc_end - toc));
    return entries;
}

/// Decompresses one stream of `entry.compressed` bytes at the reader's position into
/// packed[begin, begin + entry.decompressed), growing `packed` only as output arrives.
void decompress_stream(io::FileReader& in, ZSTD_DCtx* context, const Block& block, const TocEntry& entry,
                       std::vector<unsigned char>& packed) {
    const std::string& path = in.path();
    const std::string stream = "the " + std::string(block.name) + " stream";
    ZSTD_DCtx_reset(context, ZSTD_reset_session_only);
    std::uint64_t left = entry.compressed, produced = 0;
    std::size_t frame_left = 0;  // ZSTD_decompressStream's hint: 0 once a frame is complete
    unsigned char overflow;      // room for one byte more than the table of contents says
    while (left > 0) {
        const std::size_t chunk = static_cast<std::size_t>(std::min<std::uint64_t>(left, kInputBlockBytes));
        if (!in.require(chunk)) fail(path, stream + " is cut off by the file's end", io::at_offset(in.offset()));
        ZSTD_inBuffer input{in.data(), chunk, 0};
        while (input.pos < input.size) {
            const std::uint64_t have = packed.size() - block.begin;
            if (produced == have && have < entry.decompressed) {
                const std::uint64_t grow = std::clamp<std::uint64_t>(packed.size(), kFirstGrowBytes, kMaxGrowBytes);
                packed.resize(block.begin + std::min(entry.decompressed, have + grow));
            }
            const std::size_t room = static_cast<std::size_t>(packed.size() - block.begin - produced);
            ZSTD_outBuffer output = room > 0 ? ZSTD_outBuffer{packed.data() + block.begin + produced, room, 0}
                                             : ZSTD_outBuffer{&overflow, 1, 0};
            const std::uint64_t at = in.offset() + input.pos;
            frame_left = ZSTD_decompressStream(context, &output, &input);
            if (ZSTD_isError(frame_left))
                fail(path, "corrupt ZSTD data in " + stream + ": " + ZSTD_getErrorName(frame_left), io::at_offset(at));
            if (room == 0 && output.pos > 0)
                fail(path,
                     stream + " decompresses to more than the " + std::to_string(entry.decompressed) +
                         " bytes the table of contents says",
                     io::at_offset(at));
            produced += room > 0 ? output.pos : 0;
        }
        in.consume(chunk);
        left -= chunk;
    }
    if (frame_left != 0 || produced != entry.decompressed)
        fail(path,
             stream + " ends after " + std::to_string(produced) + " of its " + std::to_string(entry.decompressed) +
                 " decompressed bytes" + (frame_left != 0 ? ", inside a ZSTD frame" : ""),
             io::at_offset(in.offset()));
}

/// Version 4: a plain 32-byte header, the table of contents and one ZSTD stream per block.
std::vector<unsigned char> read_zstd_payload(io::FileReader& in, const LoadOptions& options, SpzHeader& header) {
    const std::string& path = in.path();
    if (!in.require(kZstdHeaderBytes))
        fail(path, "data ends early: the file ends inside the 32-byte SPZ version 4 header", io::at_offset(0));
    unsigned char raw_header[kZstdHeaderBytes];
    std::memcpy(raw_header, in.data(), kZstdHeaderBytes);
    header = parse_header(path, raw_header, true);
    const Layout layout(header);
    check_count(path, header, layout, in.size(), kZstd, io::at_offset(8), options);
    const std::vector<TocEntry> toc = read_toc(in, raw_header, layout);
    std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> context(ZSTD_createDCtx(), &ZSTD_freeDCtx);
    if (!context) fail(path, "cannot initialise ZSTD", "");
    std::vector<unsigned char> packed;
    const std::vector<Block> blocks = layout.blocks();
    for (std::size_t k = 0; k < blocks.size(); ++k) decompress_stream(in, context.get(), blocks[k], toc[k], packed);
    return packed;
}

}  // namespace

Scene read_spz(const std::string& path, const LoadOptions& options, LoadReport* report) {
    io::FileReader in(path);
    if (in.size() == 0) fail(path, "no Gaussians: the file is empty", io::at_offset(0));
    SpzHeader header;
    std::vector<unsigned char> packed = in.require(4) && std::equal(in.data(), in.data() + 4, "NGSP")
                                            ? read_zstd_payload(in, options, header)
                                            : read_gzip_payload(in, options, header);
    const Layout layout(header);
    io::ProgressTicker ticker(options.progress, path);
    ticker.update(1, 2);  // decompressing, the first of the two passes, is done
    io::SceneBuilder builder(path, header.count, header.sh_degree, kSpzEncoding, spz_field_names(header.sh_degree),
                             options);
    const SpzDecoder decoder(header, layout, packed.data(), options.spz_axes);
    double values[io::kMaxFields];
    for (std::uint64_t i = 0; i < header.count; ++i) {
        decoder.decode(i, values);
        builder.add(values, i);
    }
    std::vector<unsigned char>().swap(packed);
    Scene scene = builder.finish(report);
    ticker.finish();
    return scene;
}

}  // namespace catgs
