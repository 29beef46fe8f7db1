// write_ply: binary little-endian graphdeco layout that read_ply reads back bit-exactly.

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "catgs/scene_io.hpp"
#include "scene_io_detail.hpp"

namespace catgs {

namespace {

using io::fail;

/// sigmoid(40) rounds to 1.0 in double, so clamping the logit here lets opacity 1.0 (from
/// .splat alpha 255) round-trip instead of being written as +inf, which read_ply rejects;
/// sigmoid(-40) ~ 4e-18 lies far below the 1/255 load filter.
constexpr double kMaxAbsLogit = 40.0;
/// exp(-200) underflows to 0 in float, so a zero scale (legal in .splat) round-trips
/// instead of being written as -inf, which read_ply rejects as non-finite.
constexpr double kMinLogScale = -200.0;

/// Bytes per record: x y z and opacity, scale_0..2 as double; nx ny nz, f_dc_0..2, rot_0..3
/// and the f_rest as float.
std::size_t record_bytes(int rest) {
    return 7 * sizeof(double) + (10 + static_cast<std::size_t>(rest)) * sizeof(float);
}

std::string ply_header(const Scene& scene, int rest) {
    std::string h = "ply\nformat binary_little_endian 1.0\ncomment written by catgs\n";
    h += "element vertex " + std::to_string(scene.count()) + "\n";
    for (const char* name : {"x", "y", "z"}) h += std::string("property double ") + name + "\n";
    for (const char* name : {"nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
        h += std::string("property float ") + name + "\n";
    for (int j = 0; j < rest; ++j) h += "property float f_rest_" + std::to_string(j) + "\n";
    h += "property double opacity\n";
    for (const char* name : {"scale_0", "scale_1", "scale_2"}) h += std::string("property double ") + name + "\n";
    for (const char* name : {"rot_0", "rot_1", "rot_2", "rot_3"}) h += std::string("property float ") + name + "\n";
    return h + "end_header\n";
}

double logit(float opacity) {
    double s = opacity;
    return std::clamp(std::log(s / (1.0 - s)), -kMaxAbsLogit, kMaxAbsLogit);
}

/// Encodes Gaussian i at p; returns the byte after it.
unsigned char* encode_record(const Scene& scene, std::size_t i, unsigned char* p) {
    auto put_double = [&](double v) { io::store_little_endian(p, v), p += sizeof(double); };
    auto put_float = [&](float v) { io::store_little_endian(p, v), p += sizeof(float); };
    for (int a = 0; a < 3; ++a) put_double(scene.origin[a] + static_cast<double>(scene.positions[3 * i + a]));
    for (int a = 0; a < 3; ++a) put_float(0.0f);  // normals: unused by 3DGS, kept for graphdeco tools
    const int coefficients = scene.sh_coefficients();
    const float* sh = scene.sh.data() + i * scene.sh_floats_per_gaussian();
    for (int c = 0; c < 3; ++c) put_float(sh[c]);
    // f_rest is channel-major: all of red's higher coefficients, then green's, then blue's.
    for (int c = 0; c < 3; ++c)
        for (int k = 1; k < coefficients; ++k) put_float(sh[3 * k + c]);
    put_double(logit(scene.opacities[i]));
    for (int a = 0; a < 3; ++a)
        put_double(std::max(std::log(static_cast<double>(scene.scales[3 * i + a])), kMinLogScale));
    for (int c = 0; c < 4; ++c) put_float(scene.rotations[4 * i + c]);
    return p;
}

struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
};

void write_all(std::FILE* file, const std::string& path, const void* data, std::size_t size, std::uint64_t offset) {
    if (std::fwrite(data, 1, size, file) != size) {
        int error = errno;
        fail(path, std::string("cannot write: ") + std::strerror(error), io::at_offset(offset));
    }
}

}  // namespace

void write_ply(const Scene& scene, const std::string& path) {
    scene.check_consistent(path);
    std::unique_ptr<std::FILE, FileCloser> file(std::fopen(path.c_str(), "wb"));
    if (!file) {
        int error = errno;
        fail(path, std::string("cannot open for writing: ") + std::strerror(error), "");
    }
    const int rest = 3 * (scene.sh_coefficients() - 1);
    const std::string header = ply_header(scene, rest);
    write_all(file.get(), path, header.data(), header.size(), 0);
    std::uint64_t offset = header.size();

    const std::size_t stride = record_bytes(rest);
    const std::size_t per_chunk = std::max<std::size_t>(1, io::kChunkBytes / stride);
    std::vector<unsigned char> buffer(std::min(per_chunk, std::max<std::size_t>(scene.count(), 1)) * stride);
    for (std::size_t done = 0; done < scene.count();) {
        const std::size_t n = std::min(per_chunk, scene.count() - done);
        unsigned char* p = buffer.data();
        for (std::size_t i = done; i < done + n; ++i) p = encode_record(scene, i, p);
        write_all(file.get(), path, buffer.data(), n * stride, offset);
        offset += n * stride;
        done += n;
    }
    // fclose flushes the stdio buffer: a full disk often shows up only here.
    if (std::fclose(file.release()) != 0) {
        int error = errno;
        fail(path, std::string("cannot write: ") + std::strerror(error), io::at_offset(offset));
    }
}

}  // namespace catgs
