// The frame encoders against independent decoders: TurboJPEG decodes every stitched strip
// JPEG and must give the very pixels of the single-threaded encode; libpng decodes every PNG
// variant and must give the source image exactly. nvJPEG tests skip without a device.
#include <gtest/gtest.h>
#include <png.h>
#include <turbojpeg.h>
#include <zlib.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <random>
#include <thread>
#include <tuple>

#include "catgs/error.hpp"
#include "catgs/server/encode_methods.hpp"
#include "catgs/server/encoder.hpp"

namespace catgs::server {
namespace {

// Smooth shading, hard edges and a little noise, like a rendered frame; a fresh seed per test.
ImageRGB8 test_image(int width, int height, unsigned seed) {
    ImageRGB8 image;
    image.width = width;
    image.height = height;
    image.rgb.resize(3 * static_cast<std::size_t>(width) * height);
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> noise(-6, 6);
    const int edge_x = static_cast<int>(rng() % static_cast<unsigned>(width));
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const double fx = static_cast<double>(x) / width, fy = static_cast<double>(y) / height;
            const bool building = x > edge_x && ((x / 37 + y / 23) % 3 != 0);
            const int base[3] = {static_cast<int>(255 * fx), static_cast<int>(200 * fy),
                                 building ? 220 : static_cast<int>(128 + 100 * std::sin(9 * fx + 5 * fy))};
            for (int c = 0; c < 3; ++c)
                image.rgb[3 * (static_cast<std::size_t>(y) * width + x) + c] =
                    static_cast<std::uint8_t>(std::clamp(base[c] + noise(rng), 0, 255));
        }
    return image;
}

struct Decoded {
    ImageRGB8 image;
    int subsampling = -1;
};

Decoded decode_jpeg(const std::string& data) {
    tjhandle handle = tjInitDecompress();
    Decoded d;
    int colorspace = 0;
    const auto* bytes = reinterpret_cast<const unsigned char*>(data.data());
    EXPECT_EQ(
        tjDecompressHeader3(handle, bytes, data.size(), &d.image.width, &d.image.height, &d.subsampling, &colorspace),
        0)
        << tjGetErrorStr2(handle);
    d.image.rgb.resize(3 * static_cast<std::size_t>(d.image.width) * d.image.height);
    // TurboJPEG returns -1 on warnings too (a restart marker out of place, data past the end).
    EXPECT_EQ(
        tjDecompress2(handle, bytes, data.size(), d.image.rgb.data(), d.image.width, 0, d.image.height, TJPF_RGB, 0), 0)
        << tjGetErrorStr2(handle);
    tjDestroy(handle);
    return d;
}

ImageRGB8 decode_png(const std::string& data) {
    png_image png{};
    png.version = PNG_IMAGE_VERSION;
    ImageRGB8 out;
    if (!png_image_begin_read_from_memory(&png, data.data(), data.size())) {
        ADD_FAILURE() << png.message;
        return out;
    }
    png.format = PNG_FORMAT_RGB;
    out.width = static_cast<int>(png.width);
    out.height = static_cast<int>(png.height);
    out.rgb.resize(PNG_IMAGE_SIZE(png));
    if (!png_image_finish_read(&png, nullptr, out.rgb.data(), 0, nullptr)) ADD_FAILURE() << png.message;
    return out;
}

double psnr(const ImageRGB8& a, const ImageRGB8& b) {
    double sum = 0;
    for (std::size_t i = 0; i < a.rgb.size(); ++i) sum += std::pow(static_cast<double>(a.rgb[i]) - b.rgb[i], 2);
    const double mse = sum / static_cast<double>(a.rgb.size());
    return mse == 0 ? INFINITY : 10 * std::log10(255.0 * 255.0 / mse);
}

std::size_t count_markers(const std::string& jpeg, unsigned char lo, unsigned char hi) {
    std::size_t n = 0;
    for (std::size_t i = 0; i + 1 < jpeg.size(); ++i)
        if (static_cast<unsigned char>(jpeg[i]) == 0xFF && static_cast<unsigned char>(jpeg[i + 1]) >= lo &&
            static_cast<unsigned char>(jpeg[i + 1]) <= hi)
            ++n;
    return n;
}

// --- JPEG strips: the decoded image of every strip count equals the single-threaded one.

using StripCase = std::tuple<std::pair<int, int>, bool>;
class JpegStrips : public ::testing::TestWithParam<StripCase> {};

TEST_P(JpegStrips, DecodeToTheSinglethreadedPixels) {
    const auto [size, chroma_444] = GetParam();
    const ImageRGB8 image = test_image(size.first, size.second, 7u * size.first + size.second);
    std::string single, striped;
    encode_jpeg_turbo(image, 85, chroma_444, single);
    const Decoded reference = decode_jpeg(single);
    ASSERT_EQ(reference.image.width, image.width);
    EXPECT_EQ(reference.subsampling, chroma_444 ? TJSAMP_444 : TJSAMP_420);
    // A real encode, not a blank (a few pixels across a hard edge are beyond 4:2:0's reach).
    if (image.width >= 16 && image.height >= 16) {
        EXPECT_GT(psnr(reference.image, image), 25.0);
    }
    EncodePool pool(4);
    const int mcu_rows = (image.height + (chroma_444 ? 7 : 15)) / (chroma_444 ? 8 : 16);
    for (int strips : {2, 3, 4, 7, 16, 1000}) {
        SCOPED_TRACE("strips " + std::to_string(strips));
        encode_jpeg_strips(image, 85, chroma_444, strips, pool, striped);
        const Decoded d = decode_jpeg(striped);
        ASSERT_EQ(d.image.width, image.width);
        ASSERT_EQ(d.image.height, image.height);
        EXPECT_EQ(d.subsampling, reference.subsampling);
        EXPECT_TRUE(d.image.rgb == reference.image.rgb)
            << "PSNR to the single-threaded decode " << psnr(d.image, reference.image);
        // One SOI, one scan, and a restart marker between strips. Strips are equal (a restart
        // interval is one number) but the last: as many as equal strips of the fewest MCU rows
        // that reach `strips` need.
        const int rows_per_strip = (mcu_rows + std::min(strips, mcu_rows) - 1) / std::min(strips, mcu_rows);
        const std::size_t made = static_cast<std::size_t>((mcu_rows + rows_per_strip - 1) / rows_per_strip);
        EXPECT_EQ(count_markers(striped, 0xD8, 0xD8), 1u);
        EXPECT_EQ(count_markers(striped, 0xDA, 0xDA), 1u);
        EXPECT_EQ(count_markers(striped, 0xD0, 0xD7), made - 1);
        EXPECT_EQ(count_markers(striped, 0xDD, 0xDD), made > 1 ? 1u : 0u);
    }
}

INSTANTIATE_TEST_SUITE_P(Sizes, JpegStrips,
                         ::testing::Combine(::testing::Values(std::pair{1, 1}, std::pair{3, 5}, std::pair{17, 33},
                                                              std::pair{250, 131}, std::pair{1920, 1080}),
                                            ::testing::Bool()));

TEST(JpegStrips, FourKAtBothSubsamplings) {
    const ImageRGB8 image = test_image(3840, 2160, 4);
    EncodePool pool(3);
    for (bool chroma_444 : {false, true}) {
        std::string single, striped;
        encode_jpeg_turbo(image, 90, chroma_444, single);
        encode_jpeg_strips(image, 90, chroma_444, 5, pool, striped);
        EXPECT_TRUE(decode_jpeg(striped).image.rgb == decode_jpeg(single).image.rgb) << "444 " << chroma_444;
    }
}

// A wide 4:4:4 frame: two strips would need a restart interval past 16 bits, so the encoder
// cuts more, shorter strips.
TEST(JpegStrips, RestartIntervalStaysWithin16Bits) {
    const ImageRGB8 image = test_image(8000, 1200, 9);
    std::string single, striped;
    EncodePool pool(2);
    encode_jpeg_turbo(image, 80, true, single);
    encode_jpeg_strips(image, 80, true, 2, pool, striped);
    EXPECT_EQ(count_markers(striped, 0xD0, 0xD7), 2u);  // 150 MCU rows, at most 65 per strip
    EXPECT_TRUE(decode_jpeg(striped).image.rgb == decode_jpeg(single).image.rgb);
}

TEST(JpegStrips, StripCountFollowsThreadsAndSize) {
    EXPECT_EQ(jpeg_strip_count(1920, 1080, 1), 1);
    EXPECT_EQ(jpeg_strip_count(1920, 1080, 8), 8);
    EXPECT_EQ(jpeg_strip_count(320, 240, 16), 1);  // too small to be worth a helper
    EXPECT_EQ(jpeg_strip_count(1920, 1080, 64), 1920 * 1080 / kMinPartPixels);
}

// --- PNG: every variant decodes to the source image exactly.

class PngVariants : public ::testing::TestWithParam<std::pair<int, int>> {};

TEST_P(PngVariants, DecodeExactly) {
    // Not a structured binding: clang 14 cannot capture one in the lambda below.
    const int w = GetParam().first, h = GetParam().second;
    const ImageRGB8 image = test_image(w, h, 3u * w + h);
    EncodePool pool(3);
    std::string out;
    auto expect_exact = [&](const std::string& what) {
        const ImageRGB8 decoded = decode_png(out);
        EXPECT_EQ(decoded.width, w) << what;
        EXPECT_EQ(decoded.height, h) << what;
        EXPECT_TRUE(decoded.rgb == image.rgb) << what;
    };
    encode_png_libpng_adaptive(image, out);
    expect_exact("libpng adaptive");
    for (PngFilter f : {PngFilter::none, PngFilter::sub, PngFilter::up, PngFilter::average, PngFilter::paeth}) {
        const std::string filter = "filter " + std::to_string(static_cast<int>(f));
        encode_png_libpng(image, f, 1, Z_RLE, out);
        expect_exact("libpng " + filter);
        encode_png_spng(image, f, 1, out);
        expect_exact("spng " + filter);
        encode_png_libdeflate(image, f, 1, out);
        expect_exact("libdeflate " + filter);
        for (int chunks : {1, 2, 3, 7, 64}) {
            encode_png_parallel(image, f, 1, Z_DEFAULT_STRATEGY, chunks, pool, out);
            expect_exact("parallel " + filter + ", " + std::to_string(chunks) + " chunks");
        }
    }
    encode_png_parallel(image, PngFilter::up, 6, Z_RLE, 4, pool, out);
    expect_exact("parallel level 6, Z_RLE");
}

INSTANTIATE_TEST_SUITE_P(Sizes, PngVariants,
                         ::testing::Values(std::pair{1, 1}, std::pair{3, 5}, std::pair{17, 33}, std::pair{250, 131}));

TEST(PngParallel, FullHdInManyChunks) {
    const ImageRGB8 image = test_image(1920, 1080, 8);
    EncodePool pool(4);
    std::string out;
    encode_png_parallel(image, kPngFilter, kPngLevel, kPngStrategy, 16, pool, out);
    EXPECT_TRUE(decode_png(out).rgb == image.rgb);
}

// --- FrameEncoder: the server's entry point.

TEST(FrameEncoder, JpegAndPngMatchTheReferenceEncoders) {
    FrameEncoder encoder({JpegEncoder::turbo, 4});
    EXPECT_EQ(encoder.threads(), 4);
    EXPECT_EQ(encoder.jpeg_encoder(), JpegEncoder::turbo);
    const ImageRGB8 image = test_image(1280, 720, 11);
    for (bool chroma_444 : {false, true}) {
        std::string framed, single;
        encoder.encode(image, {Format::jpeg, 75, chroma_444}, framed);
        encode_jpeg_turbo(image, 75, chroma_444, single);
        EXPECT_TRUE(decode_jpeg(framed).image.rgb == decode_jpeg(single).image.rgb);
        EXPECT_GT(count_markers(framed, 0xD0, 0xD7), 0u);  // it did cut strips
    }
    std::string png;
    encoder.encode(image, {Format::png, 85, false}, png);
    EXPECT_TRUE(decode_png(png).rgb == image.rgb);
    FrameEncoder one_thread({JpegEncoder::turbo, 1});  // PNG through libdeflate, not in chunks
    one_thread.encode(image, {Format::png, 85, false}, png);
    EXPECT_TRUE(decode_png(png).rgb == image.rgb);
    std::string raw;
    encoder.encode(image, {Format::raw_rgb8, 85, false}, raw);
    EXPECT_EQ(raw, std::string(image.rgb.begin(), image.rgb.end()));
}

TEST(FrameEncoder, ManyCallersShareOnePool) {
    FrameEncoder encoder({JpegEncoder::turbo, 3});
    const ImageRGB8 image = test_image(640, 480, 12);
    std::string reference;
    encode_jpeg_turbo(image, 85, false, reference);
    const std::vector<std::uint8_t> expected = decode_jpeg(reference).image.rgb;
    std::atomic<int> mismatches{0};
    std::vector<std::thread> callers;
    for (int t = 0; t < 4; ++t)
        callers.emplace_back([&] {
            std::string out;
            for (int i = 0; i < 5; ++i) {
                encoder.encode(image, {Format::jpeg, 85, false}, out);
                if (decode_jpeg(out).image.rgb != expected) ++mismatches;
            }
        });
    for (auto& c : callers) c.join();
    EXPECT_EQ(mismatches.load(), 0);
}

TEST(FrameEncoder, RefusesBadImagesAndSettings) {
    FrameEncoder encoder({JpegEncoder::turbo, 2});
    ImageRGB8 image = test_image(4, 4, 1);
    image.rgb.pop_back();
    std::string out;
    try {
        encoder.encode(image, {}, out);
        ADD_FAILURE() << "a short buffer was encoded";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "encoder: image of 4x4 has 47 bytes, expected 48");
    }
    image = test_image(4, 4, 1);
    try {
        encoder.encode(image, {Format::jpeg, 101, false}, out);
        ADD_FAILURE() << "quality 101 was accepted";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "encoder: jpeg quality 101 is outside 1..100");
    }
    image.width = 0;
    image.rgb.clear();
    EXPECT_THROW(encoder.encode(image, {}, out), Error);
    try {
        FrameEncoder bad({JpegEncoder::turbo, -1});
        ADD_FAILURE() << "-1 threads were accepted";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "--encode-threads -1: expected 0 (every core) to 256");
    }
}

TEST(FrameEncoder, ParsesTheJpegEncoderFlag) {
    EXPECT_EQ(parse_jpeg_encoder("auto"), JpegEncoder::automatic);
    EXPECT_EQ(parse_jpeg_encoder("turbo"), JpegEncoder::turbo);
    EXPECT_EQ(parse_jpeg_encoder("nvjpeg"), JpegEncoder::nvjpeg);
    try {
        parse_jpeg_encoder("gpu");
        ADD_FAILURE() << "'gpu' was accepted";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "--jpeg-encoder 'gpu': expected auto, turbo or nvjpeg");
    }
}

TEST(FrameEncoder, NvjpegWhereUnusableSaysWhy) {
    const std::string why = nvjpeg_unusable_reason();
    if (why.empty()) GTEST_SKIP() << "nvJPEG is usable here: NvjpegEncode covers it";
    try {
        FrameEncoder encoder({JpegEncoder::nvjpeg, 1});
        ADD_FAILURE() << "nvjpeg was accepted";
    } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()), "--jpeg-encoder nvjpeg: " + why + " (use --jpeg-encoder turbo or auto)");
    }
    EXPECT_EQ(FrameEncoder({JpegEncoder::automatic, 1}).jpeg_encoder(), JpegEncoder::turbo);
    if (!nvjpeg_built()) {
        EXPECT_NE(why.find("without nvJPEG"), std::string::npos) << why;
    }
}

// --- nvJPEG: on the GPU host only. Its DCT and rounding differ from TurboJPEG's, so the test
// holds it to TurboJPEG's quality (PSNR to the source) within a tolerance, not to its bits.
constexpr double kNvjpegPsnrTolerance = 1.5;  // dB below TurboJPEG at the same quality
/// Both encoders can reproduce a tiny image exactly (PSNR +inf on the H200 for 1x1): compare
/// PSNRs capped here, since inf > inf - tolerance is false.
constexpr double kPsnrCap = 100.0;

TEST(NvjpegEncode, MatchesTurboQuality) {
    if (const std::string why = nvjpeg_unusable_reason(); !why.empty()) GTEST_SKIP() << why;
    for (const auto& [w, h] : {std::pair{1, 1}, std::pair{3, 5}, std::pair{17, 33}, std::pair{1920, 1080}}) {
        for (bool chroma_444 : {false, true}) {
            SCOPED_TRACE(std::to_string(w) + "x" + std::to_string(h) + (chroma_444 ? " 444" : " 420"));
            const ImageRGB8 image = test_image(w, h, 5u * w + h);
            std::string gpu, cpu;
            encode_jpeg_nvjpeg(image, 85, chroma_444, gpu);
            encode_jpeg_turbo(image, 85, chroma_444, cpu);
            const Decoded d = decode_jpeg(gpu);
            ASSERT_EQ(d.image.width, w);
            ASSERT_EQ(d.image.height, h);
            EXPECT_EQ(d.subsampling, chroma_444 ? TJSAMP_444 : TJSAMP_420);
            const double gpu_psnr = std::min(psnr(d.image, image), kPsnrCap);
            const double cpu_psnr = std::min(psnr(decode_jpeg(cpu).image, image), kPsnrCap);
            EXPECT_GE(gpu_psnr, cpu_psnr - kNvjpegPsnrTolerance);
        }
    }
}

TEST(NvjpegEncode, ThreadsEncodeAtOnce) {
    if (const std::string why = nvjpeg_unusable_reason(); !why.empty()) GTEST_SKIP() << why;
    FrameEncoder encoder({JpegEncoder::nvjpeg, 1});
    const ImageRGB8 image = test_image(1280, 720, 6);
    std::string first;
    encoder.encode(image, {}, first);
    std::atomic<int> mismatches{0};
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&] {
            std::string out;
            for (int i = 0; i < 5; ++i) {
                encoder.encode(image, {}, out);
                if (out != first) ++mismatches;  // deterministic: the same input, the same bits
            }
        });
    for (auto& t : threads) t.join();
    EXPECT_EQ(mismatches.load(), 0);
}

// --- EncodePool

TEST(EncodePool, RunsEveryPartOnceAndRethrows) {
    EncodePool pool(3);
    std::vector<std::atomic<int>> runs(50);
    pool.run(50, [&](int i) { ++runs[static_cast<std::size_t>(i)]; });
    for (const auto& r : runs) EXPECT_EQ(r.load(), 1);
    try {
        pool.run(8, [](int i) {
            if (i == 5) throw Error("part 5 failed");
        });
        ADD_FAILURE() << "no exception";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "part 5 failed");
    }
    std::atomic<int> after{0};
    pool.run(4, [&](int) { ++after; });  // still serving after a failure
    EXPECT_EQ(after.load(), 4);
}

}  // namespace
}  // namespace catgs::server
