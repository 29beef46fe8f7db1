#include "scene_io_detail.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <limits>

#include "catgs/error.hpp"
#include "catgs/regular_file.hpp"

namespace catgs::io {

namespace {

/// Untrusted text quoted in a message is cut to this many bytes: enough to recognise a
/// token, short enough that a binary blob cannot flood the one-line message.
constexpr std::size_t kMaxQuotedBytes = 64;

/// A stored position further than this from the world origin is rejected: positions become
/// floats relative to the centre of the bounds, and a spread of up to 2e30 stays far inside
/// float range (3.4e38); no real capture comes anywhere near (UTM is ~1e7 m).
constexpr double kMaxAbsCoordinate = 1e30;

/// A quaternion whose squared norm is this close to 1 is kept as it is, not divided by its
/// norm: re-normalising a float unit quaternion in double and rounding back changes about 1%
/// of them by one ulp, which would break write_ply/read_ply bit-exactness. A quaternion
/// normalised and rounded to float has |norm^2 - 1| <= 2 * 2^-24 (each component carries at
/// most half an ulp, 2^-24 relative); twice that bound leaves margin for the double sum.
/// The deviation from dividing is at most ~2^-22 relative, i.e. about one float ulp.
constexpr double kUnitNormSquaredSlack = 0x1p-22;

/// A scene is shrunk after dropping when more than this fraction of its allocation would be
/// wasted; below it the copy that shrink_to_fit makes (briefly doubling memory) is not worth it.
constexpr double kShrinkWasteFraction = 0.25;

template <typename T>
void shrink_vector(std::vector<T>& v) {
    v.shrink_to_fit();
}

void shrink_scene(Scene& scene) {
    shrink_vector(scene.positions);
    shrink_vector(scene.scales);
    shrink_vector(scene.rotations);
    shrink_vector(scene.opacities);
    shrink_vector(scene.sh);
}

}  // namespace

// ---------------------------------------------------------------------------------------

void fail(const std::string& path, const std::string& problem, const std::string& where) {
    if (where.empty()) throw Error(path + ": " + problem);
    throw Error(path + ": " + problem + " (" + where + ")");
}

std::string at_offset(std::uint64_t offset) {
    return "byte offset " + std::to_string(offset);
}

std::string at_header_line(std::size_t line) {
    return "header line " + std::to_string(line);
}

std::string at_record(std::uint64_t record) {
    return "record " + std::to_string(record);
}

std::string at_field(std::uint64_t record, std::string_view noun, std::string_view name) {
    return at_record(record) + ", " + std::string(noun) + " '" + std::string(name) + "'";
}

std::string format_value(double value) {
    char text[64];
    auto result = std::to_chars(text, text + sizeof(text), value);
    return std::string(text, result.ptr);
}

std::string quote(std::string_view text) {
    std::string out = "'";
    for (std::size_t i = 0; i < text.size() && i < kMaxQuotedBytes; ++i) {
        auto c = static_cast<unsigned char>(text[i]);
        if (c >= 0x20 && c < 0x7f) {
            out += static_cast<char>(c);
        } else {
            char escaped[8];
            std::snprintf(escaped, sizeof(escaped), "\\x%02x", c);
            out += escaped;
        }
    }
    if (text.size() > kMaxQuotedBytes) out += "...";
    return out + "'";
}

void check_limits(const std::string& path, std::uint64_t records, int sh_degree, const LoadOptions& options) {
    if (records > options.max_records)
        throw LimitError(path + ": " + std::to_string(records) + " records exceed the limit of " +
                         std::to_string(options.max_records) + " (LoadOptions::max_records)");
    const std::uint64_t each = scene_bytes_per_gaussian(sh_degree);
    // Divided rather than multiplied: the count comes from an untrusted header.
    if (records > options.max_scene_bytes / each)
        throw LimitError(path + ": " + std::to_string(records) + " records of SH degree " + std::to_string(sh_degree) +
                         " at " + std::to_string(each) + " bytes each exceed the limit of " +
                         std::to_string(options.max_scene_bytes) + " bytes (LoadOptions::max_scene_bytes)");
}

// ---------------------------------------------------------------------------------------

FileReader::FileReader(const std::string& path) : path_(path) {
    std::string problem;
    const int fd = open_regular_file(path, size_, problem);
    if (fd < 0) fail(path, "cannot open: " + problem, "");
    file_ = ::fdopen(fd, "rb");
    if (!file_) {
        const int error = errno;
        ::close(fd);
        fail(path, std::string("cannot open: ") + std::strerror(error), "");
    }
    buffer_.resize(static_cast<std::size_t>(std::min<std::uint64_t>(size_, kChunkBytes)));
}

FileReader::~FileReader() {
    std::fclose(file_);
}

bool FileReader::fill(std::size_t want) {
    if (begin_ > 0) {
        std::memmove(buffer_.data(), buffer_.data() + begin_, end_ - begin_);
        buffer_offset_ += begin_;
        end_ -= begin_;
        begin_ = 0;
    }
    if (buffer_.size() < want) buffer_.resize(want);
    bool got_any = false;
    while (end_ < buffer_.size()) {
        std::size_t n = std::fread(buffer_.data() + end_, 1, buffer_.size() - end_, file_);
        if (n == 0) {
            if (std::ferror(file_)) {
                int error = errno;
                fail(path_, std::string("read error: ") + std::strerror(error), at_offset(buffer_offset_ + end_));
            }
            break;
        }
        end_ += n;
        got_any = true;
    }
    return got_any;
}

bool FileReader::require(std::size_t n) {
    while (available() < n)
        if (!fill(std::max(n, buffer_.size()))) return false;
    return true;
}

void FileReader::skip(std::uint64_t n) {
    if (n <= available()) {
        consume(static_cast<std::size_t>(n));
        return;
    }
    std::uint64_t target = offset() + n;
    if (::fseeko(file_, static_cast<off_t>(target), SEEK_SET) != 0) {
        int error = errno;
        fail(path_, std::string("seek error: ") + std::strerror(error), at_offset(target));
    }
    buffer_offset_ = target;
    begin_ = end_ = 0;
}

FileReader::LineStatus FileReader::read_line(std::size_t max_bytes, std::string_view& line) {
    std::size_t scanned = 0;
    for (;;) {
        const auto* start = data();
        std::size_t avail = available();
        const void* newline = std::memchr(start + scanned, '\n', avail - scanned);
        std::size_t length =
            newline ? static_cast<std::size_t>(static_cast<const unsigned char*>(newline) - start) : avail;
        if (length > max_bytes) return LineStatus::kTooLong;
        bool at_end = false;
        if (!newline) {
            scanned = avail;
            // Grow only when the buffer is full of one partial line, doubling so that a long
            // line costs linear time, and never past the line limit.
            std::size_t want = avail < buffer_.size() ? buffer_.size() : std::min(max_bytes + 1, 2 * avail + 1);
            if (fill(want)) continue;
            if (avail == 0) return LineStatus::kEnd;
            at_end = true;
        }
        line = std::string_view(reinterpret_cast<const char*>(data()), length);
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        consume(at_end ? length : length + 1);
        return LineStatus::kOk;
    }
}

ProgressTicker::ProgressTicker(const Progress& progress, const std::string& path)
    : progress_(progress), label_("loading " + std::filesystem::path(path).filename().string()) {}

void ProgressTicker::update(std::uint64_t done, std::uint64_t total) const {
    if (progress_ && total > 0) progress_(static_cast<double>(done) / static_cast<double>(total), label_);
}

void ProgressTicker::finish() const {
    if (progress_) progress_(1.0, label_);
}

// ---------------------------------------------------------------------------------------

std::size_t scalar_size(ScalarType type) {
    switch (type) {
        case ScalarType::kInt8:
        case ScalarType::kUInt8:
            return 1;
        case ScalarType::kInt16:
        case ScalarType::kUInt16:
            return 2;
        case ScalarType::kInt32:
        case ScalarType::kUInt32:
        case ScalarType::kFloat32:
            return 4;
        case ScalarType::kFloat64:
            return 8;
    }
    return 0;
}

bool is_integer(ScalarType type) {
    return type != ScalarType::kFloat32 && type != ScalarType::kFloat64;
}

double decode_scalar(const unsigned char* p, ScalarType type, bool big_endian) {
    switch (type) {
        case ScalarType::kInt8:
            return static_cast<std::int8_t>(p[0]);
        case ScalarType::kUInt8:
            return p[0];
        case ScalarType::kInt16:
            return load_scalar<std::int16_t>(p, big_endian);
        case ScalarType::kUInt16:
            return load_scalar<std::uint16_t>(p, big_endian);
        case ScalarType::kInt32:
            return load_scalar<std::int32_t>(p, big_endian);
        case ScalarType::kUInt32:
            return load_scalar<std::uint32_t>(p, big_endian);
        case ScalarType::kFloat32:
            return load_scalar<float>(p, big_endian);
        case ScalarType::kFloat64:
            return load_scalar<double>(p, big_endian);
    }
    return 0.0;
}

// ---------------------------------------------------------------------------------------

SceneBuilder::SceneBuilder(const std::string& path, std::uint64_t records, int sh_degree, Encoding encoding,
                           std::vector<std::string> field_names, const LoadOptions& options)
    : path_(path),
      records_(records),
      encoding_(encoding),
      field_names_(std::move(field_names)),
      drop_invalid_(options.drop_invalid),
      recentre_(options.recentre),
      fields_(field_count(sh_degree)) {
    // Callers bound `records` by the file size; this keeps the size_t arithmetic of the
    // allocation below exact even where size_t is narrower than the 64-bit count.
    if (records > std::numeric_limits<std::size_t>::max() / (sizeof(float) * kMaxFields + 3 * sizeof(double)))
        fail(path, std::to_string(records) + " records are too many to hold", "");
    check_limits(path, records, sh_degree, options);
    scene_.sh_degree = sh_degree;
    scene_.resize(static_cast<std::size_t>(records));
    world_.resize(3 * static_cast<std::size_t>(records));
    report_.records = static_cast<std::size_t>(records);
}

void SceneBuilder::reject(const std::string& problem, std::uint64_t record, int field) {
    if (!drop_invalid_) fail(path_, problem, at_field(record, encoding_.noun, field_names_[field]));
    ++report_.dropped_invalid;
}

void SceneBuilder::reject_quaternion(const std::string& problem, std::uint64_t record) {
    if (!drop_invalid_)
        fail(path_, problem,
             at_record(record) + ", " + std::string(encoding_.nouns) + " '" + field_names_[kFieldRot] + "'..'" +
                 field_names_[kFieldRot + 3] + "'");
    ++report_.dropped_invalid;
}

void SceneBuilder::add(const double* v, std::uint64_t record) {
    for (int f = 0; f < fields_; ++f)
        if (!std::isfinite(v[f])) {
            reject("non-finite value " + format_value(v[f]), record, f);
            return;
        }
    for (int a = 0; a < 3; ++a)
        if (std::fabs(v[kFieldX + a]) > kMaxAbsCoordinate) {
            reject("coordinate " + format_value(v[kFieldX + a]) + " is beyond +-1e30", record, kFieldX + a);
            return;
        }

    float scale[3];
    for (int a = 0; a < 3; ++a) {
        double raw = v[kFieldScale + a];
        scale[a] = static_cast<float>(encoding_.log_scale ? std::exp(raw) : raw);
        if (!std::isfinite(scale[a])) {
            reject("scale " + format_value(raw) + " overflows float after exp", record, kFieldScale + a);
            return;
        }
    }

    double norm2 = 0.0;
    for (int c = 0; c < 4; ++c) norm2 += v[kFieldRot + c] * v[kFieldRot + c];
    if (!(norm2 > 0.0) || !std::isfinite(norm2)) {
        reject_quaternion(norm2 > 0.0 ? "quaternion norm overflows" : "zero-norm quaternion", record);
        return;
    }
    const double* q = v + kFieldRot;
    double rescaled[4];
    if (norm2 < std::numeric_limits<double>::min()) {
        // A subnormal norm^2 (components below ~1e-154, from double properties) keeps only a
        // few significant bits: normalise the quaternion divided by its largest component.
        double largest = 0.0;
        for (int c = 0; c < 4; ++c) largest = std::max(largest, std::fabs(q[c]));
        norm2 = 0.0;
        for (int c = 0; c < 4; ++c) {
            rescaled[c] = q[c] / largest;
            norm2 += rescaled[c] * rescaled[c];
        }
        q = rescaled;
    }
    float rotation[4];
    bool already_unit = std::fabs(norm2 - 1.0) <= kUnitNormSquaredSlack;
    double inverse_norm = already_unit ? 1.0 : 1.0 / std::sqrt(norm2);
    for (int c = 0; c < 4; ++c) rotation[c] = static_cast<float>(already_unit ? q[c] : q[c] * inverse_norm);

    const int sh_fields = fields_ - kFieldSh;
    float* sh = scene_.sh.data() + kept_ * static_cast<std::size_t>(sh_fields);
    for (int i = 0; i < sh_fields; ++i) {
        sh[i] = static_cast<float>(v[kFieldSh + i]);
        if (!std::isfinite(sh[i])) {
            reject("value " + format_value(v[kFieldSh + i]) + " overflows float", record, kFieldSh + i);
            return;
        }
    }

    double raw_opacity = v[kFieldOpacity];
    float opacity = static_cast<float>(encoding_.logit_opacity ? 1.0 / (1.0 + std::exp(-raw_opacity)) : raw_opacity);
    // After the validity checks, so that a record that is both is counted as invalid.
    if (static_cast<double>(opacity) < kMinAlpha) {
        ++report_.dropped_transparent;
        return;
    }

    for (int a = 0; a < 3; ++a) {
        world_[3 * kept_ + a] = v[kFieldX + a];
        scene_.scales[3 * kept_ + a] = scale[a];
    }
    for (int c = 0; c < 4; ++c) scene_.rotations[4 * kept_ + c] = rotation[c];
    scene_.opacities[kept_] = opacity;
    ++kept_;
}

Scene SceneBuilder::finish(LoadReport* report) {
    if (kept_ == 0) {
        std::size_t dropped = report_.dropped_transparent + report_.dropped_invalid;
        fail(path_,
             "no Gaussians left after dropping " + std::to_string(dropped) + " transparent/invalid records (" +
                 std::to_string(report_.dropped_transparent) + " with opacity < 1/255, " +
                 std::to_string(report_.dropped_invalid) + " invalid)",
             "all " + std::to_string(records_) + " records");
    }
    if (kept_ < records_) {
        scene_.resize(kept_);
        world_.resize(3 * kept_);
        if (static_cast<double>(records_ - kept_) > kShrinkWasteFraction * static_cast<double>(records_))
            shrink_scene(scene_);
    }

    // The origin comes from the double world coordinates, before any float rounding, so that
    // UTM-sized captures lose nothing beyond the final rounding of the offsets.
    scene_.origin = {0.0, 0.0, 0.0};
    if (recentre_) {
        Bounds world_bounds;
        for (int a = 0; a < 3; ++a) {
            double lo = std::numeric_limits<double>::infinity();
            double hi = -lo;
            for (std::size_t i = 0; i < kept_; ++i) {
                lo = std::min(lo, world_[3 * i + a]);
                hi = std::max(hi, world_[3 * i + a]);
            }
            world_bounds.min[a] = lo;
            world_bounds.max[a] = hi;
        }
        scene_.origin = scene_origin(world_bounds, kept_, [this](std::size_t i, int a) { return world_[3 * i + a]; });
    }
    for (std::size_t i = 0; i < kept_; ++i)
        for (int a = 0; a < 3; ++a)
            scene_.positions[3 * i + a] = static_cast<float>(world_[3 * i + a] - scene_.origin[a]);
    std::vector<double>().swap(world_);

    scene_.update_bounds();
    if (report) *report = report_;
    return std::move(scene_);
}

}  // namespace catgs::io
