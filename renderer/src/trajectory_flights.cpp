// Procedural UAV flights over a scene's bounds: "builtin:survey|orbit|flythrough|hover?...".
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "catgs/builtin_spec.hpp"
#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/trajectory.hpp"
#include "trajectory_detail.hpp"

namespace catgs {

namespace {

using detail::orthonormality_error;
using detail::V3;

double radians(double degrees) {
    return degrees * kPi / 180.0;
}

// Generated poses are orthonormal to rounding; anything worse is a bug.
constexpr double kGeneratedTolerance = 1e-9;

bool is_finite(const Pose& pose) {
    return std::all_of(pose.rotation.begin(), pose.rotation.end(), [](double v) { return std::isfinite(v); }) &&
           std::all_of(pose.translation.begin(), pose.translation.end(), [](double v) { return std::isfinite(v); });
}

constexpr const char* kKinds[] = {"orbit", "survey", "flythrough", "hover"};
// A million frames is over 9 hours at 30 fps, and ~200 MB of cameras.
constexpr std::uint64_t kMaxFrames = 1'000'000;

struct Flight {
    std::string kind;
    double speed = 8.0;  ///< m/s
    double fps = 30.0;
    double altitude = 80.0;  ///< m above the bounds' bottom along up
    double pitch = -45.0;    ///< degrees, negative looks down
    bool pitch_given = false;
    std::uint64_t frames = 300;
    std::uint64_t seed = 1;
    V3 up{0, 0, 1};
};

Flight parse_flight(const std::string& spec) {
    Flight f;
    f.kind = detail::builtin_name(spec);
    if (std::find(std::begin(kKinds), std::end(kKinds), f.kind) == std::end(kKinds)) {
        std::string available;
        for (const char* kind : kKinds) available += (available.empty() ? "" : ", ") + std::string(kind);
        throw Error(spec + ": unknown trajectory kind '" + f.kind + "' (available: " + available + ")");
    }
    const auto params = detail::builtin_params(spec, {"speed", "fps", "altitude", "pitch", "frames", "up", "seed"});
    for (const auto& [key, value] : params) {
        if (key == "frames" || key == "seed") {
            (key == "frames" ? f.frames : f.seed) = detail::spec_integer(spec, key, value);
        } else if (key == "up") {
            if (value == "z")
                f.up = {0, 0, 1};
            else if (value == "y")
                f.up = {0, 1, 0};
            else if (value == "-y")
                f.up = {0, -1, 0};
            else
                throw Error(spec + ": up '" + value + "' must be z, y or -y");
        } else {
            const double number = detail::spec_number(spec, key, value);
            if (key == "speed")
                f.speed = number;
            else if (key == "fps")
                f.fps = number;
            else if (key == "altitude")
                f.altitude = number;
            else {
                f.pitch = number;
                f.pitch_given = true;
            }
        }
    }
    for (const auto& [name, value] : {std::pair{"speed", f.speed}, {"fps", f.fps}, {"altitude", f.altitude}})
        if (!(value > 0)) throw Error(spec + ": " + name + " must be positive");
    if (f.pitch < -90 || f.pitch > 90) throw Error(spec + ": pitch must be in [-90, 90] degrees");
    if (f.frames < 1 || f.frames > kMaxFrames)
        throw Error(spec + ": frames must be in [1, " + std::to_string(kMaxFrames) + "]");
    // Positions along the flight are speed * frame / fps, evaluated in this order: they must
    // stay finite (e.g. fps=1e-308, or speed=1e308 with 3 frames).
    if (!std::isfinite(f.speed * static_cast<double>(f.frames) / f.fps))
        throw Error(spec + ": the flight is too long: speed * frames / fps is not finite");
    return f;
}

// The horizontal frame of the scene: two axes orthogonal to up with e1 x e2 = up, the
// extents along them, and the centre of the bounds lowered to their bottom.
struct Site {
    V3 up, e1, e2;
    V3 centre;
    double extent1 = 0, extent2 = 0;

    V3 at(double a, double b, double height) const { return centre + a * e1 + b * e2 + height * up; }
    V3 horizontal(double a, double b) const { return a * e1 + b * e2; }
};

Site make_site(const std::string& spec, const Bounds& bounds, const V3& up) {
    for (int a = 0; a < 3; ++a)
        if (!std::isfinite(bounds.min[a]) || !std::isfinite(bounds.max[a]) || bounds.min[a] > bounds.max[a])
            throw Error(spec + ": the scene bounds are not finite (or min > max)");
    Site site;
    site.up = up;
    site.e1 = {1, 0, 0};  // up is z, y or -y: never x
    site.e2 = cross(site.up, site.e1);
    V3 size, mid;
    for (int a = 0; a < 3; ++a) {
        size[a] = bounds.max[a] - bounds.min[a];
        mid[a] = 0.5 * (bounds.min[a] + bounds.max[a]);
    }
    site.extent1 = std::abs(dot(size, site.e1));
    site.extent2 = std::abs(dot(size, site.e2));
    // Along up the bottom is the lowest corner: min for up = +axis, max for up = -axis.
    const double bottom = dot(mid, up) - 0.5 * std::abs(dot(size, up));
    site.centre = mid + (bottom - dot(mid, up)) * up;
    return site;
}

void require_extent(const std::string& spec, const Site& site) {
    if (!(site.extent1 > 0 && site.extent2 > 0))
        throw Error(spec + ": the scene bounds have no horizontal extent to fly over");
}

// COLMAP axes from a horizontal heading and a pitch: +x right, +y down in the image, +z
// forward. Built from the heading rather than with look_at so that pitch -90 (nadir) works.
Pose flight_pose(const V3& eye, const V3& heading, double pitch_radians, const V3& up) {
    const V3 right = cross(heading, up);
    const V3 forward = std::cos(pitch_radians) * heading + std::sin(pitch_radians) * up;
    const V3 down = cross(forward, right);
    return pose_from_centre(
        eye, {right[0], down[0], forward[0], right[1], down[1], forward[1], right[2], down[2], forward[2]});
}

// A point of the flight: horizontal offsets (a, b) from the centre and heading angle psi
// in the (e1, e2) plane; pitch in radians.
struct Waypoint {
    double a, b, psi, pitch;
};

// Lawnmower: kSurveyLines lines along the longer axis, a quarter of the shorter extent
// apart and the outer ones half of that inside the edges (an oblique view reaches past its
// line), joined by half circles, so position and heading are continuous. Beyond its end
// the pattern is flown backwards (ping-pong): position stays continuous.
constexpr int kSurveyLines = 4;

std::vector<Waypoint> survey(const Flight& f, const Site& site) {
    const bool e1_long = site.extent1 >= site.extent2;
    const double length = std::max(site.extent1, site.extent2), across = std::min(site.extent1, site.extent2);
    const double spacing = across / kSurveyLines, radius = spacing / 2;
    const double line = length - 2 * radius;  // half circles stay inside the bounds
    const double turn = kPi * radius;
    const double pattern = kSurveyLines * line + (kSurveyLines - 1) * turn;
    std::vector<Waypoint> path;
    for (std::uint64_t i = 0; i < f.frames; ++i) {
        double s = std::fmod(f.speed * static_cast<double>(i) / f.fps, 2 * pattern);
        const bool backwards = s > pattern;
        if (backwards) s = 2 * pattern - s;
        const int leg = std::min(static_cast<int>(s / (line + turn)), kSurveyLines - 1);
        const double in_leg = s - leg * (line + turn);
        const double dir = leg % 2 == 0 ? 1.0 : -1.0;
        const double lane = -across / 2 + (leg + 0.5) * spacing;
        double u, v, du, dv;  // along, across, and the direction of travel
        if (in_leg <= line) {
            u = dir * (in_leg - line / 2);
            v = lane;
            du = dir;
            dv = 0;
        } else {
            const double phi = (in_leg - line) / radius - kPi / 2;  // -pi/2 .. pi/2 around the turn
            u = dir * (line / 2 + radius * std::cos(phi));
            v = lane + radius + radius * std::sin(phi);
            du = -dir * std::sin(phi);
            dv = std::cos(phi);
        }
        if (backwards) {
            du = -du;
            dv = -dv;
        }
        const double a = e1_long ? u : v, b = e1_long ? v : u;
        const double da = e1_long ? du : dv, db = e1_long ? dv : du;
        path.push_back({a, b, std::atan2(db, da), radians(f.pitch)});
    }
    return path;
}

// Counter-clockwise around the centre at 0.6 of the larger extent, facing the centre.
// Unless a pitch is given, the camera looks at the centre at ground level.
constexpr double kOrbitRadiusFraction = 0.6;

std::vector<Waypoint> orbit(const Flight& f, const Site& site) {
    const double radius = kOrbitRadiusFraction * std::max(site.extent1, site.extent2);
    const double pitch = f.pitch_given ? radians(f.pitch) : -std::atan2(f.altitude, radius);
    std::vector<Waypoint> path;
    for (std::uint64_t i = 0; i < f.frames; ++i) {
        const double theta = f.speed / radius * static_cast<double>(i) / f.fps;
        path.push_back({radius * std::cos(theta), radius * std::sin(theta), theta + kPi, pitch});
    }
    return path;
}

// Seeded uniform numbers. The engine's output is fixed by the standard; the standard
// distributions are not, so they are not used.
class Random {
public:
    explicit Random(std::uint64_t seed) : engine_(seed) {}
    double uniform(double lo, double hi) { return lo + (hi - lo) * (static_cast<double>(engine_() >> 11) * 0x1.0p-53); }
    double sign() { return uniform(0, 1) < 0.5 ? -1.0 : 1.0; }

private:
    std::mt19937_64 engine_;
};

// Legs of 4-10 s, each turning by 30-90 degrees either way and changing speed to 0.5-1.5x;
// heading and speed follow their targets smoothly (rate-limited). Leaving the central half
// of the bounds while heading outward turns the flight back toward the centre, on a circle
// of a tenth of the smaller extent and the way round that stays further inside: the loop
// then reaches at most ~85% of the way to the edge.
constexpr double kLegMinSeconds = 4, kLegMaxSeconds = 10;
constexpr double kMinTurnDegrees = 30, kMaxTurnDegrees = 90;
constexpr double kMinSpeedFactor = 0.5, kMaxSpeedFactor = 1.5;
constexpr double kSpeedChangePerSecond = 0.25;  // of the nominal speed: gentle acceleration
constexpr double kSettleDegrees = 20;           // turns ease in over their last 20 degrees
constexpr double kTurnRadiusFraction = 0.1;
constexpr double kInnerFraction = 0.5;
constexpr double kReturnSpreadDegrees = 30;
constexpr double kArrivedDegrees = 1;  // a return turn is over within this of its heading

// How far out, as a fraction of the half extents, a turn of `sweep` radians (positive:
// counter-clockwise) on a circle of radius r starting at (a, b) with heading psi reaches.
constexpr int kArcSamples = 64;

double turn_reach(double a, double b, double psi, double sweep, double r, double half1, double half2) {
    const double side = sweep >= 0 ? 1.0 : -1.0;
    const double centre_a = a - side * r * std::sin(psi), centre_b = b + side * r * std::cos(psi);
    double reach = 0;
    for (int k = 0; k <= kArcSamples; ++k) {
        const double h = psi + sweep * k / kArcSamples;
        reach = std::max({reach, std::abs(centre_a + side * r * std::sin(h)) / half1,
                          std::abs(centre_b - side * r * std::cos(h)) / half2});
    }
    return reach;
}

std::vector<Waypoint> flythrough(const Flight& f, const Site& site) {
    Random random(f.seed);
    const double turn_radius = kTurnRadiusFraction * std::min(site.extent1, site.extent2);
    const double half1 = site.extent1 / 2, half2 = site.extent2 / 2;
    const double inner1 = kInnerFraction * half1, inner2 = kInnerFraction * half2;
    const double dt = 1.0 / f.fps;
    double a = 0, b = 0, psi = random.uniform(-kPi, kPi), factor = 1;
    double target_psi = psi, target_factor = 1, leg_left = 0;
    int return_turn = 0;  ///< +1 / -1 while turning back toward the centre (counter-clockwise / clockwise)
    std::vector<Waypoint> path;
    for (std::uint64_t i = 0; i < f.frames; ++i) {
        path.push_back({a, b, psi, radians(f.pitch)});
        leg_left -= dt;
        if (leg_left <= 0) {
            leg_left = random.uniform(kLegMinSeconds, kLegMaxSeconds);
            target_psi = psi + random.sign() * radians(random.uniform(kMinTurnDegrees, kMaxTurnDegrees));
            target_factor = random.uniform(kMinSpeedFactor, kMaxSpeedFactor);
            return_turn = 0;
        }
        // Per axis: heading for the nearer edge while already past the inner box on that axis.
        const auto outward = [&](double heading) {
            return (std::abs(a) > inner1 && a * std::cos(heading) > 0) ||
                   (std::abs(b) > inner2 && b * std::sin(heading) > 0);
        };
        if (outward(target_psi)) {
            const double home = std::atan2(-b, -a);
            target_psi = home + radians(random.uniform(-kReturnSpreadDegrees, kReturnSpreadDegrees));
            if (outward(target_psi)) target_psi = home;
            leg_left = random.uniform(kLegMinSeconds, kLegMaxSeconds);
            // Turn whichever way keeps the loop further inside: near a corner the shorter
            // way round may sweep through an outward heading.
            const double error = std::remainder(target_psi - psi, 2 * kPi);
            const double left = error > 0 ? error : error + 2 * kPi, right = error < 0 ? error : error - 2 * kPi;
            return_turn = turn_reach(a, b, psi, left, turn_radius, half1, half2) <=
                                  turn_reach(a, b, psi, right, turn_radius, half1, half2)
                              ? 1
                              : -1;
        }
        const double max_change = kSpeedChangePerSecond * dt;
        factor += std::clamp(target_factor - factor, -max_change, max_change);
        const double speed = f.speed * factor;
        const double max_rate = speed / turn_radius;
        double error = std::remainder(target_psi - psi, 2 * kPi);
        if (std::abs(error) < radians(kArrivedDegrees)) return_turn = 0;
        if (error * return_turn < 0) error += return_turn * 2 * kPi;
        // Full rate until the last kSettleDegrees, then easing in; never past the target.
        const double turn = std::clamp(error / radians(kSettleDegrees), -1.0, 1.0) * max_rate * dt;
        psi += std::clamp(turn, -std::abs(error), std::abs(error));
        a += speed * dt * std::cos(psi);
        b += speed * dt * std::sin(psi);
    }
    return path;
}

// Sub-centimetre sway (two sinusoids per axis of kHoverSway each: under 7 mm in all) and a
// slow yaw drift, as a hovering drone's gimbal shows.
constexpr double kHoverSway = 0.002;  // m
constexpr double kMinSwayHz = 0.2, kMaxSwayHz = 0.8;
constexpr double kHoverYawDriftDegrees = 0.2;  // per second

std::vector<Waypoint> hover(const Flight& f) {
    Random random(f.seed);
    std::array<std::array<double, 4>, 2> sway;  // per axis a, b: two frequencies, two phases
    for (auto& axis : sway)
        axis = {random.uniform(kMinSwayHz, kMaxSwayHz), random.uniform(kMinSwayHz, kMaxSwayHz),
                random.uniform(0, 2 * kPi), random.uniform(0, 2 * kPi)};
    const double psi0 = random.uniform(-kPi, kPi);
    const double drift = radians(kHoverYawDriftDegrees) * random.sign();
    std::vector<Waypoint> path;
    for (std::uint64_t i = 0; i < f.frames; ++i) {
        const double t = static_cast<double>(i) / f.fps;
        std::array<double, 2> offset;
        for (int k = 0; k < 2; ++k)
            offset[k] = kHoverSway * (std::sin(2 * kPi * sway[k][0] * t + sway[k][2]) +
                                      std::sin(2 * kPi * sway[k][1] * t + sway[k][3]));
        path.push_back({offset[0], offset[1], psi0 + drift * t, radians(f.pitch)});
    }
    return path;
}

}  // namespace

std::vector<Camera> make_trajectory(const std::string& spec, const Bounds& bounds, const Intrinsics& intrinsics) {
    const Flight f = parse_flight(spec);
    validate(intrinsics, spec + ": intrinsics");
    const Site site = make_site(spec, bounds, f.up);
    std::vector<Waypoint> path;
    if (f.kind == "hover") {
        path = hover(f);
    } else {
        require_extent(spec, site);
        path = f.kind == "orbit" ? orbit(f, site) : f.kind == "survey" ? survey(f, site) : flythrough(f, site);
    }

    std::vector<Camera> cameras;
    cameras.reserve(path.size());
    for (std::size_t i = 0; i < path.size(); ++i) {
        const Waypoint& w = path[i];
        Camera camera;
        camera.intrinsics = intrinsics;
        camera.timestamp = static_cast<double>(i) / f.fps;
        camera.pose = flight_pose(site.at(w.a, w.b, f.altitude), site.horizontal(std::cos(w.psi), std::sin(w.psi)),
                                  w.pitch, site.up);
        if (!is_finite(camera.pose) || orthonormality_error(camera.pose.rotation) > kGeneratedTolerance)
            throw Error(spec + ": camera " + std::to_string(i) +
                        " is not a finite rigid pose (scene bounds too large?)");
        cameras.push_back(std::move(camera));
    }
    return cameras;
}

}  // namespace catgs
