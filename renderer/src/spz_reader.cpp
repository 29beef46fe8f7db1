// Niantic .spz, versions 2 and 3, written from the format's public description
// (github.com/nianticlabs/spz, README "File Format"): one gzip stream holding a 16-byte header
// and then each attribute of every Gaussian in turn (positions, alphas, colours, scales,
// rotations, SH).
//
// Memory: the stream is inflated into one packed buffer that grows with what actually
// arrives (so a lying count costs only the bytes the stream really holds) and never past what
// the header's count needs (so a gzip bomb stops there). The scene is allocated only once the
// packed data is complete, and the packed buffer (about a quarter of the scene's size) is
// released before the scene is finished.

#include <zlib.h>

#include <algorithm>
#include <array>
#include <climits>
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
constexpr std::uint32_t kFirstVersion = 2, kLastVersion = 3;
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

/// Where each attribute block starts in the payload (after the header).
struct Layout {
    std::size_t rotation_bytes = 0, sh_bytes = 0;
    std::uint64_t alphas = 0, colours = 0, scales = 0, rotations = 0, sh = 0, end = 0;

    explicit Layout(const SpzHeader& h) {
        rotation_bytes = h.version >= kSmallestThreeVersion ? 4 : 3;
        sh_bytes = 3 * static_cast<std::size_t>(sh_coefficient_count(h.sh_degree) - 1);
        alphas = h.count * kPositionBytes;
        colours = alphas + h.count;
        scales = colours + h.count * kColourBytes;
        rotations = scales + h.count * kScaleBytes;
        sh = rotations + h.count * rotation_bytes;
        end = sh + h.count * sh_bytes;
    }
    /// "the <attribute> block, Gaussian i" for a payload offset.
    std::string where(std::uint64_t offset) const {
        struct Block {
            const char* name;
            std::uint64_t begin;
            std::size_t stride;
        };
        const Block blocks[] = {{"sh", sh, sh_bytes},
                                {"rotations", rotations, rotation_bytes},
                                {"scales", scales, kScaleBytes},
                                {"colors", colours, kColourBytes},
                                {"alphas", alphas, 1},
                                {"positions", 0, kPositionBytes}};
        for (const Block& b : blocks)
            if (offset >= b.begin && b.stride > 0)
                return "the " + std::string(b.name) + " block, Gaussian " +
                       std::to_string((offset - b.begin) / b.stride) + ", decompressed byte offset " +
                       std::to_string(kHeaderBytes + offset);
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
    std::uint64_t compressed_offset() const { return in_.offset() - z_.avail_in; }

private:
    /// Hands zlib the next block of the file; false at its end.
    bool refill() {
        in_.consume(block_);
        block_ = static_cast<std::size_t>(std::min<std::uint64_t>(in_.remaining(), kInputBlockBytes));
        if (block_ == 0 || !in_.require(block_)) return false;
        z_.next_in = const_cast<Bytef*>(in_.data());
        z_.avail_in = static_cast<uInt>(block_);
        return true;
    }

    io::FileReader& in_;
    z_stream z_{};
    std::size_t block_ = 0;
    bool ended_ = false;
};

SpzHeader parse_header(const std::string& path, const unsigned char* h) {
    SpzHeader header;
    const auto magic = io::load_scalar<std::uint32_t>(h, false);
    if (magic != kSpzMagic) {
        char text[16];
        std::snprintf(text, sizeof(text), "0x%08x", magic);
        fail(path, std::string("not an SPZ stream: magic ") + text + ", expected 0x5053474e ('NGSP')",
             "decompressed byte offset 0");
    }
    header.version = io::load_scalar<std::uint32_t>(h + 4, false);
    if (header.version < kFirstVersion || header.version > kLastVersion)
        fail(path,
             "SPZ version " + std::to_string(header.version) + " is not supported (versions 2 and 3 are" +
                 (header.version == 1 ? "; version 1's float16 positions were never released)" : ")"),
             "decompressed byte offset 4");
    header.count = io::load_scalar<std::uint32_t>(h + 8, false);
    if (header.count == 0) fail(path, "no Gaussians: the header's count is 0", "decompressed byte offset 8");
    header.sh_degree = h[12];
    if (header.sh_degree > kMaxShDegree)
        fail(path,
             "SH degree " + std::to_string(header.sh_degree) + " is not supported (0.." + std::to_string(kMaxShDegree) +
                 ")",
             "decompressed byte offset 12");
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

}  // namespace

Scene read_spz(const std::string& path, const LoadOptions& options, LoadReport* report) {
    io::FileReader in(path);
    if (in.size() == 0) fail(path, "no Gaussians: the file is empty", io::at_offset(0));
    if (in.require(4) && std::equal(in.data(), in.data() + 4, "NGSP"))
        fail(path,
             "SPZ version 4 (ZSTD streams) is not supported; versions 2 and 3 (gzip) are: write version 3, e.g. "
             "splat-transform --spz-version 3",
             io::at_offset(0));
    if (!in.require(2) || in.data()[0] != 0x1f || in.data()[1] != 0x8b)
        fail(path, "not an SPZ file: no gzip signature (1f 8b)", io::at_offset(0));

    GzipStream gzip(in);
    unsigned char raw_header[kHeaderBytes];
    if (gzip.read(raw_header, kHeaderBytes) < kHeaderBytes)
        fail(path, "data ends early: the stream ends inside the 16-byte SPZ header", "decompressed byte offset 0");
    const SpzHeader header = parse_header(path, raw_header);
    const Layout layout(header);
    std::uint64_t most;
    if (!io::checked_mul(in.size(), kMaxDeflateRatio, most) || layout.end > most)
        fail(path,
             "the header's count of " + std::to_string(header.count) + " Gaussians needs " +
                 std::to_string(kHeaderBytes + layout.end) + " decompressed bytes, more than a " +
                 std::to_string(in.size()) + "-byte gzip file can hold (deflate inflates at most 1032:1)",
             "decompressed byte offset 8");
    if (header.count > options.max_records)
        fail(path, std::to_string(header.count) + " records exceed the limit of " + std::to_string(options.max_records),
             "LoadOptions::max_records");

    std::vector<unsigned char> packed = inflate_payload(path, gzip, header, layout);
    io::ProgressTicker ticker(options.progress, path);
    ticker.update(1, 2);  // inflating, the first of the two passes, is done
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
