// Camera paths: graphdeco cameras.json, our own trajectory text format, and procedural UAV
// flights over a scene's bounds.
//
// Trajectory file format (one camera per line, '#' starts a comment, blank lines ignored):
//   timestamp  px py pz  qw qx qy qz  [fx fy cx cy width height]
// p is the camera centre in world coordinates, q the camera-to-world rotation as a unit
// quaternion (w, x, y, z) in the COLMAP camera convention (+x right, +y down, +z forward).
// The optional intrinsics override the defaults given by the caller for that line.
#pragma once

#include <string>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/scene.hpp"

namespace catgs {

/// graphdeco cameras.json: a list of {id, img_name, width, height, position, rotation, fx, fy};
/// rotation is camera-to-world (columns are the camera axes), principal point at the centre.
std::vector<Camera> read_cameras_json(const std::string& path);

std::vector<Camera> read_trajectory(const std::string& path, const Intrinsics& defaults);
void write_trajectory(const std::vector<Camera>& cameras, const std::string& path);

/// Procedural UAV flight, spec "builtin:KIND?key=value&...". Kinds:
///   orbit      circle around the scene centre
///   survey     lawnmower pattern over the bounds
///   flythrough a path with turns and speed changes
///   hover      a nearly still camera with small jitter
/// Keys (all optional, defaults in brackets): speed [8] (m/s), fps [30], altitude [80] (m
/// above the lowest point of the bounds along up: for up=-y that is bounds.max.y),
/// pitch [-45] (degrees, negative looks down; for orbit an explicit pitch overrides the
/// look-at pitch, the yaw still faces the centre), frames [300], up [z] (z, y or -y: the
/// world's up axis), seed [1]. Defaults are in metres for city-sized scenes: small scenes
/// need altitude and speed. Throws catgs::Error naming any unknown kind, key or bad value.
std::vector<Camera> make_trajectory(const std::string& spec, const Bounds& bounds, const Intrinsics& intrinsics);

/// make_trajectory for "builtin:..." specs, read_cameras_json for a .json path (its own
/// intrinsics), read_trajectory otherwise.
std::vector<Camera> load_trajectory(const std::string& spec, const Bounds& bounds, const Intrinsics& intrinsics);

}  // namespace catgs
