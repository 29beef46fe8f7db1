// read_compressed_ply: SuperSplat's compressed PLY built word by word here, decoded as the
// format defines (per-chunk bounds, 11/10/11-bit vectors, smallest-three rotations, RGBA
// bytes, uint8 SH); found by content behind a plain .ply name; and bad input with the message
// it must give.

#include <cmath>
#include <random>
#include <cstdint>
#include <string>
#include <vector>

#include "catgs/scene_format.hpp"
#include "scene_io_fixtures.hpp"

namespace catgs::scene_io_test {
namespace {

constexpr double kC0 = 0.28209479177387814;

struct PackedGaussian {
    std::uint32_t position, rotation, scale, colour;
    std::vector<std::uint8_t> sh;  ///< f_rest_0.. (channel-major)
};

struct CompressedPly {
    bool colour_bounds = true;
    int sh_rest = 9;  ///< 0 for no sh element
    std::vector<std::array<float, 18>> chunks;
    std::vector<PackedGaussian> gaussians;
    std::optional<std::string> chunk_count, vertex_count, sh_count;  ///< override the counts
    std::string format = "binary_little_endian 1.0";
    std::string position_type = "uint";
    bool with_rotation = true;
    std::string trailing;

    std::string bytes() const {
        static const char* bounds[] = {"min_x",       "min_y",       "min_z",       "max_x",       "max_y",
                                       "max_z",       "min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x",
                                       "max_scale_y", "max_scale_z", "min_r",       "min_g",       "min_b",
                                       "max_r",       "max_g",       "max_b"};
        const int bound_count = colour_bounds ? 18 : 12;
        std::string h = "ply\nformat " + format + "\ncomment made by a test\n";
        h += "element chunk " + chunk_count.value_or(std::to_string(chunks.size())) + "\n";
        for (int b = 0; b < bound_count; ++b) h += std::string("property float ") + bounds[b] + "\n";
        h += "element vertex " + vertex_count.value_or(std::to_string(gaussians.size())) + "\n";
        h += "property " + position_type + " packed_position\n";
        if (with_rotation) h += "property uint packed_rotation\n";
        h += "property uint packed_scale\nproperty uint packed_color\n";
        if (sh_rest > 0) {
            h += "element sh " + sh_count.value_or(std::to_string(gaussians.size())) + "\n";
            for (int r = 0; r < sh_rest; ++r) h += "property uchar f_rest_" + std::to_string(r) + "\n";
        }
        h += "end_header\n";
        for (const auto& c : chunks)
            for (int b = 0; b < bound_count; ++b) put(h, c[static_cast<std::size_t>(b)], false);
        for (const auto& g : gaussians) {
            if (position_type == "float") {
                put(h, static_cast<float>(g.position), false);
            } else {
                put(h, g.position, false);
            }
            if (with_rotation) put(h, g.rotation, false);
            put(h, g.scale, false);
            put(h, g.colour, false);
        }
        if (sh_rest > 0)
            for (const auto& g : gaussians)
                for (int r = 0; r < sh_rest; ++r) h += static_cast<char>(g.sh[static_cast<std::size_t>(r)]);
        return h + trailing;
    }
};

std::uint32_t pack_111011(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
    return (x << 21) | (y << 11) | z;
}

std::array<float, 18> chunk_bounds(float offset) {
    return {-2.0f + offset, 1.0f,  3.0f,  6.0f + offset, 5.0f, 11.0f, -6.0f, -5.0f, -4.0f,
            -1.0f,          -2.0f, -0.5f, 0.1f,          0.2f, 0.3f,  0.9f,  0.8f,  0.7f};
}

/// n Gaussians (one chunk per 256), SH degree 1, each with distinct packed words.
CompressedPly sample(std::size_t n) {
    CompressedPly f;
    for (std::size_t c = 0; c < (n + 255) / 256; ++c) f.chunks.push_back(chunk_bounds(10.0f * c));
    for (std::size_t i = 0; i < n; ++i) {
        const auto k = static_cast<std::uint32_t>(i);
        PackedGaussian g{pack_111011(2047 - k % 2048, (3 * k) % 1024, (511 + k) % 2048),
                         // largest = x (1); w, y, z stored as 10-bit values around the middle
                         (1u << 30) | ((512u + k % 100) << 20) | ((400u + k % 50) << 10) | (600u - k % 70),
                         pack_111011(k % 2048, 1023 - k % 1024, 1024),
                         (((50 + k) % 256) << 24) | (200u << 16) | (((7 * k) % 256) << 8) | (128 + k % 128),
                         {}};
        for (int r = 0; r < 9; ++r) g.sh.push_back(static_cast<std::uint8_t>((k * 31 + r * 17) % 256));
        f.gaussians.push_back(g);
    }
    return f;
}

double unorm(std::uint32_t v, unsigned bits) {
    return static_cast<double>(v & ((1u << bits) - 1)) / ((1u << bits) - 1);
}
double lerp(double a, double b, double t) {
    return a * (1 - t) + b * t;
}

std::string write_cply(const std::string& name, const CompressedPly& f) {
    const std::string path = tmp_path(name);
    write_file(path, f.bytes());
    return path;
}

TEST(SceneIoCompressedPly, DecodesEveryWordWithinItsChunksBounds) {
    for (bool colour_bounds : {true, false}) {
        SCOPED_TRACE(colour_bounds ? "colour bounds" : "no colour bounds");
        CompressedPly f = sample(300);  // two chunks: Gaussians 256.. use the second's bounds
        f.colour_bounds = colour_bounds;
        const Scene s = read_compressed_ply(write_cply("decode.compressed.ply", f), absolute());
        ASSERT_EQ(s.count(), 300u);
        EXPECT_EQ(s.sh_degree, 1);
        for (std::size_t i : {std::size_t{0}, std::size_t{17}, std::size_t{255}, std::size_t{256}, std::size_t{299}}) {
            const PackedGaussian& g = f.gaussians[i];
            const auto& b = f.chunks[i / 256];
            const std::uint32_t p = g.position;
            EXPECT_FLOAT_EQ(s.positions[3 * i], static_cast<float>(lerp(b[0], b[3], unorm(p >> 21, 11)))) << i;
            EXPECT_FLOAT_EQ(s.positions[3 * i + 1], static_cast<float>(lerp(b[1], b[4], unorm(p >> 11, 10)))) << i;
            EXPECT_FLOAT_EQ(s.positions[3 * i + 2], static_cast<float>(lerp(b[2], b[5], unorm(p, 11)))) << i;
            EXPECT_FLOAT_EQ(s.scales[3 * i], static_cast<float>(std::exp(lerp(b[6], b[9], unorm(g.scale >> 21, 11)))));
            EXPECT_FLOAT_EQ(s.scales[3 * i + 2], static_cast<float>(std::exp(lerp(b[8], b[11], unorm(g.scale, 11)))));
            EXPECT_FLOAT_EQ(s.opacities[i], static_cast<float>(unorm(g.colour, 8)));
            double r = unorm(g.colour >> 24, 8);
            if (colour_bounds) r = lerp(b[12], b[15], r);
            EXPECT_NEAR(s.sh[12 * i], (r - 0.5) / kC0, 1e-5);
            // f_rest_0 is red's first coefficient, f_rest_3 green's, f_rest_6 blue's.
            for (int c = 0; c < 3; ++c) {
                const std::uint8_t byte = g.sh[static_cast<std::size_t>(3 * c)];
                const double level = byte == 0 ? 0.0 : byte == 255 ? 1.0 : (byte + 0.5) / 256;
                EXPECT_NEAR(s.sh[12 * i + 3 + c], (level - 0.5) * 8, 1e-6) << i << " channel " << c;
            }
            // Rotation: w, y, z stored, x the largest (index 1).
            const std::uint32_t q = g.rotation;
            const double w = (unorm(q >> 20, 10) - 0.5) * std::sqrt(2.0),
                         y = (unorm(q >> 10, 10) - 0.5) * std::sqrt(2.0), z = (unorm(q, 10) - 0.5) * std::sqrt(2.0);
            const double x = std::sqrt(std::max(0.0, 1 - w * w - y * y - z * z));
            const double want[4] = {w, x, y, z};
            for (int c = 0; c < 4; ++c) EXPECT_NEAR(s.rotations[4 * i + c], want[c], 1e-6) << i << " component " << c;
        }
    }
}

TEST(SceneIoCompressedPly, OptionalShAndDetectionBehindAPlainPlyName) {
    CompressedPly f = sample(5);
    f.sh_rest = 0;
    const std::string path = tmp_path("capture.ply");
    write_file(path, f.bytes());
    EXPECT_EQ(detect_scene_format(path), SceneFormat::compressed_ply);
    LoadOptions options = absolute();
    options.chunks = false;
    const Scene s = load_scene(path, options);
    EXPECT_EQ(s.count(), 5u);
    EXPECT_EQ(s.sh_degree, 0);
    EXPECT_FLOAT_EQ(s.positions[0], 6.0f);  // x = 2047: the chunk's max_x
}

TEST(SceneIoCompressedPlyBad, HeaderLayout) {
    struct Case {
        std::string name;
        std::function<void(CompressedPly&)> spoil;
        std::vector<std::string> parts;
    };
    const std::vector<Case> cases = {
        {"ascii",
         [](CompressedPly& f) { f.format = "ascii 1.0"; },
         {"must be 'format binary_little_endian 1.0'", "header line 2"}},
        {"float_position",
         [](CompressedPly& f) { f.position_type = "float"; },
         {"property 'packed_position' of element 'vertex' must be uint", "header line"}},
        {"no_rotation",
         [](CompressedPly& f) { f.with_rotation = false; },
         {"element 'vertex' lacks property 'packed_rotation'"}},
        {"sh10",
         [](CompressedPly& f) {
             f.sh_rest = 10;
             for (auto& g : f.gaussians) g.sh.push_back(1);
         },
         {"element 'sh' has 10 properties; expected 9, 24 or 45"}},
        {"chunk_count",
         [](CompressedPly& f) { f.chunk_count = "2"; },
         {"element 'chunk' has count 2 but 5 vertices need 1 (one per 256)", "header line 4"}},
        {"sh_count",
         [](CompressedPly& f) { f.sh_count = "4"; },
         {"element 'sh' has count 4 but element 'vertex' has 5"}},
        {"vertex_zero", [](CompressedPly& f) { f.vertex_count = "0"; }, {"no Gaussians: element 'vertex' has count 0"}},
        {"vertex_huge",
         [](CompressedPly& f) {
             f.vertex_count = "5000000000";
             f.chunk_count = "19531250";
             f.sh_count = "5000000000";
         },
         {"file too short for the header's counts"}},
        // from_chars leaves 0 on overflow: the count must not read as "no Gaussians".
        {"vertex_overflow",
         [](CompressedPly& f) { f.vertex_count = "99999999999999999999"; },
         {"malformed element line 'element vertex 99999999999999999999': the count '99999999999999999999' is not "
          "a non-negative 64-bit integer",
          "header line 23"}},
        {"vertex_not_a_number",
         [](CompressedPly& f) { f.vertex_count = "5x"; },
         {"malformed element line 'element vertex 5x': the count '5x' is not a non-negative 64-bit integer"}},
        // Each element's size fits 64 bits, their sum does not.
        {"sizes_overflow",
         [](CompressedPly& f) {
             f.vertex_count = "750000000000000000";
             f.chunk_count = "2929687500000000";
             f.sh_count = "750000000000000000";
         },
         {"element counts overflow 64-bit sizes"}},
        {"trailing",
         [](CompressedPly& f) { f.trailing = "xyz"; },
         {"3 bytes after the last element: the counts are too small"}},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        CompressedPly f = sample(5);
        c.spoil(f);
        const std::string path = write_cply(c.name + ".compressed.ply", f);
        expect_error([&] { read_compressed_ply(path); }, path, c.parts);
    }
    const std::string not_ply = tmp_path("not_ply.compressed.ply");
    write_file(not_ply, "PLY\n");
    expect_error([&] { read_compressed_ply(not_ply); }, not_ply, {"not a PLY file", "header line 1"});
}

TEST(SceneIoCompressedPlyBad, TruncatedFiles) {
    const std::string whole = sample(300).bytes();
    for (std::size_t keep : {whole.size() - 1, whole.size() / 2, std::size_t{40}}) {
        const std::string path = tmp_path("cut" + std::to_string(keep) + ".compressed.ply");
        write_file(path, whole.substr(0, keep));
        const std::string message = error_of([&] { read_compressed_ply(path); });
        EXPECT_THAT(message, ::testing::StartsWith(path + ": "));
        EXPECT_THAT(message, ::testing::AnyOf(HasSubstr("file too short for the header's counts"),
                                              HasSubstr("file ends inside the header")));
    }
}

TEST(SceneIoCompressedPlyBad, NonFiniteBoundsAndLimits) {
    CompressedPly f = sample(300);
    f.chunks[1][4] = std::numeric_limits<float>::quiet_NaN();  // chunk 1's max_y
    const std::string path = write_cply("nan.compressed.ply", f);
    expect_error([&] { read_compressed_ply(path); }, path,
                 {"non-finite value nan", "element 'chunk', record 1, property 'max_y'"});
    // Dropping: every Gaussian of chunk 1 decodes to a NaN y and is dropped, chunk 0's stay.
    LoadReport report;
    const Scene s = read_compressed_ply(path, dropping(), &report);
    EXPECT_EQ(s.count(), 256u);
    EXPECT_EQ(report.dropped_invalid, 44u);

    f.chunks[1][4] = 5.0f;
    f.chunks[0][9] = 3000.0f;  // max_scale_x: exp overflows float after dequantisation
    const std::string overflow = write_cply("overflow.compressed.ply", f);
    expect_error([&] { read_compressed_ply(overflow); }, overflow,
                 {"overflows float after exp", "property 'packed_scale'"});

    LoadOptions capped;
    capped.max_records = 100;
    const std::string ok = write_cply("capped.compressed.ply", sample(300));
    expect_error([&] { read_compressed_ply(ok, capped); }, ok,
                 {"300 records exceed the limit of 100", "LoadOptions::max_records"});
}

/// Every truncation of a small file and random byte flips end in a scene or a catgs::Error
/// naming the file.
TEST(SceneIoCompressedPlyBad, TruncationsAndMutationsNeverEscape) {
    const std::string whole = sample(3).bytes();
    const std::string path = tmp_path("mutated.compressed.ply");
    auto survives = [&](const std::string& bytes) {
        write_file(path, bytes);
        for (const LoadOptions& options : {absolute(), dropping()}) {
            try {
                const Scene s = read_compressed_ply(path, options);
                EXPECT_NO_THROW(s.check_consistent(path));
            } catch (const Error& e) {
                EXPECT_THAT(std::string(e.what()), ::testing::StartsWith(path + ": "));
            }
        }
    };
    for (std::size_t keep = 0; keep < whole.size(); ++keep) survives(whole.substr(0, keep));
    std::mt19937_64 rng(test::fresh_seed("compressed PLY mutations"));
    for (int trial = 0; trial < 300; ++trial) {
        std::string mutated = whole;
        for (int flips = 0; flips < 3; ++flips) mutated[rng() % mutated.size()] = static_cast<char>(rng());
        survives(mutated);
    }
}

}  // namespace
}  // namespace catgs::scene_io_test
