// Prints, as JSON, poses computed by catgs_core for the viewer's unit tests (client/web/tests/
// pose.test.ts): the page builds its poses in TypeScript and must send exactly what the server's
// conventions mean, so the expected numbers come from the C++ code the server runs, not from a
// second hand-written derivation. The committed copy is tests/fixtures/pose_table.json; ctest
// runs this tool and tests against its fresh output.
//
// Heading convention shared with trajectory_flights.cpp: e1 = +x, e2 = up x e1, heading(yaw) =
// cos(yaw) e1 + sin(yaw) e2, forward = cos(pitch) heading + sin(pitch) up.
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/constants.hpp"
#include "catgs/scene.hpp"
#include "catgs/trajectory.hpp"

namespace {

using V3 = std::array<double, 3>;

V3 cross(const V3& a, const V3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

void print_array(const double* values, int count) {
    std::printf("[");
    for (int i = 0; i < count; ++i) std::printf("%s%.17g", i ? ", " : "", values[i]);
    std::printf("]");
}

struct UpAxis {
    const char* name;
    V3 up;
};

constexpr UpAxis kUpAxes[] = {{"z", {0, 0, 1}}, {"y", {0, 1, 0}}, {"-y", {0, -1, 0}}};

void print_look_at_rows() {
    const double yaws[] = {0.0, 0.7, 2.5, -1.9};
    const double pitches[] = {-80.0, -45.0, 0.0, 30.0};
    const V3 eye{12.5, -3.25, 40.0};
    bool first = true;
    std::printf("  \"views\": [\n");
    for (const auto& axis : kUpAxes) {
        const V3 e1{1, 0, 0}, e2 = cross(axis.up, e1);
        for (double yaw : yaws)
            for (double pitch_degrees : pitches) {
                const double pitch = pitch_degrees * catgs::kPi / 180.0;
                V3 forward{};
                for (int a = 0; a < 3; ++a)
                    forward[a] = std::cos(pitch) * (std::cos(yaw) * e1[a] + std::sin(yaw) * e2[a]) +
                                 std::sin(pitch) * axis.up[a];
                const V3 target{eye[0] + forward[0], eye[1] + forward[1], eye[2] + forward[2]};
                const auto q = catgs::camera_to_world_quaternion(catgs::look_at(eye, target, axis.up));
                std::printf("%s    {\"up\": \"%s\", \"yaw\": %.17g, \"pitch_degrees\": %.17g, \"eye\": ",
                            first ? "" : ",\n", axis.name, yaw, pitch_degrees);
                print_array(eye.data(), 3);
                std::printf(", \"wxyz\": ");
                print_array(q.data(), 4);
                std::printf("}");
                first = false;
            }
    }
    std::printf("\n  ],\n");
}

// Camera-to-world matrices (row-major, columns = camera axes in world) of unnormalised
// quaternions, as the server builds them from a received Pose.
void print_quaternion_rows() {
    const std::array<double, 4> quaternions[] = {
        {1, 0, 0, 0}, {0.3, -0.5, 0.2, 0.8}, {-0.7, 0.1, 0.6, -0.2}, {2, 1, -3, 0.5}, {0, 0, 0, 1}};
    std::printf("  \"quaternions\": [\n");
    for (std::size_t i = 0; i < std::size(quaternions); ++i) {
        const auto pose = catgs::pose_from_quaternion({0, 0, 0}, quaternions[i]);
        std::array<double, 9> c2w{};
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) c2w[3 * r + c] = pose.rotation[3 * c + r];
        std::printf("    {\"wxyz\": ");
        print_array(quaternions[i].data(), 4);
        std::printf(", \"camera_to_world\": ");
        print_array(c2w.data(), 9);
        std::printf("}%s\n", i + 1 < std::size(quaternions) ? "," : "");
    }
    std::printf("  ],\n");
}

// The built-in orbit the page flies in follow mode, for each up axis.
void print_orbit_rows() {
    catgs::Bounds bounds;
    bounds.min = {-120, -40, -15};
    bounds.max = {200, 90, 60};
    const auto intrinsics = catgs::intrinsics_from_fov(64, 48, 70);
    std::printf("  \"orbits\": [\n");
    bool first = true;
    for (const auto& axis : kUpAxes) {
        const std::string spec = std::string("builtin:orbit?frames=6&speed=25&fps=5&altitude=50&up=") + axis.name;
        const auto cameras = catgs::make_trajectory(spec, bounds, intrinsics);
        std::printf("%s    {\"up\": \"%s\", \"speed\": 25, \"fps\": 5, \"altitude\": 50, \"min\": ", first ? "" : ",\n",
                    axis.name);
        print_array(bounds.min.data(), 3);
        std::printf(", \"max\": ");
        print_array(bounds.max.data(), 3);
        std::printf(", \"cameras\": [");
        for (std::size_t i = 0; i < cameras.size(); ++i) {
            const auto centre = catgs::camera_centre(cameras[i].pose);
            const auto q = catgs::camera_to_world_quaternion(cameras[i].pose);
            std::printf("%s{\"t\": %.17g, \"position\": ", i ? ", " : "", cameras[i].timestamp);
            print_array(centre.data(), 3);
            std::printf(", \"wxyz\": ");
            print_array(q.data(), 4);
            std::printf("}");
        }
        std::printf("]}");
        first = false;
    }
    std::printf("\n  ]\n");
}

}  // namespace

int main() {
    std::printf("{\n");
    print_look_at_rows();
    print_quaternion_rows();
    print_orbit_rows();
    std::printf("}\n");
    return 0;
}
