// The antimatter15 .splat format: headerless 32-byte little-endian records.

#include <algorithm>
#include <string>
#include <vector>

#include "catgs/scene_io.hpp"
#include "scene_io_detail.hpp"

namespace catgs {

namespace {

using io::fail;

constexpr std::size_t kSplatRecordBytes = 32;
constexpr std::size_t kColourOffset = 24;      ///< after 3 float32 position, 3 float32 scale
constexpr std::size_t kQuaternionOffset = 28;  ///< after RGBA
/// Colour bytes are 255 * (0.5 + kShC0 * f_dc): kShC0 is the degree-0 SH basis constant
/// 1 / (2 sqrt(pi)).
constexpr double kShC0 = 0.28209479177387814;
/// Quaternion components are stored as q * 128 + 128.
constexpr double kQuaternionBias = 128.0;

constexpr io::Encoding kSplatEncoding{.log_scale = false, .logit_opacity = false, .noun = "field", .nouns = "fields"};

std::vector<std::string> splat_field_names() {
    return {"x",     "y",     "z",     "scale_0", "scale_1", "scale_2", "alpha",
            "rot_0", "rot_1", "rot_2", "rot_3",   "red",     "green",   "blue"};
}

void decode_record(const unsigned char* p, double* values) {
    for (int a = 0; a < 3; ++a) {
        values[io::kFieldX + a] = io::load_scalar<float>(p + 4 * a, false);
        values[io::kFieldScale + a] = io::load_scalar<float>(p + 12 + 4 * a, false);
    }
    const unsigned char* rgba = p + kColourOffset;
    for (int c = 0; c < 3; ++c) values[io::kFieldSh + c] = (rgba[c] / 255.0 - 0.5) / kShC0;
    values[io::kFieldOpacity] = rgba[3] / 255.0;
    for (int c = 0; c < 4; ++c)
        values[io::kFieldRot + c] = (p[kQuaternionOffset + c] - kQuaternionBias) / kQuaternionBias;
}

}  // namespace

Scene read_splat(const std::string& path, const LoadOptions& options, LoadReport* report) {
    io::FileReader in(path);
    if (in.size() == 0) fail(path, "no Gaussians: the file is empty", io::at_offset(0));
    const std::uint64_t trailing = in.size() % kSplatRecordBytes;
    if (trailing != 0)
        fail(path,
             "file size " + std::to_string(in.size()) +
                 " is not a multiple of the 32-byte record: " + std::to_string(trailing) + " trailing bytes",
             io::at_offset(in.size() - trailing));
    const std::uint64_t records = in.size() / kSplatRecordBytes;

    io::SceneBuilder builder(path, records, 0, kSplatEncoding, splat_field_names(), options);
    io::ProgressTicker ticker(options.progress, path);
    constexpr std::uint64_t kPerChunk = io::kChunkBytes / kSplatRecordBytes;
    double values[io::kMaxFields];
    for (std::uint64_t done = 0; done < records;) {
        const std::size_t n = static_cast<std::size_t>(std::min(kPerChunk, records - done));
        if (!in.require(n * kSplatRecordBytes)) fail(path, "data ends early", io::at_record(done));
        const unsigned char* record = in.data();
        for (std::size_t r = 0; r < n; ++r, record += kSplatRecordBytes) {
            decode_record(record, values);
            builder.add(values, done + r);
        }
        in.consume(n * kSplatRecordBytes);
        done += n;
        ticker.update(in.offset(), in.size());
    }
    Scene scene = builder.finish(report);
    ticker.finish();
    return scene;
}

}  // namespace catgs
