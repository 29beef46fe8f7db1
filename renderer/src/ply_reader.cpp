// graphdeco 3DGS PLY reader: binary little/big endian and ASCII, properties by name.

#include <algorithm>
#include <charconv>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "catgs/scene_io.hpp"
#include "scene_io_detail.hpp"

namespace catgs {

namespace {

using io::fail;

/// The header is read with a hard cap so that a file without end_header (or a hostile one)
/// costs bounded time and memory; real 3DGS headers are a few kilobytes.
constexpr std::size_t kMaxHeaderBytes = std::size_t{1} << 20;
/// Far beyond any real header line (the longest are comments holding a path).
constexpr std::size_t kMaxHeaderLineBytes = 8192;
/// One ASCII record holds at most a few thousand values of < 30 characters; the cap bounds
/// the line buffer.
constexpr std::size_t kMaxAsciiLineBytes = std::size_t{1} << 20;
/// An ASCII value takes at least one character plus one separator (space or newline), which
/// gives a lower bound on the bytes a declared record count needs, checked before allocating.
constexpr std::uint64_t kMinAsciiBytesPerValue = 2;
/// ASCII records between progress reports: the per-line work is small, so a report per line
/// would cost more than the parsing.
constexpr std::uint64_t kAsciiProgressRecords = 1 << 16;

constexpr io::Encoding kPlyEncoding{
    .log_scale = true, .logit_opacity = true, .noun = "property", .nouns = "properties"};

/// The number of f_rest_* properties for SH degrees 0..3: 3 * ((deg + 1)^2 - 1).
constexpr int kRestCounts[] = {0, 9, 24, 45};

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

struct PlyProperty {
    std::string name;
    io::ScalarType type = io::ScalarType::kFloat32;  ///< the item type for a list
    bool is_list = false;
    io::ScalarType count_type = io::ScalarType::kUInt8;
};

/// How much of an ASCII file's tail is checked at a time for anything but whitespace.
constexpr std::size_t kAsciiScanBytes = std::size_t{1} << 16;

struct PlyElement {
    std::string name;
    std::uint64_t count = 0;
    std::size_t line = 0;
    std::vector<PlyProperty> properties;

    bool has_list() const {
        return std::any_of(properties.begin(), properties.end(), [](const PlyProperty& p) { return p.is_list; });
    }
    /// Bytes per record when every property is a scalar.
    std::uint64_t stride() const {
        std::uint64_t bytes = 0;
        for (const auto& p : properties) bytes += io::scalar_size(p.type);
        return bytes;
    }
};

struct PlyHeader {
    PlyFormat format = PlyFormat::kAscii;
    std::vector<PlyElement> elements;
    std::size_t vertex = 0;  ///< index of the vertex element
};

std::vector<std::string_view> split_words(std::string_view line) {
    std::vector<std::string_view> words;
    std::size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
        std::size_t start = i;
        while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
        if (i > start) words.push_back(line.substr(start, i - start));
    }
    return words;
}

std::optional<io::ScalarType> parse_scalar_type(std::string_view word) {
    using T = io::ScalarType;
    static const std::unordered_map<std::string_view, T> kTypes = {
        {"char", T::kInt8},     {"int8", T::kInt8},       {"uchar", T::kUInt8},    {"uint8", T::kUInt8},
        {"short", T::kInt16},   {"int16", T::kInt16},     {"ushort", T::kUInt16},  {"uint16", T::kUInt16},
        {"int", T::kInt32},     {"int32", T::kInt32},     {"uint", T::kUInt32},    {"uint32", T::kUInt32},
        {"float", T::kFloat32}, {"float32", T::kFloat32}, {"double", T::kFloat64}, {"float64", T::kFloat64},
    };
    auto it = kTypes.find(word);
    if (it == kTypes.end()) return std::nullopt;
    return it->second;
}

std::optional<std::uint64_t> parse_count(std::string_view word) {
    std::uint64_t value = 0;
    auto result = std::from_chars(word.data(), word.data() + word.size(), value);
    if (result.ec != std::errc() || result.ptr != word.data() + word.size()) return std::nullopt;
    return value;
}

// ---------------------------------------------------------------------------------------
// Header.

class HeaderParser {
public:
    explicit HeaderParser(io::FileReader& in) : in_(in), path_(in.path()) {}

    PlyHeader parse() {
        check_magic();
        std::string_view line;
        for (;;) {
            auto status = in_.read_line(kMaxHeaderLineBytes, line);
            ++line_;
            if (in_.offset() > kMaxHeaderBytes)
                fail(path_, "no end_header within the first " + std::to_string(kMaxHeaderBytes) + " bytes",
                     io::at_offset(kMaxHeaderBytes));
            if (status == io::FileReader::LineStatus::kEnd)
                fail(path_, "header ends without end_header", io::at_offset(in_.offset()));
            if (status == io::FileReader::LineStatus::kTooLong)
                fail(path_, "header line longer than " + std::to_string(kMaxHeaderLineBytes) + " bytes",
                     io::at_header_line(line_));
            if (line_ == 1) continue;  // "ply", checked by check_magic
            if (parse_line(line)) break;
        }
        return finish();
    }

private:
    void check_magic() {
        bool ok = in_.require(4) && std::memcmp(in_.data(), "ply", 3) == 0 &&
                  (in_.data()[3] == '\n' || (in_.data()[3] == '\r' && in_.require(5) && in_.data()[4] == '\n'));
        if (!ok) fail(path_, "not a PLY file: it does not start with the line 'ply'", io::at_offset(0));
    }

    [[noreturn]] void malformed(std::string_view line, std::string_view expected) const {
        fail(path_, "malformed header line " + io::quote(line) + ": expected '" + std::string(expected) + "'",
             io::at_header_line(line_));
    }

    /// Returns true at end_header.
    bool parse_line(std::string_view line) {
        auto words = split_words(line);
        if (words.empty()) return false;
        std::string_view keyword = words[0];
        if (keyword == "end_header") {
            if (words.size() != 1) malformed(line, "end_header");
            return true;
        }
        if (keyword == "comment" || keyword == "obj_info") return false;
        if (keyword == "format") {
            parse_format(line, words);
        } else if (keyword == "element") {
            parse_element(line, words);
        } else if (keyword == "property") {
            parse_property(line, words);
        } else {
            fail(path_, "unknown header keyword " + io::quote(keyword), io::at_header_line(line_));
        }
        return false;
    }

    void parse_format(std::string_view line, const std::vector<std::string_view>& words) {
        if (have_format_) fail(path_, "second format line", io::at_header_line(line_));
        if (words.size() != 3 || words[2] != "1.0")
            fail(path_,
                 "unknown format " + io::quote(line) +
                     ": expected 'format ascii|binary_little_endian|binary_big_endian 1.0'",
                 io::at_header_line(line_));
        if (words[1] == "ascii") {
            header_.format = PlyFormat::kAscii;
        } else if (words[1] == "binary_little_endian") {
            header_.format = PlyFormat::kBinaryLittleEndian;
        } else if (words[1] == "binary_big_endian") {
            header_.format = PlyFormat::kBinaryBigEndian;
        } else {
            fail(
                path_,
                "unknown format " + io::quote(words[1]) + ": expected ascii, binary_little_endian or binary_big_endian",
                io::at_header_line(line_));
        }
        have_format_ = true;
    }

    void parse_element(std::string_view line, const std::vector<std::string_view>& words) {
        if (words.size() != 3) malformed(line, "element <name> <count>");
        auto count = parse_count(words[2]);
        if (!count)
            fail(path_,
                 "malformed element line " + io::quote(line) + ": the count " + io::quote(words[2]) +
                     " is not a non-negative 64-bit integer",
                 io::at_header_line(line_));
        PlyElement element;
        element.name = std::string(words[1]);
        element.count = *count;
        element.line = line_;
        if (element.name == "vertex") {
            if (have_vertex_) fail(path_, "second vertex element", io::at_header_line(line_));
            have_vertex_ = true;
            header_.vertex = header_.elements.size();
        }
        header_.elements.push_back(std::move(element));
    }

    io::ScalarType scalar_type(std::string_view word, std::string_view property) const {
        auto type = parse_scalar_type(word);
        if (!type)
            fail(path_, "unknown property type " + io::quote(word) + " of property " + io::quote(property),
                 io::at_header_line(line_));
        return *type;
    }

    void parse_property(std::string_view line, const std::vector<std::string_view>& words) {
        if (header_.elements.empty()) fail(path_, "property line before any element", io::at_header_line(line_));
        PlyElement& element = header_.elements.back();
        PlyProperty property;
        if (words.size() >= 2 && words[1] == "list") {
            if (words.size() != 5) malformed(line, "property list <count type> <item type> <name>");
            property.name = std::string(words[4]);
            if (element.name == "vertex")
                fail(path_, "list property " + io::quote(property.name) + " in the vertex element is not supported",
                     io::at_header_line(line_));
            property.is_list = true;
            property.count_type = scalar_type(words[2], property.name);
            property.type = scalar_type(words[3], property.name);
            if (!io::is_integer(property.count_type))
                fail(path_,
                     "list count type " + io::quote(words[2]) + " of property " + io::quote(property.name) +
                         " is not an integer type",
                     io::at_header_line(line_));
        } else {
            if (words.size() != 3) malformed(line, "property <type> <name>");
            property.name = std::string(words[2]);
            property.type = scalar_type(words[1], property.name);
        }
        element.properties.push_back(std::move(property));
    }

    PlyHeader finish() {
        if (!have_format_) fail(path_, "no format line before end_header", io::at_header_line(line_));
        if (!have_vertex_) fail(path_, "no vertex element", io::at_header_line(line_));
        return std::move(header_);
    }

    io::FileReader& in_;
    const std::string& path_;
    std::size_t line_ = 0;
    bool have_format_ = false;
    bool have_vertex_ = false;
    PlyHeader header_;
};

// ---------------------------------------------------------------------------------------
// Vertex layout: which property feeds which canonical field.

std::string rest_name(int index) {
    return "f_rest_" + std::to_string(index);
}

/// Canonical field names for a degree: the PLY property each field is read from. f_rest is
/// channel-major: coefficient k (1..K-1) of channel c is f_rest_{c*(K-1) + k-1}.
std::vector<std::string> ply_field_names(int sh_degree) {
    std::vector<std::string> names = {"x",       "y",     "z",     "scale_0", "scale_1", "scale_2",
                                      "opacity", "rot_0", "rot_1", "rot_2",   "rot_3"};
    const int coefficients = sh_coefficient_count(sh_degree);
    for (int k = 0; k < coefficients; ++k)
        for (int c = 0; c < 3; ++c)
            names.push_back(k == 0 ? "f_dc_" + std::to_string(c) : rest_name(c * (coefficients - 1) + (k - 1)));
    return names;
}

struct VertexLayout {
    int sh_degree = 0;
    std::vector<std::string> field_names;
    std::vector<int> field_of_property;  ///< -1 for properties that are not used
};

int sh_degree_of(const std::string& path, const PlyElement& vertex) {
    int rest = 0;
    for (const auto& p : vertex.properties)
        if (p.name.starts_with("f_rest_")) ++rest;
    for (int degree = 0; degree <= kMaxShDegree; ++degree)
        if (kRestCounts[degree] == rest) return degree;
    fail(path,
         "the vertex element has " + std::to_string(rest) +
             " f_rest_* properties; expected 0, 9, 24 or 45 (SH degree 0..3)",
         io::at_header_line(vertex.line));
}

VertexLayout map_vertex(const std::string& path, const PlyElement& vertex) {
    VertexLayout layout;
    layout.sh_degree = sh_degree_of(path, vertex);
    layout.field_names = ply_field_names(layout.sh_degree);
    std::unordered_map<std::string_view, int> field_of_name;
    for (int f = 0; f < static_cast<int>(layout.field_names.size()); ++f) field_of_name[layout.field_names[f]] = f;

    std::vector<bool> found(layout.field_names.size(), false);
    for (const auto& p : vertex.properties) {
        auto it = field_of_name.find(p.name);
        int field = it == field_of_name.end() ? -1 : it->second;
        if (field >= 0 && found[field])
            fail(path, "duplicate property " + io::quote(p.name) + " in the vertex element",
                 io::at_header_line(vertex.line));
        if (field >= 0) found[field] = true;
        layout.field_of_property.push_back(field);
    }

    std::string missing;
    int missing_count = 0;
    for (std::size_t f = 0; f < found.size(); ++f)
        if (!found[f]) {
            if (missing_count++ > 0) missing += ", ";
            missing += io::quote(layout.field_names[f]);
        }
    if (missing_count > 0)
        fail(path, std::string("missing required ") + (missing_count > 1 ? "properties " : "property ") + missing,
             "vertex element, " + io::at_header_line(vertex.line));
    return layout;
}

// ---------------------------------------------------------------------------------------
// Data.

[[noreturn]] void data_too_short(const std::string& path, const PlyElement& element, std::uint64_t need, bool at_least,
                                 const io::FileReader& in) {
    fail(path,
         "element '" + element.name + "' declares " + std::to_string(element.count) + " records, which need " +
             (at_least ? "at least " : "") + std::to_string(need) + " bytes, but only " +
             std::to_string(in.remaining()) + " bytes follow",
         io::at_offset(in.offset()));
}

[[noreturn]] void count_overflows(const std::string& path, const PlyElement& element) {
    fail(path,
         "element '" + element.name + "' declares " + std::to_string(element.count) + " records: too many to hold",
         io::at_header_line(element.line));
}

/// Checks that the element's records fit in what remains of the file: exactly `stride` bytes
/// each for binary, at least 2 bytes per value for ASCII (the last line may lack its newline).
void check_fits(const io::FileReader& in, const PlyElement& element, bool ascii) {
    const std::string& path = in.path();
    std::uint64_t per_record = ascii ? kMinAsciiBytesPerValue * element.properties.size() : element.stride();
    std::uint64_t need = 0;
    if (!io::checked_mul(element.count, per_record, need)) count_overflows(path, element);
    if (ascii && need > 0) --need;
    if (need > in.remaining()) data_too_short(path, element, need, ascii, in);
}

/// Binary elements before the vertex with list properties must be walked record by record;
/// each record consumes at least one byte, so this ends within the file size.
void walk_binary_element(io::FileReader& in, const PlyElement& element, bool big_endian) {
    const std::string& path = in.path();
    for (std::uint64_t r = 0; r < element.count; ++r)
        for (const auto& p : element.properties) {
            std::size_t count_bytes = io::scalar_size(p.is_list ? p.count_type : p.type);
            if (!in.require(count_bytes))
                fail(path, "data ends inside element '" + element.name + "'", io::at_field(r, "property", p.name));
            std::uint64_t skip = 0;
            if (p.is_list) {
                double length = io::decode_scalar(in.data(), p.count_type, big_endian);
                if (length < 0)
                    fail(path, "negative list length " + io::format_value(length), io::at_field(r, "property", p.name));
                if (!io::checked_mul(static_cast<std::uint64_t>(length), io::scalar_size(p.type), skip))
                    skip = std::numeric_limits<std::uint64_t>::max();
            }
            in.consume(count_bytes);
            if (skip > in.remaining())
                fail(path, "data ends inside element '" + element.name + "'", io::at_field(r, "property", p.name));
            in.skip(skip);
        }
}

void skip_binary_element(io::FileReader& in, const PlyElement& element, bool big_endian) {
    if (element.has_list()) {
        walk_binary_element(in, element, big_endian);
        return;
    }
    check_fits(in, element, false);
    in.skip(element.count * element.stride());
}

/// One record per line, as every ASCII PLY writer lays them out.
void skip_ascii_element(io::FileReader& in, const PlyElement& element) {
    std::string_view line;
    for (std::uint64_t r = 0; r < element.count; ++r) {
        auto status = in.read_line(kMaxAsciiLineBytes, line);
        if (status == io::FileReader::LineStatus::kEnd)
            fail(in.path(), "data ends inside element '" + element.name + "'", io::at_record(r));
        if (status == io::FileReader::LineStatus::kTooLong)
            fail(in.path(),
                 "line longer than " + std::to_string(kMaxAsciiLineBytes) + " bytes in element '" + element.name + "'",
                 io::at_record(r));
    }
}

/// Walks over one element whose values are not used (before or after the vertices).
void skip_element(io::FileReader& in, const PlyElement& element, bool ascii, bool big_endian) {
    if (ascii)
        skip_ascii_element(in, element);
    else
        skip_binary_element(in, element, big_endian);
}

struct BinarySlot {
    std::size_t offset;
    io::ScalarType type;
    int field;
};

void read_binary_vertices(io::FileReader& in, const PlyElement& vertex, const VertexLayout& layout, bool big_endian,
                          io::SceneBuilder& builder, const io::ProgressTicker& ticker) {
    std::vector<BinarySlot> slots;
    std::size_t offset = 0;
    for (std::size_t p = 0; p < vertex.properties.size(); ++p) {
        if (layout.field_of_property[p] >= 0)
            slots.push_back({offset, vertex.properties[p].type, layout.field_of_property[p]});
        offset += io::scalar_size(vertex.properties[p].type);
    }
    const std::size_t stride = offset;
    const std::uint64_t per_chunk = std::max<std::uint64_t>(1, io::kChunkBytes / stride);
    double values[io::kMaxFields];
    for (std::uint64_t done = 0; done < vertex.count;) {
        const std::size_t n = static_cast<std::size_t>(std::min(per_chunk, vertex.count - done));
        // The size was checked against the file before allocating; this catches a file that
        // shrank while being read.
        if (!in.require(n * stride)) fail(in.path(), "data ends early", io::at_record(done));
        const unsigned char* record = in.data();
        for (std::size_t r = 0; r < n; ++r, record += stride) {
            for (const auto& slot : slots)
                values[slot.field] = io::decode_scalar(record + slot.offset, slot.type, big_endian);
            builder.add(values, done + r);
        }
        in.consume(n * stride);
        done += n;
        ticker.update(in.offset(), in.size());
    }
}

/// from_chars reports out_of_range without a value; PLY writers produce such tokens only
/// for values beyond double range (overflow, treated as infinite like a binary inf) or tiny
/// ones with a negative exponent (underflow to zero).
double out_of_range_value(std::string_view token) {
    bool negative = token.front() == '-';
    auto e = token.find_first_of("eE");
    bool underflow = e != std::string_view::npos && e + 1 < token.size() && token[e + 1] == '-';
    double magnitude = underflow ? 0.0 : std::numeric_limits<double>::infinity();
    return negative ? -magnitude : magnitude;
}

bool parse_ascii_number(std::string_view token, double& value) {
    // from_chars does not take the leading '+' that some writers emit.
    if (token.size() > 1 && token[0] == '+' && token[1] != '-' && token[1] != '+') token.remove_prefix(1);
    auto result = std::from_chars(token.data(), token.data() + token.size(), value);
    if (result.ptr != token.data() + token.size()) return false;
    if (result.ec == std::errc::result_out_of_range) {
        value = out_of_range_value(token);
        return true;
    }
    return result.ec == std::errc();
}

std::string_view next_token(std::string_view line, std::size_t& pos) {
    while (pos < line.size() && (line[pos] == ' ' || line[pos] == '\t')) ++pos;
    std::size_t start = pos;
    while (pos < line.size() && line[pos] != ' ' && line[pos] != '\t') ++pos;
    return line.substr(start, pos - start);
}

void read_ascii_vertices(io::FileReader& in, const PlyElement& vertex, const VertexLayout& layout,
                         io::SceneBuilder& builder, const io::ProgressTicker& ticker) {
    const std::string& path = in.path();
    double values[io::kMaxFields];
    std::string_view line;
    for (std::uint64_t r = 0; r < vertex.count; ++r) {
        auto status = in.read_line(kMaxAsciiLineBytes, line);
        if (status == io::FileReader::LineStatus::kEnd)
            fail(path,
                 "data ends after " + std::to_string(r) + " of " + std::to_string(vertex.count) + " vertex records",
                 io::at_field(r, "property", vertex.properties.front().name));
        if (status == io::FileReader::LineStatus::kTooLong)
            fail(path, "line longer than " + std::to_string(kMaxAsciiLineBytes) + " bytes", io::at_record(r));
        std::size_t pos = 0;
        for (std::size_t p = 0; p < vertex.properties.size(); ++p) {
            std::string_view token = next_token(line, pos);
            const std::string& name = vertex.properties[p].name;
            if (token.empty())
                fail(path,
                     "missing value: the line has only " + std::to_string(p) + " of " +
                         std::to_string(vertex.properties.size()) + " values",
                     io::at_field(r, "property", name));
            const int field = layout.field_of_property[p];
            if (field >= 0 && !parse_ascii_number(token, values[field]))
                fail(path, "cannot parse " + io::quote(token) + " as a number", io::at_field(r, "property", name));
        }
        if (!next_token(line, pos).empty())
            fail(path, "more than " + std::to_string(vertex.properties.size()) + " values on the line",
                 io::at_record(r));
        builder.add(values, r);
        if ((r + 1) % kAsciiProgressRecords == 0) ticker.update(in.offset(), in.size());
    }
}

/// A header that declares fewer records than the file holds (say 1000 of 2000 vertices) would
/// otherwise load part of the scene without a word; the compressed PLY reader refuses the same.
/// An ASCII file may end with blank lines.
void check_nothing_after(io::FileReader& in, const PlyElement& last, bool ascii) {
    const std::uint64_t end = in.offset();
    const std::uint64_t extra = in.remaining();
    for (std::uint64_t at = end; ascii && in.remaining() > 0;) {
        const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(in.remaining(), kAsciiScanBytes));
        if (!in.require(n)) break;
        const unsigned char* data = in.data();
        for (std::size_t k = 0; k < n; ++k, ++at) {
            const unsigned char c = data[k];
            if (!(c == ' ' || c == '\t' || c == '\r' || c == '\n'))
                fail(in.path(),
                     "data after the last element " + io::quote(last.name) +
                         ": the header declares fewer records than the file holds",
                     io::at_offset(at));
        }
        in.consume(n);
    }
    if (!ascii && extra > 0)
        fail(in.path(),
             std::to_string(extra) + " bytes after the last element " + io::quote(last.name) + ", which ends at byte " +
                 std::to_string(end) + ": the header declares fewer records than the file holds",
             io::at_offset(end));
}

}  // namespace

Scene read_ply(const std::string& path, const LoadOptions& options, LoadReport* report) {
    io::FileReader in(path);
    const PlyHeader header = HeaderParser(in).parse();
    const PlyElement& vertex = header.elements[header.vertex];
    const VertexLayout layout = map_vertex(path, vertex);
    const bool ascii = header.format == PlyFormat::kAscii;
    const bool big_endian = header.format == PlyFormat::kBinaryBigEndian;

    for (std::size_t e = 0; e < header.vertex; ++e) skip_element(in, header.elements[e], ascii, big_endian);

    if (vertex.count == 0)
        fail(path, "no Gaussians: the vertex element has 0 records", io::at_header_line(vertex.line));
    // Before allocating: a header may claim any count, the file must hold it.
    check_fits(in, vertex, ascii);

    io::SceneBuilder builder(path, vertex.count, layout.sh_degree, kPlyEncoding, layout.field_names, options);
    io::ProgressTicker ticker(options.progress, path);
    if (ascii) {
        read_ascii_vertices(in, vertex, layout, builder, ticker);
    } else {
        read_binary_vertices(in, vertex, layout, big_endian, builder, ticker);
    }
    // Elements after the vertices (faces, say) are not used, but a file that ends before their
    // data was cut short, so its vertices cannot be trusted either: the records must be there,
    // checked by size when binary records have a fixed size, else walked (lists, ASCII lines).
    for (std::size_t e = header.vertex + 1; e < header.elements.size(); ++e)
        skip_element(in, header.elements[e], ascii, big_endian);
    check_nothing_after(in, header.elements.back(), ascii);
    Scene scene = builder.finish(report);
    ticker.finish();
    return scene;
}

}  // namespace catgs
