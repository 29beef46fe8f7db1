// TurboJPEG, whole or in restart-interval strips. A strip encoded on its own is a complete
// JPEG whose scan starts with zero DC predictors and ends padded to a byte: exactly the state
// a decoder is in after an RSTn marker. So the strips' scans, joined by RST markers under the
// first strip's headers (frame height patched, DRI added), are one baseline JPEG whose
// coefficients, and so decoded pixels, equal the single-threaded encode's (chroma is averaged
// inside each MCU, which no strip boundary cuts).
#include <turbojpeg.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "catgs/error.hpp"
#include "encode_buffer.hpp"
#include "catgs/server/encode_methods.hpp"

namespace catgs::server {
namespace {

// JPEG markers (ITU T.81 table B.1).
constexpr std::uint8_t kMarkerSof0 = 0xC0, kMarkerDht = 0xC4, kMarkerRst0 = 0xD0, kMarkerSoi = 0xD8, kMarkerEoi = 0xD9,
                       kMarkerSos = 0xDA, kMarkerDqt = 0xDB, kMarkerDri = 0xDD;
// Restart intervals count MCUs in 16 bits.
constexpr long kMaxRestartInterval = 0xFFFF;
// The frame height in SOF0 is 16 bits.
constexpr int kMaxJpegSide = 0xFFFF;

/// One TurboJPEG compressor per thread: creating a handle per frame costs more than encoding
/// a small frame, and a handle must not be used by two threads at once.
class JpegHandle {
public:
    JpegHandle() : handle_(tjInitCompress()) {}
    ~JpegHandle() {
        if (handle_) tjDestroy(handle_);
    }
    JpegHandle(const JpegHandle&) = delete;
    JpegHandle& operator=(const JpegHandle&) = delete;
    tjhandle get() const { return handle_; }

private:
    tjhandle handle_;
};

// An MCU is one 8x8 block of each component at 4:4:4, 16x16 luma pixels at 4:2:0.
int mcu_side(bool chroma_444) {
    return chroma_444 ? 8 : 16;
}

// Rows [y0, y0 + rows) of `image` into `buffer`; returns the size.
std::size_t compress_rows(const ImageRGB8& image, int y0, int rows, int quality, bool chroma_444,
                          ScratchBuffer& buffer) {
    thread_local JpegHandle handle;
    if (!handle.get()) throw Error("jpeg encoder: tjInitCompress failed");
    const int subsampling = chroma_444 ? TJSAMP_444 : TJSAMP_420;
    // Pre-sized to TurboJPEG's worst case so that it never reallocates (TJFLAG_NOREALLOC).
    const unsigned long capacity = tjBufSize(image.width, rows, subsampling);
    if (capacity == static_cast<unsigned long>(-1))
        throw Error(std::string("jpeg encoder: ") + tjGetErrorStr2(nullptr));
    unsigned char* data = buffer.reserve(capacity);
    unsigned long size = capacity;
    const unsigned char* first = image.rgb.data() + 3 * static_cast<std::size_t>(image.width) * y0;
    if (tjCompress2(handle.get(), first, image.width, 0, rows, TJPF_RGB, &data, &size, subsampling, quality,
                    TJFLAG_NOREALLOC) != 0)
        throw Error(std::string("jpeg encoder: ") + tjGetErrorStr2(handle.get()));
    return size;
}

// Where a strip's parts are: [0, sos) the headers before SOS, [sos, scan) the SOS segment,
// [scan, size - 2) the entropy-coded data, then EOI.
struct StripLayout {
    std::size_t sof_height = 0;  // offset of SOF0's 16-bit height
    std::size_t sos = 0, scan = 0, end = 0;
    bool has_restarts = false;  // a DRI already (TJ_RESTART in the environment)
};

StripLayout parse_strip(const unsigned char* data, std::size_t size) {
    auto fail = [](const char* what) { throw Error(std::string("jpeg encoder: TurboJPEG strip output: ") + what); };
    if (size < 4 || data[0] != 0xFF || data[1] != kMarkerSoi) fail("no SOI");
    if (data[size - 2] != 0xFF || data[size - 1] != kMarkerEoi) fail("no EOI at the end");
    StripLayout layout;
    std::size_t at = 2;
    for (;;) {
        if (at + 4 > size || data[at] != 0xFF) fail("a marker segment runs past the data");
        const std::uint8_t marker = data[at + 1];
        const std::size_t length = (static_cast<std::size_t>(data[at + 2]) << 8) | data[at + 3];
        if (length < 2 || at + 2 + length > size) fail("a marker segment's length is out of range");
        if (marker == kMarkerSof0) {
            if (length < 8) fail("SOF0 too short");
            layout.sof_height = at + 5;
        } else if (marker == kMarkerDri) {
            layout.has_restarts = true;
        } else if (marker == kMarkerSos) {
            layout.sos = at;
            layout.scan = at + 2 + length;
            layout.end = size - 2;
            break;
        } else if (marker != kMarkerDqt && marker != kMarkerDht && (marker < 0xE0 || marker > 0xEF)) {
            // Only baseline segments are expected: anything else (progressive, arithmetic)
            // would not stitch.
            layout.has_restarts = true;
        }
        at += 2 + length;
    }
    if (layout.sof_height == 0) fail("no baseline SOF0 before SOS");
    return layout;
}

// The headers of a strip with its height masked: every strip must carry the same tables.
bool same_tables(const unsigned char* a, const StripLayout& la, const unsigned char* b, const StripLayout& lb) {
    if (la.scan != lb.scan || la.sof_height != lb.sof_height) return false;
    const std::size_t h = la.sof_height;
    return std::memcmp(a, b, h) == 0 && std::memcmp(a + h + 2, b + h + 2, la.scan - h - 2) == 0;
}

struct StripPlan {
    int strips = 1;
    int rows_per_strip = 0;  // pixel rows, a multiple of the MCU height
    long restart_interval = 0;
};

StripPlan plan_strips(int width, int height, bool chroma_444, int wanted) {
    const int mcu_rows = (height + mcu_side(chroma_444) - 1) / mcu_side(chroma_444);
    const long mcus_per_row = (width + mcu_side(chroma_444) - 1) / mcu_side(chroma_444);
    StripPlan plan;
    plan.rows_per_strip = height;
    if (wanted <= 1 || mcu_rows < 2 || mcus_per_row > kMaxRestartInterval || height > kMaxJpegSide) return plan;
    int mcu_rows_per_strip = (mcu_rows + std::min(wanted, mcu_rows) - 1) / std::min(wanted, mcu_rows);
    mcu_rows_per_strip = std::min<long>(mcu_rows_per_strip, kMaxRestartInterval / mcus_per_row);
    plan.strips = (mcu_rows + mcu_rows_per_strip - 1) / mcu_rows_per_strip;
    plan.rows_per_strip = mcu_rows_per_strip * mcu_side(chroma_444);
    plan.restart_interval = mcus_per_row * mcu_rows_per_strip;
    return plan;
}

void put_u16(std::string& out, std::size_t at, unsigned value) {
    out[at] = static_cast<char>(value >> 8);
    out[at + 1] = static_cast<char>(value & 0xFF);
}

// Joins the scans of strips [0, sizes.size()) under strip 0's headers; false when their
// tables differ.
bool stitch(const std::vector<ScratchBuffer>& strips, const std::vector<std::size_t>& sizes, int height,
            long restart_interval, std::string& out) {
    std::vector<StripLayout> layouts;
    layouts.reserve(sizes.size());
    std::size_t total = 0;
    for (std::size_t i = 0; i < sizes.size(); ++i) {
        layouts.push_back(parse_strip(strips[i].data(), sizes[i]));
        if (layouts[i].has_restarts || !same_tables(strips[0].data(), layouts[0], strips[i].data(), layouts[i]))
            return false;
        total += layouts[i].end - layouts[i].scan + 2;
    }
    const StripLayout& first = layouts[0];
    const char* head = reinterpret_cast<const char*>(strips[0].data());
    out.clear();
    out.reserve(first.scan + 6 + total);
    out.append(head, first.sos);
    put_u16(out, first.sof_height, static_cast<unsigned>(height));
    const char dri[6] = {'\xFF', static_cast<char>(kMarkerDri), 0, 4, 0, 0};
    out.append(dri, sizeof dri);
    put_u16(out, out.size() - 2, static_cast<unsigned>(restart_interval));
    out.append(head + first.sos, first.scan - first.sos);
    for (std::size_t i = 0; i < sizes.size(); ++i) {
        if (i > 0) {
            out.push_back('\xFF');
            out.push_back(static_cast<char>(kMarkerRst0 + (i - 1) % 8));
        }
        const char* data = reinterpret_cast<const char*>(strips[i].data());
        out.append(data + layouts[i].scan, layouts[i].end - layouts[i].scan);
    }
    out.push_back('\xFF');
    out.push_back(static_cast<char>(kMarkerEoi));
    return true;
}

}  // namespace

void encode_jpeg_turbo(const ImageRGB8& image, int quality, bool chroma_444, std::string& out) {
    thread_local ScratchBuffer buffer;
    const std::size_t size = compress_rows(image, 0, image.height, quality, chroma_444, buffer);
    out.assign(reinterpret_cast<const char*>(buffer.data()), size);
}

int jpeg_strip_count(int width, int height, int threads) {
    const long pixels = static_cast<long>(width) * height;
    return static_cast<int>(std::clamp<long>(pixels / kMinPartPixels, 1, std::max(threads, 1)));
}

void encode_jpeg_strips(const ImageRGB8& image, int quality, bool chroma_444, int strips, EncodePool& pool,
                        std::string& out) {
    const StripPlan plan = plan_strips(image.width, image.height, chroma_444, strips);
    if (plan.strips <= 1) return encode_jpeg_turbo(image, quality, chroma_444, out);
    // The caller's own buffers, reused frame after frame: helpers write into them, and they
    // outlive every strip because run() returns only when all are done.
    // (Named by reference here: inside the lambda, a thread_local's name would mean the
    // helper's own.)
    thread_local std::vector<ScratchBuffer> caller_buffers;
    thread_local std::vector<std::size_t> caller_sizes;
    auto& buffers = caller_buffers;
    auto& sizes = caller_sizes;
    if (buffers.size() < static_cast<std::size_t>(plan.strips)) buffers.resize(static_cast<std::size_t>(plan.strips));
    sizes.assign(static_cast<std::size_t>(plan.strips), 0);
    pool.run(plan.strips, [&](int strip) {
        const int y0 = strip * plan.rows_per_strip;
        const int rows = std::min(plan.rows_per_strip, image.height - y0);
        sizes[static_cast<std::size_t>(strip)] =
            compress_rows(image, y0, rows, quality, chroma_444, buffers[static_cast<std::size_t>(strip)]);
    });
    if (!stitch(buffers, sizes, image.height, plan.restart_interval, out))
        encode_jpeg_turbo(image, quality, chroma_444, out);  // tables differ (TJ_OPTIMIZE set): one strip
}

}  // namespace catgs::server
