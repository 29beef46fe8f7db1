// libFuzzer target: catgs::read_spz on arbitrary bytes, with and without drop_invalid
// (fuzz_scene_reader), twice per input: the bytes as the file, and the bytes gzipped into a
// file. Mutations of a gzip stream almost only reach the inflater's error paths; gzipping the
// input lets them reach the SPZ header and attribute blocks too. The seed corpus holds
// splat-transform's .spz files and their inflated payloads (*.spz.raw, version 2 and 3).

#include <zlib.h>

#include <cstddef>
#include <cstdint>
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

void check(const catgs::Scene& scene) {
    catgs::fuzz::require(scene.sh_degree >= 0 && scene.sh_degree <= catgs::kMaxShDegree,
                         ".spz scene with an SH degree outside 0..3");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > catgs::fuzz::kMaxInputBytes) return -1;
    catgs::fuzz::fuzz_scene_reader(data, size, catgs::read_spz, check);
    const std::vector<std::uint8_t> zipped = gzip(data, size);
    return catgs::fuzz::fuzz_scene_reader(zipped.data(), zipped.size(), catgs::read_spz, check);
}
