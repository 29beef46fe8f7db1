// SuperSplat's compressed PLY, written from the layout PlayCanvas documents and its tools
// (supersplat, splat-transform) write: Gaussians in chunks of 256 sharing one set of float
// bounds, each Gaussian four uint32 words quantised within its chunk's bounds, and optional
// uint8 SH.
//
// The header is parsed strictly: this layout is fixed (binary little-endian; elements chunk,
// vertex and optionally sh, in that order; scalar properties only), so anything else is an
// error naming the header line. The data is read in one pass over the vertices, with a second
// reader over the sh element, which the file keeps after all the vertices.

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "catgs/scene_io.hpp"
#include "scene_io_detail.hpp"

namespace catgs {

namespace {

using io::fail;

constexpr std::uint64_t kGaussiansPerChunk = 256;  ///< Gaussians sharing one chunk's bounds
/// Header lines longer than this, or more of them, are not a compressed PLY header (its
/// longest line is ~30 bytes and a degree-3 file has 79 lines).
constexpr std::size_t kMaxHeaderLineBytes = 1024;
constexpr std::size_t kMaxHeaderLines = 4096;

/// The chunk element's bounds, in the order they are kept in ChunkBounds::values.
constexpr std::array<const char*, 18> kBoundNames = {
    "min_x",       "min_y",       "min_z",       "max_x", "max_y", "max_z", "min_scale_x", "min_scale_y", "min_scale_z",
    "max_scale_x", "max_scale_y", "max_scale_z", "min_r", "min_g", "min_b", "max_r",       "max_g",       "max_b"};
constexpr int kMinPosition = 0, kMaxPosition = 3, kMinScale = 6, kMaxScale = 9, kMinColour = 12, kMaxColour = 15;
constexpr int kRequiredBounds = 12;  ///< the colour bounds are optional (older files lack them)
constexpr std::array<const char*, 4> kPackedNames = {"packed_position", "packed_rotation", "packed_scale",
                                                     "packed_color"};

/// 11, 10 and 11 bits of x, y, z (positions and log scales), most significant first.
constexpr unsigned kBits11 = 11, kBits10 = 10;
/// The three components of packed_rotation besides the largest are 10-bit values of
/// (q + sqrt(1/2)) / sqrt(2): a unit quaternion's other components lie within +-sqrt(1/2).
constexpr unsigned kRotationBits = 10;
constexpr double kRotationRange = 1.4142135623730951;  ///< sqrt(2)
/// Colour bytes are 0.5 + SH_C0 * f_dc (within the chunk's colour bounds when present).
constexpr double kShC0 = 0.28209479177387814;
/// SH bytes quantise (coefficient / 8 + 0.5) to 256 levels, sampled at bucket centres except
/// the two ends, which the writer clamps to.
constexpr double kShRange = 8.0;

constexpr io::Encoding kCompressedEncoding{
    .log_scale = true, .logit_opacity = false, .noun = "property", .nouns = "properties"};

struct Element {
    std::string name;
    std::uint64_t count = 0;
    std::vector<std::pair<std::string, io::ScalarType>> properties;
    std::size_t header_line = 0;
    std::size_t record_bytes() const {
        std::size_t bytes = 0;
        for (const auto& p : properties) bytes += io::scalar_size(p.second);
        return bytes;
    }
    std::optional<std::size_t> index_of(std::string_view property) const {
        for (std::size_t i = 0; i < properties.size(); ++i)
            if (properties[i].first == property) return i;
        return std::nullopt;
    }
};

std::optional<io::ScalarType> scalar_type(std::string_view word) {
    if (word == "float" || word == "float32") return io::ScalarType::kFloat32;
    if (word == "uint" || word == "uint32") return io::ScalarType::kUInt32;
    if (word == "uchar" || word == "uint8") return io::ScalarType::kUInt8;
    return std::nullopt;
}

std::vector<std::string_view> words_of(std::string_view line) {
    std::vector<std::string_view> words;
    std::size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && line[i] == ' ') ++i;
        std::size_t j = i;
        while (j < line.size() && line[j] != ' ') ++j;
        if (j > i) words.push_back(line.substr(i, j - i));
        i = j;
    }
    return words;
}

/// An element line's count, worded as ply_reader words it. from_chars leaves the value 0 on
/// overflow yet still moves past the digits, so its error code must be checked too, or a huge
/// count would read as none.
std::uint64_t parse_count(const std::string& path, std::string_view line, std::string_view text, std::size_t n) {
    std::uint64_t count = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), count);
    if (ec != std::errc() || end != text.data() + text.size())
        fail(path,
             "malformed element line " + io::quote(line) + ": the count " + io::quote(text) +
                 " is not a non-negative 64-bit integer",
             io::at_header_line(n));
    return count;
}

std::vector<Element> parse_header(io::FileReader& in) {
    const std::string& path = in.path();
    std::vector<Element> elements;
    std::string_view line;
    for (std::size_t n = 1;; ++n) {
        if (n > kMaxHeaderLines) fail(path, "header has no end_header within 4096 lines", io::at_header_line(n));
        const auto status = in.read_line(kMaxHeaderLineBytes, line);
        if (status == io::FileReader::LineStatus::kTooLong)
            fail(path, "header line longer than 1024 bytes", io::at_header_line(n));
        if (status == io::FileReader::LineStatus::kEnd)
            fail(path, "file ends inside the header", io::at_header_line(n));
        if (n == 1 && line != "ply")
            fail(path, "not a PLY file: the first line is " + io::quote(line), io::at_header_line(1));
        // A header cut short ends in a line without its newline: nothing follows it.
        if (in.remaining() == 0 && line != "end_header")
            fail(path, "file ends inside the header", io::at_header_line(n));
        if (n == 1) continue;
        const auto words = words_of(line);
        if (words.empty() || words[0] == "comment" || words[0] == "obj_info") continue;
        if (words[0] == "end_header") break;
        if (words[0] == "format") {
            if (words.size() != 3 || words[1] != "binary_little_endian" || words[2] != "1.0")
                fail(path, "compressed PLY must be 'format binary_little_endian 1.0', not " + io::quote(line),
                     io::at_header_line(n));
        } else if (words[0] == "element") {
            if (words.size() != 3) fail(path, "malformed element line " + io::quote(line), io::at_header_line(n));
            elements.push_back(Element{std::string(words[1]), parse_count(path, line, words[2], n), {}, n});
        } else if (words[0] == "property") {
            if (elements.empty()) fail(path, "property before any element", io::at_header_line(n));
            if (words.size() != 3)
                fail(path, "compressed PLY properties are 'property <type> <name>', not " + io::quote(line),
                     io::at_header_line(n));
            const auto type = scalar_type(words[1]);
            if (!type)
                fail(path, "property type " + io::quote(words[1]) + " is not float, uint or uchar",
                     io::at_header_line(n));
            elements.back().properties.emplace_back(std::string(words[2]), *type);
        } else {
            fail(path, "unknown header keyword " + io::quote(words[0]), io::at_header_line(n));
        }
    }
    return elements;
}

/// Where each packed word or SH byte sits in its record.
struct Layout {
    const Element* chunk = nullptr;
    const Element* vertex = nullptr;
    const Element* sh = nullptr;
    std::array<std::size_t, 18> bound_index{};
    bool colour_bounds = false;
    std::array<std::size_t, 4> packed_index{};
    std::vector<std::size_t> rest_offset;  ///< byte of f_rest_i in the sh record (all uchar)
    int sh_degree = 0;
};

const Element& require_element(const std::string& path, const std::vector<Element>& elements, std::size_t i,
                               std::string_view name) {
    if (i >= elements.size() || elements[i].name != name)
        fail(path,
             "compressed PLY needs element '" + std::string(name) + "' here, found " +
                 (i < elements.size() ? "'" + elements[i].name + "'" : std::string("no more elements")),
             i < elements.size() ? io::at_header_line(elements[i].header_line) : "header");
    return elements[i];
}

void require_type(const std::string& path, const Element& e, std::size_t property, io::ScalarType type,
                  const char* type_name) {
    if (e.properties[property].second != type)
        fail(path, "property '" + e.properties[property].first + "' of element '" + e.name + "' must be " + type_name,
             io::at_header_line(e.header_line + 1 + property));
}

Layout map_layout(const std::string& path, const std::vector<Element>& elements) {
    Layout l;
    l.chunk = &require_element(path, elements, 0, "chunk");
    l.vertex = &require_element(path, elements, 1, "vertex");
    if (elements.size() > 2) l.sh = &require_element(path, elements, 2, "sh");
    if (elements.size() > 3)
        fail(path, "unexpected element '" + elements[3].name + "' after sh",
             io::at_header_line(elements[3].header_line));
    for (std::size_t p = 0; p < l.chunk->properties.size(); ++p)
        require_type(path, *l.chunk, p, io::ScalarType::kFloat32, "float");
    for (std::size_t b = 0; b < kBoundNames.size(); ++b) {
        const auto index = l.chunk->index_of(kBoundNames[b]);
        if (!index && b < kRequiredBounds)
            fail(path, std::string("element 'chunk' lacks property '") + kBoundNames[b] + "'",
                 io::at_header_line(l.chunk->header_line));
        if (index) l.bound_index[b] = *index;
        if (b == kMinColour) l.colour_bounds = index.has_value();
        if (b > kMinColour && index.has_value() != l.colour_bounds)
            fail(path, "element 'chunk' has some colour bounds (min_r..max_b) but not all",
                 io::at_header_line(l.chunk->header_line));
    }
    for (std::size_t p = 0; p < l.vertex->properties.size(); ++p)
        require_type(path, *l.vertex, p, io::ScalarType::kUInt32, "uint");
    for (std::size_t w = 0; w < kPackedNames.size(); ++w) {
        const auto index = l.vertex->index_of(kPackedNames[w]);
        if (!index)
            fail(path, std::string("element 'vertex' lacks property '") + kPackedNames[w] + "'",
                 io::at_header_line(l.vertex->header_line));
        l.packed_index[w] = *index;
    }
    if (l.sh) {
        const std::size_t rest = l.sh->properties.size();
        int degree = 0;
        while (degree < kMaxShDegree && 3 * (sh_coefficient_count(degree) - 1) != static_cast<int>(rest)) ++degree;
        if (3 * (sh_coefficient_count(degree) - 1) != static_cast<int>(rest) || rest == 0)
            fail(path,
                 "element 'sh' has " + std::to_string(rest) + " properties; expected 9, 24 or 45 (SH degree 1..3)",
                 io::at_header_line(l.sh->header_line));
        l.sh_degree = degree;
        for (std::size_t r = 0; r < rest; ++r) {
            const std::string name = "f_rest_" + std::to_string(r);
            const auto index = l.sh->index_of(name);
            if (!index) fail(path, "element 'sh' lacks property '" + name + "'", io::at_header_line(l.sh->header_line));
            require_type(path, *l.sh, *index, io::ScalarType::kUInt8, "uchar");
            l.rest_offset.push_back(*index);
        }
    }
    return l;
}

/// Counts against each other and the file size, before anything is allocated for them.
void check_counts(const io::FileReader& in, const Layout& l) {
    const std::string& path = in.path();
    const std::uint64_t gaussians = l.vertex->count;
    if (gaussians == 0)
        fail(path, "no Gaussians: element 'vertex' has count 0", io::at_header_line(l.vertex->header_line));
    const std::uint64_t chunks_needed = (gaussians + kGaussiansPerChunk - 1) / kGaussiansPerChunk;
    if (l.chunk->count != chunks_needed)
        fail(path,
             "element 'chunk' has count " + std::to_string(l.chunk->count) + " but " + std::to_string(gaussians) +
                 " vertices need " + std::to_string(chunks_needed) + " (one per 256)",
             io::at_header_line(l.chunk->header_line));
    if (l.sh && l.sh->count != gaussians)
        fail(path,
             "element 'sh' has count " + std::to_string(l.sh->count) + " but element 'vertex' has " +
                 std::to_string(gaussians),
             io::at_header_line(l.sh->header_line));
    std::uint64_t chunk_bytes, vertex_bytes, sh_bytes = 0, need = 0;
    if (!io::checked_mul(l.chunk->count, l.chunk->record_bytes(), chunk_bytes) ||
        !io::checked_mul(gaussians, l.vertex->record_bytes(), vertex_bytes) ||
        (l.sh && !io::checked_mul(gaussians, l.sh->record_bytes(), sh_bytes)) ||
        __builtin_add_overflow(chunk_bytes, vertex_bytes, &need) || __builtin_add_overflow(need, sh_bytes, &need))
        fail(path, "element counts overflow 64-bit sizes", io::at_header_line(l.vertex->header_line));
    const std::uint64_t data = in.remaining();
    if (need > data)
        fail(path,
             "file too short for the header's counts: " + std::to_string(need) + " data bytes needed, " +
                 std::to_string(data) + " present",
             io::at_offset(in.size()));
    if (need < data)
        fail(path, std::to_string(data - need) + " bytes after the last element: the counts are too small",
             io::at_offset(in.offset() + need));
}

/// Every chunk's bounds, read up front: 4 bytes per bound per 256 Gaussians.
std::vector<float> read_bounds(io::FileReader& in, const Layout& l, bool drop_invalid) {
    const std::size_t record = l.chunk->record_bytes();
    std::vector<float> bounds(static_cast<std::size_t>(l.chunk->count) * kBoundNames.size());
    for (std::uint64_t c = 0; c < l.chunk->count; ++c) {
        if (!in.require(record)) fail(in.path(), "data ends early", "element 'chunk', " + io::at_record(c));
        for (std::size_t b = 0; b < kBoundNames.size(); ++b) {
            if (b >= kMinColour && !l.colour_bounds) continue;
            const float value = io::load_scalar<float>(in.data() + 4 * l.bound_index[b], false);
            // A non-finite bound turns every Gaussian of its chunk non-finite; dropping them is
            // SceneBuilder's job, so only the strict mode stops here, naming the chunk.
            if (!std::isfinite(value) && !drop_invalid)
                fail(in.path(), "non-finite value " + io::format_value(value),
                     "element 'chunk', " + io::at_field(c, "property", kBoundNames[b]));
            bounds[c * kBoundNames.size() + b] = value;
        }
        in.consume(record);
    }
    return bounds;
}

double unorm(std::uint32_t word, unsigned shift, unsigned bits) {
    const std::uint32_t top = (1u << bits) - 1;
    return static_cast<double>((word >> shift) & top) / top;
}

double lerp(double lo, double hi, double t) {
    return lo * (1.0 - t) + hi * t;
}

/// The 11/10/11-bit vector within [lo, hi] of each axis.
void unpack_111011(std::uint32_t word, const float* lo, const float* hi, double* out) {
    out[0] = lerp(lo[0], hi[0], unorm(word, kBits10 + kBits11, kBits11));
    out[1] = lerp(lo[1], hi[1], unorm(word, kBits11, kBits10));
    out[2] = lerp(lo[2], hi[2], unorm(word, 0, kBits11));
}

/// (w, x, y, z): the largest component's index in the top 2 bits, the other three in order.
void unpack_rotation(std::uint32_t word, double* q) {
    const unsigned largest = word >> 30;
    double norm2 = 0.0;
    unsigned shift = 2 * kRotationBits;
    for (unsigned c = 0; c < 4; ++c) {
        if (c == largest) continue;
        q[c] = (unorm(word, shift, kRotationBits) - 0.5) * kRotationRange;
        norm2 += q[c] * q[c];
        shift -= kRotationBits;
    }
    // The format's decoders clamp: three stored components beyond the unit sphere mean the
    // largest is 0, and SceneBuilder normalises what is left.
    q[largest] = std::sqrt(std::max(0.0, 1.0 - norm2));
}

double unpack_sh(std::uint8_t byte) {
    const double level = byte == 0 ? 0.0 : byte == 255 ? 1.0 : (byte + 0.5) / 256.0;
    return (level - 0.5) * kShRange;
}

std::vector<std::string> field_names(int sh_degree) {
    std::vector<std::string> names = {"packed_position", "packed_position", "packed_position", "packed_scale",
                                      "packed_scale",    "packed_scale",    "packed_color",    "packed_rotation",
                                      "packed_rotation", "packed_rotation", "packed_rotation", "packed_color",
                                      "packed_color",    "packed_color"};
    const int rest = 3 * (sh_coefficient_count(sh_degree) - 1);
    for (int k = 0; k < rest / 3; ++k)
        for (int c = 0; c < 3; ++c) names.push_back("f_rest_" + std::to_string(c * rest / 3 + k));
    return names;
}

}  // namespace

Scene read_compressed_ply(const std::string& path, const LoadOptions& options, LoadReport* report) {
    io::FileReader in(path);
    // Before any line is read: FileReader's line search needs a non-empty buffer.
    if (in.size() == 0) fail(path, "not a PLY file: the file is empty", io::at_offset(0));
    const std::vector<Element> elements = parse_header(in);
    const Layout l = map_layout(path, elements);
    check_counts(in, l);
    const std::uint64_t gaussians = l.vertex->count;
    io::check_limits(path, gaussians, l.sh_degree, options);
    const std::vector<float> bounds = read_bounds(in, l, options.drop_invalid);

    // The sh element follows every vertex: a second reader walks it alongside.
    std::optional<io::FileReader> sh_in;
    const std::size_t vertex_record = l.vertex->record_bytes();
    const std::size_t sh_record = l.sh ? l.sh->record_bytes() : 0;
    if (l.sh) {
        sh_in.emplace(path);
        sh_in->skip(in.offset() + gaussians * vertex_record);
    }
    const int rest = 3 * (sh_coefficient_count(l.sh_degree) - 1);
    io::SceneBuilder builder(path, gaussians, l.sh_degree, kCompressedEncoding, field_names(l.sh_degree), options);
    io::ProgressTicker ticker(options.progress, path);
    double v[io::kMaxFields];
    constexpr std::uint64_t kPerBlock = io::kChunkBytes / 64;
    for (std::uint64_t done = 0; done < gaussians;) {
        const std::size_t n = static_cast<std::size_t>(std::min(kPerBlock, gaussians - done));
        if (!in.require(n * vertex_record)) fail(path, "data ends early", "element 'vertex', " + io::at_record(done));
        if (sh_in && !sh_in->require(n * sh_record))
            fail(path, "data ends early", "element 'sh', " + io::at_record(done));
        for (std::size_t r = 0; r < n; ++r) {
            const std::uint64_t i = done + r;
            const float* b = bounds.data() + (i / kGaussiansPerChunk) * kBoundNames.size();
            const unsigned char* record = in.data() + r * vertex_record;
            std::uint32_t word[4];
            for (int w = 0; w < 4; ++w) word[w] = io::load_scalar<std::uint32_t>(record + 4 * l.packed_index[w], false);
            unpack_111011(word[0], b + kMinPosition, b + kMaxPosition, v + io::kFieldX);
            unpack_rotation(word[1], v + io::kFieldRot);
            unpack_111011(word[2], b + kMinScale, b + kMaxScale, v + io::kFieldScale);
            for (int c = 0; c < 3; ++c) {
                double colour = unorm(word[3], 24 - 8 * c, 8);
                if (l.colour_bounds) colour = lerp(b[kMinColour + c], b[kMaxColour + c], colour);
                v[io::kFieldSh + c] = (colour - 0.5) / kShC0;
            }
            v[io::kFieldOpacity] = unorm(word[3], 0, 8);
            if (sh_in) {
                // f_rest_* are channel-major (all red coefficients, then green, then blue).
                const unsigned char* sh = sh_in->data() + r * sh_record;
                const int per_channel = rest / 3;
                for (int k = 0; k < per_channel; ++k)
                    for (int c = 0; c < 3; ++c)
                        v[io::kFieldSh + 3 * (k + 1) + c] =
                            unpack_sh(sh[l.rest_offset[static_cast<std::size_t>(c * per_channel + k)]]);
            }
            builder.add(v, i);
        }
        in.consume(n * vertex_record);
        if (sh_in) sh_in->consume(n * sh_record);
        done += n;
        ticker.update(done, gaussians);
    }
    Scene scene = builder.finish(report);
    ticker.finish();
    return scene;
}

}  // namespace catgs
