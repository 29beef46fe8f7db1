#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "catgs/camera.hpp"
#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/host_vector.hpp"
#include "catgs/trajectory.hpp"

namespace {

using catgs::Bounds;
using catgs::Camera;
using catgs::cross;
using catgs::distance;
using catgs::dot;
using catgs::Intrinsics;
using catgs::kPi;
using catgs::Pose;
using V3 = catgs::HostVec3;

std::string temp_path(const std::string& name) {
    const std::filesystem::path dir = std::filesystem::path(CATGS_TEST_TMP) / "trajectory";
    std::filesystem::create_directories(dir);
    return (dir / name).string();
}

std::string write_file(const std::string& name, const std::string& text) {
    const std::string path = temp_path(name);
    std::ofstream(path, std::ios::binary) << text;
    return path;
}

V3 to_camera(const Pose& p, const V3& x) {
    const auto& r = p.rotation;
    V3 out;
    for (int i = 0; i < 3; ++i) out[i] = r[3 * i] * x[0] + r[3 * i + 1] * x[1] + r[3 * i + 2] * x[2] + p.translation[i];
    return out;
}

// Camera axis `row` (0 right, 1 down, 2 forward) in world coordinates: a row of R.
V3 axis(const Pose& p, int row) {
    return {p.rotation[3 * row], p.rotation[3 * row + 1], p.rotation[3 * row + 2]};
}

void expect_rigid(const Pose& p, const std::string& what) {
    for (double v : p.rotation) ASSERT_TRUE(std::isfinite(v)) << what;
    for (double v : p.translation) ASSERT_TRUE(std::isfinite(v)) << what;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) ASSERT_NEAR(dot(axis(p, i), axis(p, j)), i == j ? 1.0 : 0.0, 1e-12) << what;
    const V3 x = axis(p, 0), y = axis(p, 1), z = axis(p, 2);
    ASSERT_GT(dot(cross(x, y), z), 0.999) << what << ": not right-handed";
}

template <typename F>
void expect_error(F&& f, const std::vector<std::string>& parts, const std::string& context) {
    try {
        f();
        ADD_FAILURE() << context << ": no error";
    } catch (const catgs::Error& e) {
        const std::string message = e.what();
        for (const auto& part : parts) EXPECT_NE(message.find(part), std::string::npos) << context << ": " << message;
    }
}

// ---------------------------------------------------------------------------------------
// cameras.json

constexpr const char* kCamerasJson = R"([
  {"id": 0, "img_name": "00000", "width": 640, "height": 480,
   "position": [0, 0, -5], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 500, "fy": 510},
  {"id": 1, "img_name": "side", "width": 800, "height": 600,
   "position": [10, 0, 0], "rotation": [[0, 0, -1], [1, 0, 0], [0, -1, 0]], "fx": 400.5, "fy": 400.5}
])";

TEST(CamerasJson, ReadsGraphdecoCameras) {
    const auto cameras = catgs::read_cameras_json(write_file("cameras.json", kCamerasJson));
    ASSERT_EQ(cameras.size(), 2u);

    const Camera& front = cameras[0];
    EXPECT_EQ(front.name, "00000");
    EXPECT_EQ(front.intrinsics.width, 640);
    EXPECT_EQ(front.intrinsics.height, 480);
    EXPECT_EQ(front.intrinsics.fx, 500.0);
    EXPECT_EQ(front.intrinsics.fy, 510.0);
    EXPECT_EQ(front.intrinsics.cx, 320.0);
    EXPECT_EQ(front.intrinsics.cy, 240.0);
    const V3 centre = catgs::camera_centre(front.pose);
    EXPECT_NEAR(distance(centre, {0, 0, -5}), 0.0, 1e-12);
    // Identity camera-to-world at z = -5: the world origin is 5 m ahead on the optical axis.
    const V3 origin = to_camera(front.pose, {0, 0, 0});
    EXPECT_NEAR(origin[0], 0.0, 1e-12);
    EXPECT_NEAR(origin[1], 0.0, 1e-12);
    EXPECT_NEAR(origin[2], 5.0, 1e-12);

    // Columns of the second rotation: right = +y, down = -z, forward = -x (looking back at
    // the origin from x = 10 with z up).
    const Camera& side = cameras[1];
    EXPECT_EQ(side.name, "side");
    EXPECT_NEAR(distance(axis(side.pose, 0), {0, 1, 0}), 0.0, 1e-12);
    EXPECT_NEAR(distance(axis(side.pose, 1), {0, 0, -1}), 0.0, 1e-12);
    EXPECT_NEAR(distance(axis(side.pose, 2), {-1, 0, 0}), 0.0, 1e-12);
    const V3 p = to_camera(side.pose, {0, 2, 1});  // right of and above the origin
    EXPECT_NEAR(p[0], 2.0, 1e-12);
    EXPECT_NEAR(p[1], -1.0, 1e-12);
    EXPECT_NEAR(p[2], 10.0, 1e-12);
    expect_rigid(side.pose, "side");
}

TEST(CamerasJson, ReorthonormalisesRoundedRotations) {
    // Rotation about z by 30 degrees, printed with 4 digits (error ~5e-5).
    const auto cameras = catgs::read_cameras_json(write_file("rounded.json", R"([{"id": 0, "img_name": "a",
        "width": 10, "height": 10, "position": [1, 2, 3], "fx": 5, "fy": 5,
        "rotation": [[0.8660, -0.5, 0], [0.5, 0.8660, 0], [0, 0, 1]]}])"));
    expect_rigid(cameras[0].pose, "rounded");
    EXPECT_NEAR(axis(cameras[0].pose, 0)[0], std::cos(kPi / 6), 1e-4);
    EXPECT_NEAR(distance(catgs::camera_centre(cameras[0].pose), {1, 2, 3}), 0.0, 1e-12);
}

TEST(CamerasJson, ErrorsNameFileCameraAndField) {
    const nlohmann::json good = {{"id", 0},
                                 {"img_name", "a"},
                                 {"width", 640},
                                 {"height", 480},
                                 {"position", {0, 0, 0}},
                                 {"rotation", {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}},
                                 {"fx", 500},
                                 {"fy", 500}};
    // The second camera is the bad one, so the index in the message matters.
    const auto with = [&](const std::string& field, const nlohmann::json& value) {
        nlohmann::json bad = good;
        bad[field] = value;
        return nlohmann::json::array({good, bad}).dump();
    };
    const auto without = [&](const std::string& field) {
        nlohmann::json bad = good;
        bad.erase(field);
        return nlohmann::json::array({good, bad}).dump();
    };
    std::string overflow = with("position", {0, 12345, 0});
    overflow.replace(overflow.find("12345"), 5, "1e999");  // JSON has no infinities: the parser refuses it

    const std::vector<std::pair<std::string, std::vector<std::string>>> cases{
        {"[{\"id\": 0,", {"not JSON (at byte"}},
        {"", {"not JSON"}},
        {overflow, {"not JSON"}},
        {"{}", {"expected a JSON array of cameras, found object"}},
        {"[]", {"contains no cameras"}},
        {nlohmann::json::array({good, 3}).dump(), {"camera 1: expected an object, found number"}},
        {without("fx"), {"camera 1: missing field 'fx'"}},
        {without("img_name"), {"camera 1: missing field 'img_name'"}},
        {without("rotation"), {"camera 1: missing field 'rotation'"}},
        {with("fx", "500"), {"camera 1: field 'fx' must be a number"}},
        {with("fy", -2), {"camera 1: field 'fy' must be positive"}},
        {with("width", 0), {"camera 1: field 'width' must be positive"}},
        {with("height", 480.5), {"camera 1: field 'height' must be an integer"}},
        {with("img_name", 7), {"camera 1: field 'img_name' must be a string"}},
        {with("position", {0, 0}), {"camera 1: field 'position' must be an array of 3 numbers"}},
        {with("position", {0, "x", 0}), {"camera 1: field 'position[1]' must be a number"}},
        {with("rotation", {{1, 0, 0}, {0, 1, 0}}), {"camera 1: field 'rotation' must be a 3x3 array"}},
        {with("rotation", {{1, 0, 0}, {0, 1, 0}, {0, nullptr, 1}}),
         {"camera 1: field 'rotation[2][1]' must be a number"}},
        {with("rotation", {{2, 0, 0}, {0, 2, 0}, {0, 0, 2}}), {"camera 1: field 'rotation' is not orthonormal"}},
        {with("rotation", {{1, 0, 0}, {0, 1, 0}, {0, 0.01, 1}}), {"is not orthonormal"}},
        {with("rotation", {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}}), {"camera 1: field 'rotation' is a reflection"}},
    };
    for (std::size_t i = 0; i < cases.size(); ++i) {
        const std::string path = write_file("bad" + std::to_string(i) + ".json", cases[i].first);
        auto parts = cases[i].second;
        parts.push_back(path + ": ");
        expect_error([&] { catgs::read_cameras_json(path); }, parts, cases[i].first);
    }
    expect_error([] { catgs::read_cameras_json(temp_path("missing.json")); }, {"missing.json: cannot open"}, "missing");
}

// ---------------------------------------------------------------------------------------
// Trajectory files

const Intrinsics kDefaults = catgs::intrinsics_from_fov(1280, 720, 70);

TEST(TrajectoryFile, WriteThenReadReproducesCameras) {
    std::vector<Camera> cameras;
    for (int i = 0; i < 5; ++i) {
        Camera c;
        c.timestamp = 0.1 * i + 1e-9;
        c.pose = catgs::look_at({1e5 + 3.7 * i, -2e6 + 0.3, 40.0 + i}, {1e5, -2e6, 0}, {0, 0, 1});
        c.intrinsics = i % 2 ? kDefaults : catgs::intrinsics_from_fov(640 + i, 480, 50 + i);
        c.intrinsics.cx += 0.25 * i;  // off-centre principal points survive too
        cameras.push_back(c);
    }
    const std::string path = temp_path("round_trip.txt");
    catgs::write_trajectory(cameras, path);
    const auto back = catgs::read_trajectory(path, Intrinsics{});  // invalid defaults: every line has intrinsics
    ASSERT_EQ(back.size(), cameras.size());
    for (std::size_t i = 0; i < cameras.size(); ++i) {
        EXPECT_EQ(back[i].timestamp, cameras[i].timestamp);
        for (int k = 0; k < 9; ++k) EXPECT_NEAR(back[i].pose.rotation[k], cameras[i].pose.rotation[k], 1e-12) << i;
        EXPECT_LT(distance(catgs::camera_centre(back[i].pose), catgs::camera_centre(cameras[i].pose)), 1e-12 * 2e6)
            << i;
        EXPECT_EQ(back[i].intrinsics.fx, cameras[i].intrinsics.fx);
        EXPECT_EQ(back[i].intrinsics.fy, cameras[i].intrinsics.fy);
        EXPECT_EQ(back[i].intrinsics.cx, cameras[i].intrinsics.cx);
        EXPECT_EQ(back[i].intrinsics.cy, cameras[i].intrinsics.cy);
        EXPECT_EQ(back[i].intrinsics.width, cameras[i].intrinsics.width);
        EXPECT_EQ(back[i].intrinsics.height, cameras[i].intrinsics.height);
    }
}

TEST(TrajectoryFile, ReadsCommentsDefaultsAndUnnormalisedQuaternions) {
    const std::string path = write_file("hand.txt",
                                        "# a hand-written path\n"
                                        "\n"
                                        "0.0  0 0 -5  2 0 0 0   # identity, scaled quaternion\n"
                                        "   \t\n"
                                        "0.5  10 0 0  0.5 -0.5 -0.5 0.5  400 410 100 50 200 120\n");
    const auto cameras = catgs::read_trajectory(path, kDefaults);
    ASSERT_EQ(cameras.size(), 2u);
    EXPECT_EQ(cameras[0].timestamp, 0.0);
    EXPECT_EQ(cameras[0].intrinsics.fx, kDefaults.fx);
    EXPECT_EQ(cameras[0].intrinsics.width, kDefaults.width);
    const V3 ahead = to_camera(cameras[0].pose, {0, 0, 0});
    EXPECT_NEAR(distance(ahead, {0, 0, 5}), 0.0, 1e-12);
    expect_rigid(cameras[0].pose, "line 3");

    // (0.5, -0.5, -0.5, 0.5) is the rotation with columns (0, 1, 0), (0, 0, -1), (-1, 0, 0):
    // at x = 10 it looks back at the origin with z up.
    EXPECT_EQ(cameras[1].timestamp, 0.5);
    EXPECT_EQ(cameras[1].intrinsics.fx, 400.0);
    EXPECT_EQ(cameras[1].intrinsics.fy, 410.0);
    EXPECT_EQ(cameras[1].intrinsics.cx, 100.0);
    EXPECT_EQ(cameras[1].intrinsics.cy, 50.0);
    EXPECT_EQ(cameras[1].intrinsics.width, 200);
    EXPECT_EQ(cameras[1].intrinsics.height, 120);
    EXPECT_NEAR(distance(axis(cameras[1].pose, 2), {-1, 0, 0}), 0.0, 1e-12);
    EXPECT_NEAR(distance(axis(cameras[1].pose, 1), {0, 0, -1}), 0.0, 1e-12);
    EXPECT_NEAR(distance(to_camera(cameras[1].pose, {0, 0, 0}), {0, 0, 10}), 0.0, 1e-12);
}

TEST(TrajectoryFile, ErrorsNameFileLineAndProblem) {
    const std::string ok = "0 0 0 0 1 0 0 0\n";
    const std::vector<std::pair<std::string, std::vector<std::string>>> cases{
        {ok + "# c\n0 0 0 0 1 0 0 0 9\n", {":3: expected 8 fields", "or 14", "found 9"}},
        {"0 0 0\n", {":1: expected 8 fields", "found 3"}},
        {ok + "0 abc 0 0 1 0 0 0\n", {":2: field 2 (px) 'abc' is not a number"}},
        {ok + "0 1,5 0 0 1 0 0 0\n", {":2: field 2 (px) '1,5' is not a number"}},
        {ok + "0 0 0 nan 1 0 0 0\n", {":2: field 4 (pz) 'nan' is not finite"}},
        {ok + "inf 0 0 0 1 0 0 0\n", {":2: field 1 (timestamp) 'inf' is not finite"}},
        {ok + "0 0 0 1e999 1 0 0 0\n", {":2: field 4 (pz) '1e999' is out of range"}},
        {ok + "0 0 0 0 0 0 0 0\n", {":2: quaternion (qw qx qy qz) has zero or non-finite norm"}},
        {ok + "0 0 0 0 1 0 0 0 500 500 320 240 0 480\n", {":2: width 0 must be a positive whole number"}},
        {ok + "0 0 0 0 1 0 0 0 500 500 320 240 640 480.5\n", {":2: height 480.5 must be a positive whole number"}},
        {ok + "0 0 0 0 1 0 0 0 0 500 320 240 640 480\n", {":2: focal lengths"}},
        {ok + "0 0 0 0 1 0 0 0 1e30 1e30 8 8 16 16\n",
         {":2: focal length fx 1e+30 gives a field of view of", "degrees across the image's 16 px, below 0.001"}},
        {ok + "0 0 0 0 1 0 0 0 500 1e-30 320 240 640 480\n",
         {":2: focal length fy 1e-30 gives a field of view of 180 degrees across the image's 480 px, above 179.9"}},
        {ok + "0 0 0 0 1 0 0 0 500 500 320 240 100000 100000\n",
         {":2: image size 100000x100000 exceeds the largest supported side, 16384"}},
        {"# only a comment\n\n", {"no cameras"}},
    };
    for (std::size_t i = 0; i < cases.size(); ++i) {
        const std::string path = write_file("bad" + std::to_string(i) + ".txt", cases[i].first);
        auto parts = cases[i].second;
        parts.push_back(path);
        expect_error([&] { catgs::read_trajectory(path, kDefaults); }, parts, cases[i].first);
    }
    // The ends of --fov's range are valid on any image shape (square pixels give the shorter
    // side less than 0.001 degrees at the narrow end).
    for (const auto& [w, h, fov] :
         {std::tuple{160, 90, catgs::kMinFieldOfViewDegrees}, std::tuple{90, 160, catgs::kMinFieldOfViewDegrees},
          std::tuple{160, 90, catgs::kMaxFieldOfViewDegrees}, std::tuple{90, 160, catgs::kMaxFieldOfViewDegrees}})
        EXPECT_NO_THROW(catgs::validate(catgs::intrinsics_from_fov(w, h, fov), "fov range"))
            << w << "x" << h << " at " << fov;
    const std::string no_intrinsics = write_file("defaults.txt", ok);
    expect_error([&] { catgs::read_trajectory(no_intrinsics, Intrinsics{}); },
                 {no_intrinsics + ":1: default intrinsics", "image size 0x0"}, "defaults");
    expect_error([] { catgs::read_trajectory(temp_path("missing.txt"), kDefaults); }, {"missing.txt: cannot open"},
                 "missing");
}

// ---------------------------------------------------------------------------------------
// Procedural flights

struct World {
    std::string up;  ///< the spec's value
    V3 up_vector;
    Bounds bounds;
    double bottom;  ///< lowest coordinate along up
};

// The same 200 x 200 m site, 60 m tall, with z up and in COLMAP's y-down layout.
const std::vector<World> kWorlds{
    {"z", {0, 0, 1}, Bounds{{-100, -100, 0}, {100, 100, 60}}, 0.0},
    {"-y", {0, -1, 0}, Bounds{{-100, -60, -100}, {100, 5, 100}}, -5.0},
};

std::vector<Camera> fly(const std::string& kind, const World& w, const std::string& keys = "") {
    return catgs::make_trajectory("builtin:" + kind + "?up=" + w.up + keys, w.bounds, kDefaults);
}

V3 centre_of(const Camera& c) {
    return catgs::camera_centre(c.pose);
}

// The part of v orthogonal to up.
V3 horizontal_part(const World& w, const V3& v) {
    const double along_up = dot(v, w.up_vector);
    return {v[0] - along_up * w.up_vector[0], v[1] - along_up * w.up_vector[1], v[2] - along_up * w.up_vector[2]};
}

// Horizontal offset of a point from the centre of the site's bounds.
V3 horizontal(const World& w, const V3& p) {
    V3 offset;
    for (int a = 0; a < 3; ++a) offset[a] = p[a] - 0.5 * (w.bounds.min[a] + w.bounds.max[a]);
    return horizontal_part(w, offset);
}

double pitch_degrees(const Camera& c, const World& w) {
    return std::asin(dot(axis(c.pose, 2), w.up_vector)) * 180 / kPi;
}

// Every generated flight: frames, timestamps, intrinsics, rigid poses, +y down in the image.
void expect_common(const std::vector<Camera>& cameras, const World& w, std::size_t frames, double fps,
                   const std::string& what) {
    ASSERT_EQ(cameras.size(), frames) << what;
    for (std::size_t i = 0; i < cameras.size(); ++i) {
        EXPECT_EQ(cameras[i].timestamp, static_cast<double>(i) / fps) << what;
        EXPECT_EQ(cameras[i].intrinsics.fx, kDefaults.fx) << what;
        EXPECT_EQ(cameras[i].intrinsics.width, kDefaults.width) << what;
        expect_rigid(cameras[i].pose, what + " camera " + std::to_string(i));
        EXPECT_LT(dot(axis(cameras[i].pose, 1), w.up_vector), 1e-9) << what << ": image +y points up";
        EXPECT_NEAR(dot(axis(cameras[i].pose, 0), w.up_vector), 0.0, 1e-12) << what << ": horizon tilted";
    }
}

TEST(Flight, SurveyFliesTheLawnmowerAtAltitudeSpeedAndPitch) {
    for (const World& w : kWorlds) {
        const auto cameras = fly("survey", w, "&speed=10&fps=25&altitude=70&pitch=-60&frames=400");
        expect_common(cameras, w, 400, 25, "survey up=" + w.up);
        for (std::size_t i = 0; i < cameras.size(); ++i) {
            EXPECT_NEAR(dot(centre_of(cameras[i]), w.up_vector) - w.bottom, 70.0, 1e-9);
            EXPECT_NEAR(pitch_degrees(cameras[i], w), -60.0, 1e-9);
            if (i == 0) continue;
            const V3 a = centre_of(cameras[i - 1]), b = centre_of(cameras[i]);
            EXPECT_NEAR(distance(a, b), 10.0 / 25, 1e-3 * 10.0 / 25) << i;
            // The camera looks along the direction of travel.
            const V3 step = horizontal_part(w, {b[0] - a[0], b[1] - a[1], b[2] - a[2]});
            const double along = dot(step, axis(cameras[i].pose, 2)) / distance(step, {0, 0, 0});
            EXPECT_GT(along / std::cos(60 * kPi / 180), 0.99) << i;
        }
        // The first line starts a turn radius in from one edge and half a line spacing in
        // from the other: 4 lines 50 m apart, joined by half circles of 25 m.
        const V3 start = horizontal(w, centre_of(cameras[0]));
        for (int a = 0; a < 3; ++a) EXPECT_NEAR(std::abs(start[a]), w.up_vector[a] != 0 ? 0.0 : 75.0, 1e-9) << a;
    }
}

TEST(Flight, SurveyRepeatsBackwardsWithoutJumpsAndCoversTheBounds) {
    for (const World& w : kWorlds) {
        const auto cameras = fly("survey", w, "&speed=50&fps=10&frames=1000");  // 5 km: several passes
        expect_common(cameras, w, 1000, 10, "long survey");
        double lo[3] = {1e9, 1e9, 1e9}, hi[3] = {-1e9, -1e9, -1e9};
        for (std::size_t i = 0; i < cameras.size(); ++i) {
            const V3 h = horizontal(w, centre_of(cameras[i]));
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::min(lo[a], h[a]);
                hi[a] = std::max(hi[a], h[a]);
            }
            if (i > 0) {
                EXPECT_LE(distance(centre_of(cameras[i - 1]), centre_of(cameras[i])), 5.0 + 1e-9) << i;
            }
        }
        // Along the lines the half circles reach the edges; across, the outer lines lie
        // 25 m inside them.
        std::vector<std::pair<double, double>> ranges;
        for (int a = 0; a < 3; ++a)
            if (w.up_vector[a] == 0) ranges.emplace_back(lo[a], hi[a]);
        std::sort(ranges.begin(), ranges.end());
        // Sampled every 5 m, the 25 m half circles' apexes are missed by up to 0.13 m.
        EXPECT_NEAR(ranges[0].first, -100.0, 0.2) << w.up;
        EXPECT_NEAR(ranges[0].second, 100.0, 0.2) << w.up;
        EXPECT_GE(ranges[0].first, -100.0 - 1e-9) << w.up;
        EXPECT_LE(ranges[0].second, 100.0 + 1e-9) << w.up;
        EXPECT_NEAR(ranges[1].first, -75.0, 1e-9) << w.up;
        EXPECT_NEAR(ranges[1].second, 75.0, 1e-9) << w.up;
    }
}

TEST(Flight, OrbitCirclesTheCentreLookingAtIt) {
    for (const World& w : kWorlds) {
        const auto cameras = fly("orbit", w, "&frames=300");
        expect_common(cameras, w, 300, 30, "orbit up=" + w.up);
        V3 target;
        for (int a = 0; a < 3; ++a) target[a] = 0.5 * (w.bounds.min[a] + w.bounds.max[a]);
        for (int a = 0; a < 3; ++a) target[a] += (w.bottom - dot(target, w.up_vector)) * w.up_vector[a];
        for (std::size_t i = 0; i < cameras.size(); ++i) {
            const V3 c = centre_of(cameras[i]);
            EXPECT_NEAR(distance(horizontal(w, c), {0, 0, 0}), 0.6 * 200, 1e-9);
            EXPECT_NEAR(dot(c, w.up_vector) - w.bottom, 80.0, 1e-9);
            const V3 seen = to_camera(cameras[i].pose, target);
            EXPECT_GT(seen[2], 0.0);
            EXPECT_NEAR(seen[0] / seen[2], 0.0, 1e-12);  // on the optical axis
            EXPECT_NEAR(seen[1] / seen[2], 0.0, 1e-12);
            EXPECT_NEAR(pitch_degrees(cameras[i], w), -std::atan2(80.0, 120.0) * 180 / kPi, 1e-9);
            if (i > 0) {
                EXPECT_NEAR(distance(centre_of(cameras[i - 1]), c), 8.0 / 30, 1e-6);
            }
        }
        // 300 frames at 8 m/s on a 120 m circle: 10 s, 2/3 of a radian.
        const V3 first = horizontal(w, centre_of(cameras.front())), last = horizontal(w, centre_of(cameras.back()));
        EXPECT_NEAR(std::acos(dot(first, last) / (120.0 * 120.0)), 8.0 * 299 / 30 / 120, 1e-9);
    }
}

TEST(Flight, OrbitWithExplicitPitchStillFacesTheCentre) {
    for (const World& w : kWorlds) {
        const auto cameras = fly("orbit", w, "&pitch=-20&frames=50");
        expect_common(cameras, w, 50, 30, "orbit pitch");
        V3 target;
        for (int a = 0; a < 3; ++a) target[a] = 0.5 * (w.bounds.min[a] + w.bounds.max[a]);
        for (const Camera& c : cameras) {
            EXPECT_NEAR(pitch_degrees(c, w), -20.0, 1e-9);
            const V3 seen = to_camera(c.pose, target);
            EXPECT_GT(seen[2], 0.0);
            EXPECT_NEAR(seen[0], 0.0, 1e-9);  // yawed toward the centre
        }
    }
}

TEST(Flight, FlythroughTurnsChangesSpeedAndStaysOverTheBounds) {
    for (const World& w : kWorlds)
        for (int seed : {1, 2, 3}) {
            const std::string what = "flythrough up=" + w.up + " seed=" + std::to_string(seed);
            const auto cameras = fly("flythrough", w, "&frames=9000&seed=" + std::to_string(seed));  // 5 minutes
            expect_common(cameras, w, 9000, 30, what);
            double slowest = 1e9, fastest = 0, turning = 0;
            for (std::size_t i = 0; i < cameras.size(); ++i) {
                const V3 c = centre_of(cameras[i]);
                const V3 h = horizontal(w, c);
                for (double v : h) EXPECT_LT(std::abs(v), 100.0) << what << " frame " << i;
                EXPECT_NEAR(dot(c, w.up_vector) - w.bottom, 80.0, 1e-9);
                EXPECT_NEAR(pitch_degrees(cameras[i], w), -45.0, 1e-9);
                if (i == 0) continue;
                const double step = distance(centre_of(cameras[i - 1]), c);
                slowest = std::min(slowest, step);
                fastest = std::max(fastest, step);
                const V3 f0 = axis(cameras[i - 1].pose, 0), f1 = axis(cameras[i].pose, 0);
                turning += std::acos(std::min(1.0, dot(f0, f1)));
            }
            const double nominal = 8.0 / 30;
            EXPECT_GE(slowest, 0.5 * nominal * (1 - 1e-9)) << what;
            EXPECT_LE(fastest, 1.5 * nominal * (1 + 1e-9)) << what;
            EXPECT_GT(fastest / slowest, 1.5) << what;  // real speed changes
            // Legs of 4-10 s with 30-90 degree turns: dozens of turns in 5 minutes.
            EXPECT_GT(turning * 180 / kPi, 30 * 60.0) << what;
        }
    const auto a = fly("flythrough", kWorlds[0], "&seed=1"), b = fly("flythrough", kWorlds[0], "&seed=2");
    EXPECT_GT(distance(centre_of(a.back()), centre_of(b.back())), 1.0);
}

TEST(Flight, HoverIsNearlyStill) {
    for (const World& w : kWorlds) {
        const auto cameras = fly("hover", w, "&pitch=-90");  // nadir works too
        expect_common(cameras, w, 300, 30, "hover");
        const V3 first = centre_of(cameras.front());
        EXPECT_LT(distance(horizontal(w, first), {0, 0, 0}), 0.01);
        for (std::size_t i = 0; i < cameras.size(); ++i) {
            const V3 c = centre_of(cameras[i]);
            EXPECT_LT(distance(c, first), 0.01);
            EXPECT_NEAR(dot(c, w.up_vector) - w.bottom, 80.0, 1e-9);
            EXPECT_NEAR(dot(axis(cameras[i].pose, 2), w.up_vector), -1.0, 1e-12);
            if (i > 0) {
                EXPECT_LT(distance(centre_of(cameras[i - 1]), c), 0.001);
            }
        }
        const double yaw_change = std::acos(dot(axis(cameras.front().pose, 0), axis(cameras.back().pose, 0)));
        // A slow drift: 0.2 degrees per second over 10 s.
        EXPECT_NEAR(yaw_change * 180 / kPi, 0.2 * 299 / 30, 1e-6);
    }
}

TEST(Flight, DefaultsAndLoadTrajectory) {
    const World& w = kWorlds[0];
    const auto cameras = catgs::make_trajectory("builtin:survey", w.bounds, kDefaults);
    expect_common(cameras, w, 300, 30, "defaults");
    EXPECT_NEAR(dot(centre_of(cameras[0]), w.up_vector), 80.0, 1e-9);
    EXPECT_NEAR(pitch_degrees(cameras[0], w), -45.0, 1e-9);
    EXPECT_NEAR(distance(centre_of(cameras[0]), centre_of(cameras[1])), 8.0 / 30, 1e-9);

    const auto loaded = catgs::load_trajectory("builtin:survey", w.bounds, kDefaults);
    ASSERT_EQ(loaded.size(), cameras.size());
    EXPECT_EQ(loaded.back().pose.rotation, cameras.back().pose.rotation);
    const std::string path = temp_path("loaded.txt");
    catgs::write_trajectory(cameras, path);
    const auto from_file = catgs::load_trajectory(path, w.bounds, Intrinsics{});
    ASSERT_EQ(from_file.size(), cameras.size());
    EXPECT_NEAR(distance(centre_of(from_file.back()), centre_of(cameras.back())), 0.0, 1e-9);
}

TEST(Flight, SpecErrorsNameKindKeyAndValue) {
    const Bounds city{{-100, -100, 0}, {100, 100, 60}};
    const std::vector<std::pair<std::string, std::vector<std::string>>> cases{
        {"builtin:spiral",
         {"builtin:spiral: unknown trajectory kind 'spiral' (available: orbit, survey, flythrough, hover)"}},
        {"builtin:survey?fps=0", {"builtin:survey?fps=0: fps must be positive"}},
        {"builtin:orbit?speed=-1", {"speed must be positive"}},
        {"builtin:hover?altitude=0", {"altitude must be positive"}},
        {"builtin:survey?pitch=-91", {"pitch must be in [-90, 90] degrees"}},
        {"builtin:survey?frames=0", {"frames must be in [1, 1000000]"}},
        {"builtin:survey?frames=2000000", {"frames must be in [1, 1000000]"}},
        {"builtin:survey?frames=ten", {"value 'ten' of 'frames' is not a non-negative integer"}},
        {"builtin:survey?speed=fast", {"value 'fast' of 'speed' is not a finite number"}},
        {"builtin:survey?speed=inf", {"value 'inf' of 'speed' is not a finite number"}},
        {"builtin:survey?up=x", {"up 'x' must be z, y or -y"}},
        {"builtin:orbit?radius=5", {"unknown key 'radius'", "speed, fps, altitude, pitch, frames, up, seed"}},
        {"builtin:orbit?speed=1&speed=2", {"duplicate key 'speed'"}},
        {"builtin:orbit?speed", {"'speed' is missing '='"}},
        // Found by fuzzing (fuzz_trajectory_spec): time and distance overflowed to inf, and the
        // survey converted the NaN position along its pattern to int (undefined behaviour).
        {"builtin:survey?speed=1e308&fps=1e-308&frames=2",
         {"the flight is too long: speed * frames / fps is not finite"}},
        {"builtin:hover?speed=1e10&fps=1e-300&frames=2", {"the flight is too long"}},
        {"builtin:survey?speed=1e308&fps=2&frames=3", {"the flight is too long"}},  // speed * 2 overflows
    };
    for (const auto& c : cases) {
        const std::string& spec = c.first;  // not a structured binding: clang 14 cannot capture those
        auto expected = c.second;
        expected.push_back(spec + ": ");
        expect_error([&] { catgs::make_trajectory(spec, city, kDefaults); }, expected, spec);
    }
    expect_error([&] { catgs::make_trajectory("builtin:orbit", city, Intrinsics{}); },
                 {"builtin:orbit: intrinsics: image size"}, "intrinsics");
    const Bounds point{{1, 2, 3}, {1, 2, 3}};
    expect_error([&] { catgs::make_trajectory("builtin:survey", point, kDefaults); },
                 {"builtin:survey: the scene bounds have no horizontal extent"}, "flat bounds");
    EXPECT_EQ(catgs::make_trajectory("builtin:hover", point, kDefaults).size(), 300u);  // needs no extent
    const Bounds broken{{0, 0, std::nan("")}, {1, 1, 1}};
    expect_error([&] { catgs::make_trajectory("builtin:hover", broken, kDefaults); }, {"bounds are not finite"},
                 "nan bounds");
}

}  // namespace
