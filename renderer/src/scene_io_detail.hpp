// Internals shared by the scene readers and the writer (ply_reader.cpp, splat_reader.cpp,
// ply_writer.cpp): error wording, a bounded chunked file reader, scalar decoding, and the
// SceneBuilder that validates, activates and stores records the same way for every format.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "catgs/constants.hpp"
#include "catgs/progress.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"

namespace catgs::io {

// ---------------------------------------------------------------------------------------
// Error wording: every message is "<path>: <problem> (<where>)" on one line.

[[noreturn]] void fail(const std::string& path, const std::string& problem, const std::string& where);
std::string at_offset(std::uint64_t offset);
std::string at_header_line(std::size_t line);
std::string at_record(std::uint64_t record);
std::string at_field(std::uint64_t record, std::string_view noun, std::string_view name);
/// A value for a message: round-trip precision, so that what the user sees is what was read.
std::string format_value(double value);
/// Quotes an untrusted token for a message, cut short and with control bytes escaped so that
/// the message stays one readable line whatever the file holds.
std::string quote(std::string_view text);

/// a * b, or false when it does not fit: counts come from untrusted headers.
inline bool checked_mul(std::uint64_t a, std::uint64_t b, std::uint64_t& out) {
    return !__builtin_mul_overflow(a, b, &out);
}

/// Refuses `records` Gaussians of `sh_degree` beyond options.max_records or
/// options.max_scene_bytes. Readers of compressed formats call it as soon as the header gives
/// the count and degree, before decompressing; SceneBuilder calls it for every format.
void check_limits(const std::string& path, std::uint64_t records, int sh_degree, const LoadOptions& options);

// ---------------------------------------------------------------------------------------
// Chunked reading.

/// Binary data is read in blocks of this size: large enough that the per-read cost vanishes
/// against the decoding, small enough to stay in L2/L3-friendly territory and to give the
/// progress callback a steady rhythm.
inline constexpr std::size_t kChunkBytes = std::size_t{8} << 20;

/// A read-only file consumed front to back through one bounded buffer. Nothing it does
/// allocates more than the largest single request (a chunk, a record or a line), so a
/// hostile file cannot make it grow without bound.
class FileReader {
public:
    /// Throws "<path>: cannot open: <strerror>" when the file cannot be opened, and refuses
    /// anything that is not a regular file (a FIFO or device has no size to check against).
    explicit FileReader(const std::string& path);
    ~FileReader();
    FileReader(const FileReader&) = delete;
    FileReader& operator=(const FileReader&) = delete;

    const std::string& path() const { return path_; }
    std::uint64_t size() const { return size_; }
    /// File offset of the next unconsumed byte.
    std::uint64_t offset() const { return buffer_offset_ + begin_; }
    std::uint64_t remaining() const { return size_ - offset(); }

    /// Makes at least n bytes available at data(); false when the file ends first.
    bool require(std::size_t n);
    const unsigned char* data() const { return buffer_.data() + begin_; }
    std::size_t available() const { return end_ - begin_; }
    void consume(std::size_t n) { begin_ += n; }
    /// Skips n bytes (n <= remaining(), checked by the caller against size()).
    void skip(std::uint64_t n);

    enum class LineStatus { kOk, kEnd, kTooLong };
    /// Reads one line ('\n' or "\r\n" terminated, or the file's last bytes) of at most
    /// max_bytes; the view stays valid until the next call.
    LineStatus read_line(std::size_t max_bytes, std::string_view& line);

private:
    /// Moves the unconsumed bytes to the front and reads more, growing the buffer to at least
    /// `want` bytes. Returns false at end of file.
    bool fill(std::size_t want);

    std::string path_;
    std::FILE* file_ = nullptr;
    std::uint64_t size_ = 0;
    std::vector<unsigned char> buffer_;
    std::size_t begin_ = 0;
    std::size_t end_ = 0;
    std::uint64_t buffer_offset_ = 0;  ///< file offset of buffer_[0]
};

/// "loading <file name>" at most once per chunk, then 1.0 at the end.
class ProgressTicker {
public:
    ProgressTicker(const Progress& progress, const std::string& path);
    void update(std::uint64_t done, std::uint64_t total) const;
    void finish() const;

private:
    const Progress& progress_;
    std::string label_;
};

// ---------------------------------------------------------------------------------------
// Scalars.

enum class ScalarType : std::uint8_t { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64 };

std::size_t scalar_size(ScalarType type);
bool is_integer(ScalarType type);

template <typename T>
T byteswap_value(T value) {
    static_assert(std::is_trivially_copyable_v<T>);
    unsigned char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
    std::memcpy(&value, bytes, sizeof(T));
    return value;
}

/// Reads a T stored in the given byte order at p.
template <typename T>
T load_scalar(const unsigned char* p, bool big_endian) {
    T value;
    std::memcpy(&value, p, sizeof(T));
    if (big_endian != (std::endian::native == std::endian::big)) value = byteswap_value(value);
    return value;
}

/// Stores a T at p in little-endian order.
template <typename T>
void store_little_endian(unsigned char* p, T value) {
    if constexpr (std::endian::native == std::endian::big) value = byteswap_value(value);
    std::memcpy(p, &value, sizeof(T));
}

double decode_scalar(const unsigned char* p, ScalarType type, bool big_endian);

// ---------------------------------------------------------------------------------------
// Records. Every reader turns a record into this canonical list of doubles; SceneBuilder
// validates, activates and stores it, so that the formats cannot drift apart.

inline constexpr int kFieldX = 0;        ///< x, y, z: world position
inline constexpr int kFieldScale = 3;    ///< 3 scales (log or linear, see Encoding)
inline constexpr int kFieldOpacity = 6;  ///< logit or linear, see Encoding
inline constexpr int kFieldRot = 7;      ///< w, x, y, z, not necessarily normalised
inline constexpr int kFieldSh = 11;      ///< [coefficient][rgb], coefficient 0 = f_dc
constexpr int field_count(int sh_degree) {
    return kFieldSh + 3 * sh_coefficient_count(sh_degree);
}
inline constexpr int kMaxFields = field_count(kMaxShDegree);

/// How a format stores the fields that need an activation.
struct Encoding {
    bool log_scale;          ///< scale = exp(value), else the value is the linear scale
    bool logit_opacity;      ///< opacity = sigmoid(value), else the value is the opacity
    std::string_view noun;   ///< what a message calls a field: "property" (PLY), "field" (.splat)
    std::string_view nouns;  ///< and several of them
};

/// Collects the records of one file into a Scene. The caller must have checked `records`
/// against the file size: the builder allocates for all of them up front.
class SceneBuilder {
public:
    SceneBuilder(const std::string& path, std::uint64_t records, int sh_degree, Encoding encoding,
                 std::vector<std::string> field_names, const LoadOptions& options);

    /// Validates and stores one record of field_count(sh_degree) values, or counts it as
    /// dropped. Throws on invalid values unless options.drop_invalid.
    void add(const double* values, std::uint64_t record);

    /// Chooses the origin, converts positions to float and fills the report.
    Scene finish(LoadReport* report);

private:
    /// Counts the record as dropped, or throws, as options.drop_invalid says.
    void reject(const std::string& problem, std::uint64_t record, int field);
    void reject_quaternion(const std::string& problem, std::uint64_t record);

    std::string path_;
    std::uint64_t records_;
    Encoding encoding_;
    std::vector<std::string> field_names_;
    bool drop_invalid_;
    bool recentre_;
    int fields_;
    Scene scene_;
    std::vector<double> world_;  ///< 3 per kept record, until the origin is known
    std::size_t kept_ = 0;
    LoadReport report_;
};

}  // namespace catgs::io
