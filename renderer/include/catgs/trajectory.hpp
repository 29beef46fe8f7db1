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
/// Keys (all optional): speed (m/s), fps, altitude (m above the bounds' bottom),
/// pitch (degrees, negative looks down), frames, up (z, y or -y: the world's up axis),
/// seed. Throws catgs::Error naming any unknown kind, key or bad value.
std::vector<Camera> make_trajectory(const std::string& spec, const Bounds& bounds, const Intrinsics& intrinsics);

/// read_trajectory or make_trajectory, by whether spec starts with "builtin:".
std::vector<Camera> load_trajectory(const std::string& spec, const Bounds& bounds, const Intrinsics& intrinsics);

}  // namespace catgs
