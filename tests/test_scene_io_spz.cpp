// read_spz: .spz versions 2 and 3 built byte by byte here (zlib gzips them) and version 4
// (a plain header, a table of contents and a ZSTD stream per attribute block), decoded exactly
// as the format quantises; the RUB conversion checked against the geometry it must preserve;
// and bad input (magic, version, truncation, lying counts and tables of contents,
// decompression bombs, NaN after dequantisation) with the message it must give.

#include <zlib.h>
#include <zstd.h>

#include <cmath>
#include <random>
#include <cstdint>
#include <string>
#include <vector>

#include "catgs/scene_format.hpp"
#include "catgs/stages/sh.hpp"
#include "scene_io_fixtures.hpp"

namespace catgs::scene_io_test {
namespace {

/// One Gaussian as the test means it, before quantisation.
struct SpzGaussian {
    std::array<double, 3> position;
    double alpha;
    std::array<double, 3> colour;     ///< f_dc
    std::array<double, 3> log_scale;  ///< log of the scale
    std::array<double, 4> q_xyzw;     ///< need not be unit
    std::vector<double> sh;           ///< [coefficient][rgb] without the DC term
};

struct SpzFile {
    std::uint32_t magic = 0x5053474e;
    std::uint32_t version = 3;
    int sh_degree = 1;
    int fractional_bits = 12;
    std::uint8_t flags = 0;
    std::optional<std::uint32_t> count;  ///< overrides the header's count
    std::vector<SpzGaussian> gaussians;
    std::string trailing;  ///< after the SH block

    std::string payload() const;
};

std::uint8_t byte_of(double v) {
    return static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
}

void put_smallest_three(std::string& out, std::array<double, 4> q) {
    double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    int largest = 0;
    for (int c = 0; c < 4; ++c) {
        q[c] /= n;
        if (std::fabs(q[c]) > std::fabs(q[largest])) largest = c;
    }
    const bool negate = q[largest] < 0;
    std::uint32_t bits = static_cast<std::uint32_t>(largest);
    for (int c = 0; c < 4; ++c) {
        if (c == largest) continue;
        const std::uint32_t sign = (q[c] < 0) != negate;
        const auto magnitude = static_cast<std::uint32_t>(std::lround(511 * std::fabs(q[c]) / std::sqrt(0.5)));
        bits = (bits << 10) | (sign << 9) | magnitude;
    }
    put(out, bits, false);
}

std::string SpzFile::payload() const {
    std::string out;
    put(out, magic, false);
    put(out, version, false);
    put(out, count.value_or(static_cast<std::uint32_t>(gaussians.size())), false);
    out += static_cast<char>(sh_degree);
    out += static_cast<char>(fractional_bits);
    out += static_cast<char>(flags);
    out += '\0';
    for (const auto& g : gaussians)
        for (double p : g.position) {
            const auto fixed = static_cast<std::int32_t>(std::lround(p * (1 << fractional_bits)));
            for (int b = 0; b < 3; ++b) out += static_cast<char>((fixed >> (8 * b)) & 0xff);
        }
    for (const auto& g : gaussians) out += static_cast<char>(byte_of(255 * g.alpha));
    for (const auto& g : gaussians)
        for (double c : g.colour) out += static_cast<char>(byte_of(255 * (0.5 + 0.15 * c)));
    for (const auto& g : gaussians)
        for (double s : g.log_scale) out += static_cast<char>(byte_of(16 * (s + 10)));
    for (const auto& g : gaussians) {
        if (version >= 3) {
            put_smallest_three(out, g.q_xyzw);
        } else {
            auto q = g.q_xyzw;
            const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
            const double sign = q[3] < 0 ? -1 : 1;
            for (int c = 0; c < 3; ++c) out += static_cast<char>(byte_of(127.5 * (1 + sign * q[c] / n)));
        }
    }
    for (const auto& g : gaussians)
        for (double c : g.sh) out += static_cast<char>(byte_of(128 + 128 * c));
    return out + trailing;
}

std::string gzip(const std::string& bytes) {
    z_stream z{};
    EXPECT_EQ(deflateInit2(&z, 6, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
    std::string out(deflateBound(&z, bytes.size()), '\0');
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
    z.avail_in = static_cast<uInt>(bytes.size());
    z.next_out = reinterpret_cast<Bytef*>(out.data());
    z.avail_out = static_cast<uInt>(out.size());
    EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
    out.resize(z.total_out);
    deflateEnd(&z);
    return out;
}

/// Three Gaussians asymmetric in every axis, with SH of the given degree.
std::vector<SpzGaussian> asymmetric(int sh_degree) {
    std::vector<SpzGaussian> g;
    for (int i = 0; i < 3; ++i) {
        SpzGaussian x{{1.25 + i, -2.5 + 0.5 * i, 7.75 - i},
                      0.2 + 0.3 * i,
                      {0.4, -0.2 * i, 1.1},
                      {-3.0 + 0.25 * i, -4.0, -2.5},
                      {0.1 + 0.2 * i, -0.3, 0.6, 0.7 - 0.1 * i},
                      {}};
        for (int k = 0; k < 3 * (sh_coefficient_count(sh_degree) - 1); ++k)
            x.sh.push_back(((k * 7 + i * 3) % 11 - 5) / 8.0);
        g.push_back(x);
    }
    return g;
}

/// The parts of a version 4 file, each replaceable by a test: the 32-byte header's stream count
/// and table-of-contents offset, extension bytes between the header and the table, and the
/// streams with their table entries.
struct ZstdParts {
    std::optional<std::uint8_t> stream_count;
    std::optional<std::uint32_t> toc_offset;
    std::string extensions;
    std::vector<std::string> streams;                     ///< compressed
    std::vector<std::uint64_t> compressed, decompressed;  ///< the table of contents

    std::string bytes(const std::string& header16) const {
        std::string out = header16;
        out[15] = static_cast<char>(stream_count.value_or(static_cast<std::uint8_t>(streams.size())));
        put(out, toc_offset.value_or(static_cast<std::uint32_t>(32 + extensions.size())), false);
        out += std::string(12, '\0');
        out += extensions;
        for (std::size_t k = 0; k < compressed.size(); ++k) {
            put(out, compressed[k], false);
            put(out, decompressed[k], false);
        }
        for (const std::string& stream : streams) out += stream;
        return out;
    }
};

std::string zstd(const std::string& bytes) {
    std::string out(ZSTD_compressBound(bytes.size()), '\0');
    const std::size_t n = ZSTD_compress(out.data(), out.size(), bytes.data(), bytes.size(), 3);
    EXPECT_FALSE(ZSTD_isError(n));
    out.resize(n);
    return out;
}

/// A version 4 file's parts from `file`'s payload (which is laid out as versions 2 and 3 are):
/// each attribute block compressed on its own, the table of contents telling the truth.
ZstdParts zstd_parts(const SpzFile& file) {
    const std::string payload = file.payload();
    const std::size_t n = file.gaussians.size();
    const std::size_t sh = 3 * static_cast<std::size_t>(sh_coefficient_count(file.sh_degree) - 1);
    std::vector<std::size_t> sizes = {9 * n, n, 3 * n, 3 * n, 4 * n};
    if (sh > 0) sizes.push_back(sh * n);
    ZstdParts parts;
    std::size_t at = 16;
    for (std::size_t size : sizes) {
        parts.streams.push_back(zstd(payload.substr(at, size)));
        parts.compressed.push_back(parts.streams.back().size());
        parts.decompressed.push_back(size);
        at += size;
    }
    return parts;
}

/// Writes `file` as its version says: gzipped for 2 and 3, ZSTD streams for 4.
std::string write_spz(const std::string& name, const SpzFile& file) {
    const std::string path = tmp_path(name);
    write_file(path, file.version >= 4 ? zstd_parts(file).bytes(file.payload().substr(0, 16)) : gzip(file.payload()));
    return path;
}

/// The quaternion (w, x, y, z) of a Gaussian, normalised, with w >= 0 (q and -q are one rotation).
std::array<double, 4> canonical(const float* q) {
    const double sign = q[0] < 0 ? -1 : 1;
    return {sign * q[0], sign * q[1], sign * q[2], sign * q[3]};
}

TEST(SceneIoSpz, DecodesEveryFieldAsTheFormatQuantisesIt) {
    for (std::uint32_t version : {2u, 3u, 4u}) {
        SCOPED_TRACE("version " + std::to_string(version));
        SpzFile file;
        file.version = version;
        file.gaussians = asymmetric(1);
        const std::string path = write_spz("v" + std::to_string(version) + ".spz", file);
        const Scene s = read_spz(path, absolute());
        ASSERT_EQ(s.count(), 3u);
        EXPECT_EQ(s.sh_degree, 1);
        const std::string payload = file.payload();
        for (std::size_t i = 0; i < 3; ++i) {
            const SpzGaussian& g = file.gaussians[i];
            // Positions are multiples of 1/4096 here: exact.
            for (int a = 0; a < 3; ++a) EXPECT_EQ(s.positions[3 * i + a], g.position[a]);
            EXPECT_FLOAT_EQ(s.opacities[i], static_cast<float>(byte_of(255 * g.alpha) / 255.0));
            for (int a = 0; a < 3; ++a) {
                EXPECT_FLOAT_EQ(s.scales[3 * i + a],
                                static_cast<float>(std::exp(byte_of(16 * (g.log_scale[a] + 10)) / 16.0 - 10)));
                EXPECT_NEAR(s.sh[12 * i + a], g.colour[a], 0.5 / 255 / 0.15 + 1e-6);
            }
            for (int k = 0; k < 6; ++k) EXPECT_NEAR(s.sh[12 * i + 3 + k], g.sh[k], 0.5 / 128 + 1e-6);
            const double n = std::sqrt(g.q_xyzw[0] * g.q_xyzw[0] + g.q_xyzw[1] * g.q_xyzw[1] +
                                       g.q_xyzw[2] * g.q_xyzw[2] + g.q_xyzw[3] * g.q_xyzw[3]);
            const double sign = g.q_xyzw[3] < 0 ? -1 : 1;
            const std::array<double, 4> want = {sign * g.q_xyzw[3] / n, sign * g.q_xyzw[0] / n, sign * g.q_xyzw[1] / n,
                                                sign * g.q_xyzw[2] / n};
            const auto got = canonical(&s.rotations[4 * i]);
            // v2: 8-bit components; v3 and v4: 9-bit magnitudes of sqrt(1/2).
            const double tolerance = version == 2 ? 0.01 : 0.003;
            for (int c = 0; c < 4; ++c) EXPECT_NEAR(got[c], want[c], tolerance) << "component " << c;
        }
    }
}

TEST(SceneIoSpz, EveryShDegreeAndFractionalBits) {
    for (std::uint32_t version : {3u, 4u})
        for (int degree = 0; degree <= kMaxShDegree; ++degree) {
            SpzFile file;
            file.version = version;
            file.sh_degree = degree;
            file.fractional_bits = 8 + degree;
            file.gaussians = asymmetric(degree);
            // Appended piece by piece: GCC 12's -Wrestrict misfires on one long concatenation.
            std::string name = "v";
            name += std::to_string(version);
            name += "sh";
            name += std::to_string(degree);
            name += ".spz";
            const Scene s = read_spz(write_spz(name, file), absolute());
            EXPECT_EQ(s.sh_degree, degree);
            EXPECT_EQ(s.sh.size(), 3 * 3u * sh_coefficient_count(degree));
            EXPECT_EQ(s.positions[0], 1.25f);
            EXPECT_EQ(s.positions[1], -2.5f);
            if (degree > 0) {
                EXPECT_NEAR(s.sh[3], file.gaussians[0].sh[0], 0.5 / 128 + 1e-6);
            }
        }
}

/// Version 4 carries the same quantised values as version 3 in another container: the scenes
/// must be identical, and extension records between the header and the table are skipped.
TEST(SceneIoSpz, VersionFourLoadsWhatVersionThreeHolds) {
    SpzFile file;
    file.sh_degree = 3;
    file.gaussians = asymmetric(3);
    const Scene v3 = read_spz(write_spz("same_v3.spz", file), absolute());
    file.version = 4;
    const Scene v4 = read_spz(write_spz("same_v4.spz", file), absolute());
    EXPECT_EQ(v4.positions, v3.positions);
    EXPECT_EQ(v4.scales, v3.scales);
    EXPECT_EQ(v4.rotations, v3.rotations);
    EXPECT_EQ(v4.opacities, v3.opacities);
    EXPECT_EQ(v4.sh, v3.sh);

    file.flags = 0x2;
    ZstdParts parts = zstd_parts(file);
    parts.extensions = std::string(8, '\x01') + "extdata!";  // skipped whatever it holds
    const std::string path = tmp_path("extensions_v4.spz");
    write_file(path, parts.bytes(file.payload().substr(0, 16)));
    EXPECT_EQ(read_spz(path, absolute()).sh, v3.sh);
}

/// With SpzAxes::rub the file's frame is x right, y up, z back: catgs' RDF sees the same
/// geometry after a half turn about x, S = diag(1, -1, -1). Positions map by S, rotations by
/// S R S, and the colour seen along a direction d (in the file's frame) must equal the colour
/// of the converted coefficients seen along S d: checked through sh_colour, independently of
/// the reader's sign table.
TEST(SceneIoSpz, RubFilesConvertToRdfPreservingGeometryAndColour) {
    SpzFile file;
    file.sh_degree = 3;
    file.gaussians = asymmetric(3);
    const std::string path = write_spz("rub.spz", file);
    const Scene raw = read_spz(path, absolute());
    LoadOptions rub = absolute();
    rub.spz_axes = SpzAxes::rub;
    const Scene converted = read_spz(path, rub);
    ASSERT_EQ(raw.count(), converted.count());
    const double s[3] = {1, -1, -1};
    for (std::size_t i = 0; i < raw.count(); ++i) {
        for (int a = 0; a < 3; ++a) EXPECT_EQ(converted.positions[3 * i + a], s[a] * raw.positions[3 * i + a]);
        const float* q = &raw.rotations[4 * i];
        const float* r = &converted.rotations[4 * i];
        EXPECT_EQ(r[0], q[0]);
        for (int a = 0; a < 3; ++a) EXPECT_EQ(r[1 + a], s[a] * q[1 + a]);
        for (const Vec3<double> d : {Vec3<double>{0.6, 0.0, 0.8}, Vec3<double>{-0.48, 0.6, 0.64},
                                     Vec3<double>{0.0, -0.6, 0.8}, Vec3<double>{0.36, 0.48, -0.8}}) {
            const Vec3<double> in_file = sh_colour(&raw.sh[48 * i], 3, d);
            const Vec3<double> in_catgs = sh_colour(&converted.sh[48 * i], 3, Vec3<double>{d.x, -d.y, -d.z});
            EXPECT_NEAR(in_catgs.x, in_file.x, 1e-6);
            EXPECT_NEAR(in_catgs.y, in_file.y, 1e-6);
            EXPECT_NEAR(in_catgs.z, in_file.z, 1e-6);
        }
    }
}

TEST(SceneIoSpz, LoadSceneFindsSpzByContentWhateverTheName) {
    SpzFile file;
    file.gaussians = asymmetric(1);
    const std::string path = tmp_path("misnamed.ply");
    write_file(path, gzip(file.payload()));
    EXPECT_EQ(detect_scene_format(path), SceneFormat::spz);
    LoadOptions options = absolute();
    options.chunks = false;
    const Scene s = load_scene(path, options);
    EXPECT_EQ(s.count(), 3u);
    EXPECT_EQ(s.sh_degree, 1);
}

TEST(SceneIoSpzBad, SignaturesVersionsAndHeader) {
    const std::string empty = tmp_path("empty.spz");
    write_file(empty, "");
    expect_error([&] { read_spz(empty); }, empty, {"no Gaussians: the file is empty", "byte offset 0"});

    const std::string plain = tmp_path("plain.spz");
    write_file(plain, "ply\nformat ascii 1.0\n");
    expect_error([&] { read_spz(plain); }, plain,
                 {"no gzip signature (1f 8b) and no 'NGSP' (version 4)", "byte offset 0"});

    SpzFile file;
    file.gaussians = asymmetric(1);
    file.magic = 0x12345678;
    const std::string magic = write_spz("magic.spz", file);
    expect_error([&] { read_spz(magic); }, magic,
                 {"not an SPZ stream: magic 0x12345678, expected 0x5053474e ('NGSP')", "decompressed byte offset 0"});

    file.magic = 0x5053474e;
    for (std::uint32_t version : {1u, 4u, 77u}) {
        file.version = version;
        const std::string path = tmp_path("version" + std::to_string(version) + ".spz");
        write_file(path, gzip(file.payload()));
        expect_error([&] { read_spz(path); }, path,
                     {"SPZ version " + std::to_string(version) +
                          " is not supported in a gzip stream (versions 2 and 3 are; version 4 files are not gzipped",
                      "decompressed byte offset 4"});
    }
    file.version = 3;
    file.sh_degree = 4;
    const std::string degree = write_spz("degree4.spz", file);
    expect_error([&] { read_spz(degree); }, degree,
                 {"SH degree 4 is not supported (0..3)", "decompressed byte offset 12"});

    file.sh_degree = 1;
    file.count = 0;
    const std::string zero = write_spz("zero.spz", file);
    expect_error([&] { read_spz(zero); }, zero, {"no Gaussians: the header's count is 0"});

    const std::string header_cut = tmp_path("header_cut.spz");
    write_file(header_cut, gzip(file.payload().substr(0, 10)));
    expect_error([&] { read_spz(header_cut); }, header_cut, {"the stream ends inside the 16-byte SPZ header"});
}

TEST(SceneIoSpzBad, TruncatedAndCorruptStreams) {
    SpzFile file;
    file.sh_degree = 2;
    file.gaussians = asymmetric(2);
    const std::string whole = gzip(file.payload());
    const std::string cut = tmp_path("cut.spz");
    write_file(cut, whole.substr(0, whole.size() / 2));
    expect_error([&] { read_spz(cut); }, cut, {"data ends early: the stream is cut off after", "Gaussians need"});

    // A complete payload without the gzip trailer (CRC and size).
    const std::string no_trailer = tmp_path("no_trailer.spz");
    write_file(no_trailer, whole.substr(0, whole.size() - 8));
    expect_error([&] { read_spz(no_trailer); }, no_trailer, {"truncated gzip stream"});

    std::string corrupt = whole;
    for (std::size_t i = 12; i < corrupt.size() - 8; i += 3) corrupt[i] = static_cast<char>(corrupt[i] ^ 0x5a);
    const std::string bad = tmp_path("corrupt.spz");
    write_file(bad, corrupt);
    const std::string message = error_of([&] { read_spz(bad); });
    EXPECT_THAT(message, ::testing::StartsWith(bad + ": "));
    EXPECT_THAT(message, ::testing::AnyOf(HasSubstr("corrupt gzip data"), HasSubstr("data ends early"),
                                          HasSubstr("not an SPZ stream"), HasSubstr("truncated gzip stream"),
                                          HasSubstr("more than the header's")));
}

/// Whether a byte value makes zlib refuse the stream depends on the deflate bits around it and
/// on zlib's version, so every value is tried rather than one baked in.
std::string first_zlib_error(std::string bytes, std::size_t at, const std::string& path) {
    for (int value = 0; value < 256; ++value) {
        bytes[at] = static_cast<char>(value);
        write_file(path, bytes);
        try {
            read_spz(path);
        } catch (const Error& e) {
            if (std::string(e.what()).find("corrupt gzip data: ") != std::string::npos) return e.what();
        }
    }
    return "";
}

// The offset once came out as the start of the read block minus zlib's unread input, which
// wraps below zero; it must be where zlib stopped, at or just past the damaged byte.
TEST(SceneIoSpzBad, CorruptGzipDataNamesItsOffsetInTheFile) {
    SpzFile file;
    file.gaussians = asymmetric(1);
    const std::string whole = gzip(file.payload());
    constexpr std::size_t kDamaged = 20;
    const std::string path = tmp_path("corrupt20.spz");
    const std::string message = first_zlib_error(whole, kDamaged, path);
    ASSERT_THAT(message, ::testing::StartsWith(path + ": corrupt gzip data: "));
    const std::string marker = "(byte offset ";
    ASSERT_THAT(message, HasSubstr(marker));
    const std::uint64_t offset = std::stoull(message.substr(message.rfind(marker) + marker.size()));
    EXPECT_LE(offset, whole.size()) << message;
    // zlib may have pulled a few bytes past the damage into its bit buffer before it decodes.
    EXPECT_GE(offset, kDamaged) << message;
    EXPECT_LE(offset, kDamaged + 8) << message;
}

TEST(SceneIoSpzBad, LyingCounts) {
    SpzFile file;
    file.gaussians = asymmetric(1);
    file.count = 4;  // one more than the payload holds: the stream ends in the SH block
    const std::string more = write_spz("more.spz", file);
    expect_error([&] { read_spz(more); }, more,
                 {"data ends early: the stream ends after", "4 Gaussians need", "the sh block, Gaussian"});

    file.count = 2;  // one less: bytes are left over
    const std::string fewer = write_spz("fewer.spz", file);
    expect_error([&] { read_spz(fewer); }, fewer,
                 {"more than the header's 2 Gaussians need (a count that is too small)"});

    file.count = 4'000'000'000u;  // far more than the file could inflate to: refused before inflating
    const std::string huge = write_spz("huge.spz", file);
    expect_error([&] { read_spz(huge); }, huge,
                 {"the header's count of 4000000000 Gaussians needs", "deflate inflates at most 1032:1",
                  "decompressed byte offset 8"});

    file.count.reset();
    LoadOptions capped;
    capped.max_records = 2;
    const std::string capped_path = write_spz("capped.spz", file);
    expect_error([&] { read_spz(capped_path, capped); }, capped_path,
                 {"3 records exceed the limit of 2", "LoadOptions::max_records"});
    LoadOptions budget;
    budget.max_scene_bytes = 2 * scene_bytes_per_gaussian(1);
    expect_error(
        [&] { read_spz(capped_path, budget); }, capped_path,
        {"3 records of SH degree 1 at 92 bytes each exceed the limit of 184 bytes", "LoadOptions::max_scene_bytes"});
}

/// A small file that inflates to 16 MiB of zeros after a valid 3-Gaussian payload: the reader
/// must stop at what the count needs (and the 1 MiB extension allowance), not inflate it all.
TEST(SceneIoSpzBad, GzipBombStopsAtTheDeclaredCount) {
    SpzFile file;
    file.sh_degree = 0;
    file.gaussians = asymmetric(0);
    file.trailing = std::string(std::size_t{16} << 20, '\0');
    const std::string compressed = gzip(file.payload());
    ASSERT_LT(compressed.size(), 50'000u);
    const std::string bomb = tmp_path("bomb.spz");
    write_file(bomb, compressed);
    expect_error([&] { read_spz(bomb); }, bomb, {"more than the header's 3 Gaussians need"});
    file.flags = 0x2;  // extensions may follow, but not 16 MiB of them
    write_file(bomb, gzip(file.payload()));
    expect_error([&] { read_spz(bomb); }, bomb, {"more than the header's 3 Gaussians need", "extensions beyond 1 MiB"});

    file.trailing = "ext";  // a short extension record is skipped
    const Scene s = read_spz(write_spz("extension.spz", file));
    EXPECT_EQ(s.count(), 3u);
}

/// Version 3's three stored components can square-sum past 1 only in a corrupt file: the
/// derived largest component is then the square root of a negative number.
TEST(SceneIoSpzBad, NanAfterDequantisation) {
    SpzFile file;
    file.sh_degree = 0;
    file.gaussians = asymmetric(0);
    std::string payload = file.payload();
    const std::size_t rotations = 16 + 3 * (9 + 1 + 3 + 3);
    // Largest index 3 (w), three magnitudes of 511 (sqrt(1/2) each): 1.5 > 1.
    const std::uint32_t bits = (3u << 30) | (511u << 20) | (511u << 10) | 511u;
    std::memcpy(&payload[rotations + 4], &bits, 4);
    const std::string path = tmp_path("nan.spz");
    write_file(path, gzip(payload));
    expect_error([&] { read_spz(path); }, path, {"non-finite value nan", "record 1", "field 'rot_w'"});
    LoadReport report;
    const Scene s = read_spz(path, dropping(), &report);
    EXPECT_EQ(s.count(), 2u);
    EXPECT_EQ(report.dropped_invalid, 1u);
}

/// A version 4 file whose header, table of contents or streams lie, each refused with what
/// lies and where.
TEST(SceneIoSpzBad, VersionFourContainers) {
    SpzFile file;
    file.version = 4;
    file.sh_degree = 1;
    file.gaussians = asymmetric(1);
    const std::string header = file.payload().substr(0, 16);
    const std::string path = tmp_path("bad_v4.spz");
    auto refused = [&](const ZstdParts& parts, std::vector<std::string> parts_of_message) {
        write_file(path, parts.bytes(header));
        expect_error([&] { read_spz(path); }, path, parts_of_message);
    };
    ZstdParts parts = zstd_parts(file);
    parts.stream_count = 5;
    refused(parts, {"the header names 5 ZSTD streams, but a file of this SH degree has 6", "byte offset 15"});

    parts = zstd_parts(file);
    parts.toc_offset = 20;
    refused(parts, {"the table of contents at byte 20", "does not lie between the 32-byte header", "byte offset 16"});
    parts.toc_offset = 1u << 30;
    refused(parts, {"the table of contents at byte 1073741824"});

    parts = zstd_parts(file);
    parts.decompressed[2] = 8;  // the colours of 3 Gaussians are 9 bytes
    refused(parts, {"the colors stream decompresses to 8 bytes by the table of contents, but the header's 3 "
                    "Gaussians need 9"});

    parts = zstd_parts(file);
    parts.streams.back() += "junk";  // bytes after the last stream
    refused(parts, {"the table of contents' streams take", "but", "follow it"});

    parts = zstd_parts(file);
    parts.compressed[0] = 1u << 30;
    refused(parts, {"the positions stream's compressed size 1073741824 is larger than the file"});

    // A stream that holds more than its entry says, and one that holds less.
    parts = zstd_parts(file);
    const std::string payload = file.payload();
    parts.streams[1] = zstd(payload.substr(16 + 27, 4));
    parts.compressed[1] = parts.streams[1].size();
    refused(parts, {"the alphas stream decompresses to more than the 3 bytes the table of contents says"});
    parts.streams[1] = zstd(payload.substr(16 + 27, 2));
    parts.compressed[1] = parts.streams[1].size();
    refused(parts, {"the alphas stream ends after 2 of its 3 decompressed bytes"});

    // A frame cut short, and one corrupted.
    parts = zstd_parts(file);
    parts.streams[0].resize(parts.streams[0].size() - 3);
    parts.compressed[0] = parts.streams[0].size();
    refused(parts, {"the positions stream ends after", "inside a ZSTD frame"});
    parts = zstd_parts(file);
    for (std::size_t i = 0; i < parts.streams[4].size(); ++i) parts.streams[4][i] = static_cast<char>(0xa5 ^ i);
    refused(parts, {"corrupt ZSTD data in the rotations stream"});

    // The header's count against what the file could hold, and against the caller's limit.
    SpzFile huge = file;
    huge.count = 4'000'000'000u;
    write_file(path, zstd_parts(file).bytes(huge.payload().substr(0, 16)));
    expect_error([&] { read_spz(path); }, path,
                 {"the header's count of 4000000000 Gaussians needs", "ZSTD expands at most 32768:1", "byte offset 8"});
    write_file(path, zstd_parts(file).bytes(header));
    LoadOptions capped;
    capped.max_records = 2;
    expect_error([&] { read_spz(path, capped); }, path, {"3 records exceed the limit of 2"});

    write_file(path, header.substr(0, 4) + std::string("\x05\0\0\0", 4) + header.substr(8) + std::string(16, '\0'));
    expect_error([&] { read_spz(path); }, path,
                 {"SPZ version 5 is not supported in a plain (not gzipped) file", "byte offset 4"});
    write_file(path, header);
    expect_error([&] { read_spz(path); }, path, {"the file ends inside the 32-byte SPZ version 4 header"});
}

/// A version 4 stream that decompresses to far more than its table entry (16 MiB of zeros in
/// a few hundred bytes): the reader stops one byte past what the entry says.
TEST(SceneIoSpzBad, ZstdBombStopsAtTheTableOfContents) {
    SpzFile file;
    file.version = 4;
    file.sh_degree = 0;
    file.gaussians = asymmetric(0);
    ZstdParts parts = zstd_parts(file);
    parts.streams[3] = zstd(std::string(std::size_t{16} << 20, '\0'));
    parts.compressed[3] = parts.streams[3].size();
    ASSERT_LT(parts.streams[3].size(), 5'000u);
    const std::string path = tmp_path("zstd_bomb.spz");
    write_file(path, parts.bytes(file.payload().substr(0, 16)));
    expect_error([&] { read_spz(path); }, path, {"the scales stream decompresses to more than the 9 bytes"});
}

/// Every truncation of a small file, and random byte flips of its payload (gzipped again so
/// that they reach the decoder), end in a scene or a catgs::Error naming the file.
TEST(SceneIoSpzBad, TruncationsAndMutationsNeverEscape) {
    SpzFile file;
    file.sh_degree = 2;
    file.gaussians = asymmetric(2);
    const std::string payload = file.payload();
    const std::string whole = gzip(payload);
    const std::string path = tmp_path("mutated.spz");
    auto survives = [&](const std::string& bytes) {
        write_file(path, bytes);
        for (const LoadOptions& options : {absolute(), dropping()}) {
            try {
                const Scene s = read_spz(path, options);
                EXPECT_NO_THROW(s.check_consistent(path));
            } catch (const Error& e) {
                EXPECT_THAT(std::string(e.what()), ::testing::StartsWith(path + ": "));
            }
        }
    };
    for (std::size_t keep = 0; keep < whole.size(); ++keep) survives(whole.substr(0, keep));
    std::mt19937_64 rng(test::fresh_seed("spz mutations"));
    for (int trial = 0; trial < 300; ++trial) {
        std::string mutated = payload;
        for (int flips = 0; flips < 3; ++flips) mutated[rng() % mutated.size()] = static_cast<char>(rng());
        survives(gzip(mutated));
    }
    // Version 4: every truncation, and flips anywhere in the header, table or streams.
    file.version = 4;
    const std::string v4 = zstd_parts(file).bytes(file.payload().substr(0, 16));
    for (std::size_t keep = 0; keep < v4.size(); ++keep) survives(v4.substr(0, keep));
    for (int trial = 0; trial < 300; ++trial) {
        std::string mutated = v4;
        for (int flips = 0; flips < 3; ++flips) mutated[rng() % mutated.size()] = static_cast<char>(rng());
        survives(mutated);
    }
}

}  // namespace
}  // namespace catgs::scene_io_test
