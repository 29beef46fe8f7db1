// Camera path files: graphdeco cameras.json and our own trajectory text format (read and
// written), and load_trajectory, which picks a reader or the procedural flights by the spec.
#include "catgs/trajectory.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <utility>

#include <nlohmann/json.hpp>

#include "catgs/error.hpp"
#include "catgs/regular_file.hpp"
#include "trajectory_detail.hpp"

namespace catgs {

namespace {

using detail::M3;
using detail::orthonormality_error;
using detail::V3;

// cameras.json stores rotations with 7-9 significant digits, so 1e-3 only rejects matrices
// that are not rotations at all (a transposed or scaled matrix, a typo).
constexpr double kOrthonormalTolerance = 1e-3;

double determinant(const M3& m) {
    return m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6]);
}

std::string format_double(double value) {
    // Shortest text that reads back to the same double, independent of the C locale.
    char buffer[32];
    const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
    return std::string(buffer, result.ptr);
}

// ---------------------------------------------------------------------------------------
// Trajectory text format

constexpr std::size_t kPoseFields = 8;
constexpr std::size_t kFullFields = 14;
constexpr std::array<const char*, kFullFields> kFieldNames{"timestamp", "px", "py", "pz", "qw", "qx",    "qy",
                                                           "qz",        "fx", "fy", "cx", "cy", "width", "height"};

std::vector<std::string> split_fields(const std::string& line) {
    std::vector<std::string> fields;
    constexpr const char* kBlank = " \t\r\v\f";
    for (std::size_t begin = line.find_first_not_of(kBlank); begin != std::string::npos;) {
        const std::size_t end = std::min(line.find_first_of(kBlank, begin), line.size());
        fields.push_back(line.substr(begin, end - begin));
        begin = line.find_first_not_of(kBlank, end);
    }
    return fields;
}

double parse_field(const std::string& where, std::size_t index, const std::string& text) {
    double value = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
    const std::string field = "field " + std::to_string(index + 1) + " (" + kFieldNames[index] + ") '" + text + "'";
    if (ec == std::errc::result_out_of_range) throw Error(where + ": " + field + " is out of range");
    if (ec != std::errc() || end != text.data() + text.size()) throw Error(where + ": " + field + " is not a number");
    if (!std::isfinite(value)) throw Error(where + ": " + field + " is not finite");
    return value;
}

int image_size(const std::string& where, const char* name, double value) {
    if (value != std::floor(value) || value <= 0 || value > INT_MAX)
        throw Error(where + ": " + name + " " + format_double(value) + " must be a positive whole number");
    return static_cast<int>(value);
}

}  // namespace

std::vector<Camera> read_cameras_json(const std::string& path) {
    std::string problem;
    const std::optional<std::string> text = read_regular_file(path, kMaxCameraFileBytes, problem);
    if (!text) throw Error(path + ": cannot open cameras file: " + problem);
    nlohmann::json doc;
    try {
        doc = nlohmann::json::parse(*text);
    } catch (const nlohmann::json::parse_error& e) {
        throw Error(path + ": not JSON (at byte " + std::to_string(e.byte) + "): " + e.what());
    } catch (const nlohmann::json::exception& e) {
        throw Error(path + ": not JSON: " + e.what());
    }
    if (!doc.is_array()) throw Error(path + ": expected a JSON array of cameras, found " + doc.type_name());
    if (doc.empty()) throw Error(path + ": contains no cameras");

    std::vector<Camera> cameras;
    cameras.reserve(doc.size());
    for (std::size_t i = 0; i < doc.size(); ++i) {
        const std::string where = path + ": camera " + std::to_string(i);
        const nlohmann::json& entry = doc[i];
        if (!entry.is_object()) throw Error(where + ": expected an object, found " + entry.type_name());
        const auto field = [&](const char* name) -> const nlohmann::json& {
            const auto it = entry.find(name);
            if (it == entry.end()) throw Error(where + ": missing field '" + name + "'");
            return *it;
        };
        const auto number = [&](const nlohmann::json& value, const std::string& name) {
            if (!value.is_number()) throw Error(where + ": field '" + name + "' must be a number");
            const double v = value.get<double>();
            if (!std::isfinite(v)) throw Error(where + ": field '" + name + "' is not finite");
            return v;
        };
        const auto size = [&](const char* name) {
            const nlohmann::json& value = field(name);
            if (!value.is_number_integer())
                throw Error(where + ": field '" + std::string(name) + "' must be an integer");
            const auto v = value.get<std::int64_t>();
            if (v <= 0 || v > INT_MAX) throw Error(where + ": field '" + std::string(name) + "' must be positive");
            return static_cast<int>(v);
        };
        const auto focal = [&](const char* name) {
            const double v = number(field(name), name);
            if (!(v > 0)) throw Error(where + ": field '" + std::string(name) + "' must be positive");
            return v;
        };

        Camera camera;
        const nlohmann::json& name = field("img_name");
        if (!name.is_string()) throw Error(where + ": field 'img_name' must be a string");
        camera.name = name.get<std::string>();
        Intrinsics& k = camera.intrinsics;
        k.width = size("width");
        k.height = size("height");
        k.fx = focal("fx");
        k.fy = focal("fy");
        k.cx = 0.5 * k.width;
        k.cy = 0.5 * k.height;

        const nlohmann::json& position = field("position");
        if (!position.is_array() || position.size() != 3)
            throw Error(where + ": field 'position' must be an array of 3 numbers");
        V3 centre;
        for (int a = 0; a < 3; ++a) centre[a] = number(position[a], "position[" + std::to_string(a) + "]");

        const nlohmann::json& rotation = field("rotation");
        if (!rotation.is_array() || rotation.size() != 3 ||
            !std::all_of(rotation.begin(), rotation.end(),
                         [](const auto& row) { return row.is_array() && row.size() == 3; }))
            throw Error(where + ": field 'rotation' must be a 3x3 array of numbers");
        M3 camera_to_world;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c)
                camera_to_world[3 * r + c] =
                    number(rotation[r][c], "rotation[" + std::to_string(r) + "][" + std::to_string(c) + "]");
        const double error = orthonormality_error(camera_to_world);
        if (error > kOrthonormalTolerance)
            throw Error(where + ": field 'rotation' is not orthonormal (R^T R deviates from I by " +
                        format_double(error) + ")");
        if (determinant(camera_to_world) < 0)
            throw Error(where + ": field 'rotation' is a reflection (determinant -1), not a rotation");
        // Through the quaternion: the stored digits leave up to 1e-3 of skew, the pose gets none.
        camera.pose =
            pose_from_quaternion(centre, camera_to_world_quaternion(pose_from_centre(centre, camera_to_world)));
        cameras.push_back(std::move(camera));
    }
    return cameras;
}

std::vector<Camera> read_trajectory(const std::string& path, const Intrinsics& defaults) {
    std::string problem;
    const std::optional<std::string> text = read_regular_file(path, kMaxCameraFileBytes, problem);
    if (!text) throw Error(path + ": cannot open trajectory file: " + problem);
    std::istringstream in(*text);
    std::vector<Camera> cameras;
    std::string line;
    for (std::size_t line_number = 1; std::getline(in, line); ++line_number) {
        const std::vector<std::string> fields = split_fields(line.substr(0, line.find('#')));
        if (fields.empty()) continue;
        const std::string where = path + ":" + std::to_string(line_number);
        if (fields.size() != kPoseFields && fields.size() != kFullFields)
            throw Error(where +
                        ": expected 8 fields (timestamp px py pz qw qx qy qz) or 14 (with fx fy cx cy width "
                        "height), found " +
                        std::to_string(fields.size()));
        std::array<double, kFullFields> v{};
        for (std::size_t i = 0; i < fields.size(); ++i) v[i] = parse_field(where, i, fields[i]);

        Camera camera;
        camera.timestamp = v[0];
        const double norm = std::sqrt(v[4] * v[4] + v[5] * v[5] + v[6] * v[6] + v[7] * v[7]);
        if (!(norm > 0) || !std::isfinite(norm))
            throw Error(where + ": quaternion (qw qx qy qz) has zero or non-finite norm");
        camera.pose = pose_from_quaternion({v[1], v[2], v[3]}, {v[4], v[5], v[6], v[7]});
        if (fields.size() == kFullFields) {
            camera.intrinsics = {
                v[8], v[9], v[10], v[11], image_size(where, "width", v[12]), image_size(where, "height", v[13])};
            validate(camera.intrinsics, where);
        } else {
            camera.intrinsics = defaults;
            validate(camera.intrinsics, where + ": default intrinsics (this line gives none)");
        }
        cameras.push_back(std::move(camera));
    }
    if (in.bad()) throw Error(path + ": read error");
    if (cameras.empty()) throw Error(path + ": no cameras (every line is blank or a comment)");
    return cameras;
}

void write_trajectory(const std::vector<Camera>& cameras, const std::string& path) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path + ": cannot open for writing");
    out << "# timestamp px py pz qw qx qy qz fx fy cx cy width height\n"
           "# camera centre in world coordinates, camera-to-world quaternion, COLMAP axes (+x right, +y down, +z "
           "forward)\n";
    for (const Camera& camera : cameras) {
        const V3 c = camera_centre(camera.pose);
        const std::array<double, 4> q = camera_to_world_quaternion(camera.pose);
        const Intrinsics& k = camera.intrinsics;
        std::string line = format_double(camera.timestamp);
        for (double value : {c[0], c[1], c[2], q[0], q[1], q[2], q[3], k.fx, k.fy, k.cx, k.cy})
            line += ' ' + format_double(value);
        line += ' ' + std::to_string(k.width) + ' ' + std::to_string(k.height) + '\n';
        out << line;
    }
    out.close();
    if (!out) throw Error(path + ": write failed");
}

std::vector<Camera> load_trajectory(const std::string& spec, const Bounds& bounds, const Intrinsics& intrinsics) {
    if (spec.rfind("builtin:", 0) == 0) return make_trajectory(spec, bounds, intrinsics);
    std::string extension = std::filesystem::path(spec).extension().string();
    for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (extension == ".json") return read_cameras_json(spec);
    return read_trajectory(spec, intrinsics);
}

}  // namespace catgs
