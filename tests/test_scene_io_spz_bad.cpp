// read_spz on bad input, each with the message it must give: magic, version and header,
// truncation, corrupt gzip data (with its offset), lying counts and tables of contents,
// decompression bombs, NaN after dequantisation, and random mutations that must never escape as
// anything but catgs::Error. The files are built by spz_fixtures.hpp.

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "spz_fixtures.hpp"

namespace catgs::scene_io_test {
namespace {

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
