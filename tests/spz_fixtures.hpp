// The .spz writer of the reader tests (test_scene_io_spz*.cpp): versions 2 and 3 built byte by
// byte and gzipped, version 4 as a header, a table of contents and a ZSTD stream per attribute
// block, each part replaceable so that the bad-input tests can lie in any one of them.
#pragma once

#include <zlib.h>
#include <zstd.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "catgs/scene_format.hpp"
#include "catgs/stages/sh.hpp"
#include "scene_io_fixtures.hpp"

namespace catgs::scene_io_test {

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

inline std::uint8_t byte_of(double v) {
    return static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
}

inline void put_smallest_three(std::string& out, std::array<double, 4> q) {
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

inline std::string SpzFile::payload() const {
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

inline std::string gzip(const std::string& bytes) {
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
inline std::vector<SpzGaussian> asymmetric(int sh_degree) {
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

inline std::string zstd(const std::string& bytes) {
    std::string out(ZSTD_compressBound(bytes.size()), '\0');
    const std::size_t n = ZSTD_compress(out.data(), out.size(), bytes.data(), bytes.size(), 3);
    EXPECT_FALSE(ZSTD_isError(n));
    out.resize(n);
    return out;
}

/// A version 4 file's parts from `file`'s payload (which is laid out as versions 2 and 3 are):
/// each attribute block compressed on its own, the table of contents telling the truth.
inline ZstdParts zstd_parts(const SpzFile& file) {
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
inline std::string write_spz(const std::string& name, const SpzFile& file) {
    const std::string path = tmp_path(name);
    write_file(path, file.version >= 4 ? zstd_parts(file).bytes(file.payload().substr(0, 16)) : gzip(file.payload()));
    return path;
}

/// The quaternion (w, x, y, z) of a Gaussian, normalised, with w >= 0 (q and -q are one rotation).
inline std::array<double, 4> canonical(const float* q) {
    const double sign = q[0] < 0 ? -1 : 1;
    return {sign * q[0], sign * q[1], sign * q[2], sign * q[3]};
}

}  // namespace catgs::scene_io_test
