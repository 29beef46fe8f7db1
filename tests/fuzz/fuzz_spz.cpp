// libFuzzer target: catgs::read_spz on arbitrary bytes, with and without drop_invalid
// (fuzz_scene_reader), three times per input: the bytes as the file, the bytes gzipped into a
// file (versions 2 and 3), and the bytes as a 16-byte header and payload laid out as versions
// 2 and 3 lay it out, cut into its attribute blocks and ZSTD-compressed into a version 4 file.
// Mutations of a gzip or ZSTD stream almost only reach the decompressor's error paths;
// compressing the input lets them reach the SPZ header and attribute blocks too. The seed
// corpus holds splat-transform's .spz files (versions 3 and 4) and their payloads (*.spz.raw,
// version 2 and 3).

#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "catgs/constants.hpp"
#include "catgs/scene_io.hpp"
#include "scene_checks.hpp"

namespace {

/// gzip at the fastest level with the smallest window and state: the fuzz speed matters, not
/// the ratio (zlib's default state is ~256 KiB to allocate and clear per input).
constexpr int kFastLevel = 1, kSmallWindowBits = 9, kSmallMemLevel = 1;

std::vector<std::uint8_t> gzip(const std::uint8_t* data, std::size_t size) {
    z_stream z{};
    if (deflateInit2(&z, kFastLevel, Z_DEFLATED, 16 + kSmallWindowBits, kSmallMemLevel, Z_DEFAULT_STRATEGY) != Z_OK)
        catgs::fuzz::violation("deflateInit2 failed");
    std::vector<std::uint8_t> out(deflateBound(&z, static_cast<uLong>(size)));
    z.next_in = const_cast<Bytef*>(data);
    z.avail_in = static_cast<uInt>(size);
    z.next_out = out.data();
    z.avail_out = static_cast<uInt>(out.size());
    if (deflate(&z, Z_FINISH) != Z_STREAM_END) catgs::fuzz::violation("deflate did not finish");
    out.resize(z.total_out);
    deflateEnd(&z);
    return out;
}

/// The version 4 file of a version 2/3-style header and payload: the header's first 15 bytes
/// (version set to 4), the stream count and table of contents, and the payload cut into the
/// blocks the header's count and SH degree name (the last ones short or empty where the input
/// ends, so that the reader sees lying tables too), each ZSTD-compressed.
std::vector<std::uint8_t> version_four(const std::uint8_t* data, std::size_t size) {
    constexpr std::size_t kLegacyHeader = 16, kHeader = 32;
    if (size < kLegacyHeader) return {};
    std::uint32_t count;
    std::memcpy(&count, data + 8, 4);
    const int degree = data[12] <= catgs::kMaxShDegree ? data[12] : 0;
    const std::size_t sh = 3 * static_cast<std::size_t>((degree + 1) * (degree + 1) - 1);
    std::vector<std::size_t> strides = {9, 1, 3, 3, 4};
    if (sh > 0) strides.push_back(sh);
    // One context for every input: creating one per call would dominate the run.
    static ZSTD_CCtx* context = ZSTD_createCCtx();
    std::vector<std::vector<std::uint8_t>> streams;
    std::vector<std::uint64_t> decompressed;
    std::size_t at = kLegacyHeader;
    for (std::size_t stride : strides) {
        const std::size_t want = static_cast<std::size_t>(count) * stride;
        const std::size_t take = std::min(want, size - at);
        std::vector<std::uint8_t> out(ZSTD_compressBound(take));
        const std::size_t n = ZSTD_compressCCtx(context, out.data(), out.size(), data + at, take, 1);
        if (ZSTD_isError(n)) catgs::fuzz::violation("ZSTD_compressCCtx failed");
        out.resize(n);
        streams.push_back(std::move(out));
        decompressed.push_back(want);  // the table says what the count needs, true or not
        at += take;
    }
    std::vector<std::uint8_t> file(data, data + 15);
    file[4] = 4;
    file[5] = file[6] = file[7] = 0;
    file.push_back(static_cast<std::uint8_t>(streams.size()));
    const std::uint32_t toc = kHeader;
    const auto* toc_bytes = reinterpret_cast<const std::uint8_t*>(&toc);
    file.insert(file.end(), toc_bytes, toc_bytes + 4);
    file.resize(kHeader, 0);
    for (std::size_t k = 0; k < streams.size(); ++k) {
        const std::uint64_t sizes[2] = {streams[k].size(), decompressed[k]};
        const auto* bytes = reinterpret_cast<const std::uint8_t*>(sizes);
        file.insert(file.end(), bytes, bytes + sizeof(sizes));
    }
    for (const auto& stream : streams) file.insert(file.end(), stream.begin(), stream.end());
    return file;
}

void check(const catgs::Scene& scene) {
    catgs::fuzz::require(scene.sh_degree >= 0 && scene.sh_degree <= catgs::kMaxShDegree,
                         ".spz scene with an SH degree outside 0..3");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > catgs::fuzz::kMaxInputBytes) return -1;
    catgs::fuzz::fuzz_scene_reader(data, size, catgs::read_spz, check);
    const std::vector<std::uint8_t> zipped = gzip(data, size);
    catgs::fuzz::fuzz_scene_reader(zipped.data(), zipped.size(), catgs::read_spz, check);
    const std::vector<std::uint8_t> streams = version_four(data, size);
    if (streams.empty()) return 0;
    return catgs::fuzz::fuzz_scene_reader(streams.data(), streams.size(), catgs::read_spz, check);
}
