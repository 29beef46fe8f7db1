// Camera poses in the server's conventions (proto/catgs/v1/catgs.proto, renderer/include/catgs/
// camera.hpp): camera axes +x right, +y down, +z forward (COLMAP/3DGS); a Pose carries the camera
// centre and the camera-to-world rotation as a quaternion (w, x, y, z). The viewer steers with a
// yaw and a pitch about the world's up axis, built exactly as trajectory_flights.cpp builds its
// flights: e1 = +x, e2 = up x e1, heading = cos(yaw) e1 + sin(yaw) e2, forward = cos(pitch)
// heading + sin(pitch) up. tests/pose.test.ts checks these against numbers from catgs_core.

export type Vec3 = [number, number, number];
/** (w, x, y, z) */
export type Quat = [number, number, number, number];
/** Row-major 3x3; for a camera-to-world matrix the columns are the camera axes in world. */
export type Mat3 = [number, number, number, number, number, number, number, number, number];

export type UpAxis = "z" | "y" | "-y";
export const UP_AXES: readonly UpAxis[] = ["z", "y", "-y"];

// Just short of straight down/up: at +-90 degrees the heading still defines the right axis
// (flight_pose is built from the heading), but yaw changes would spin the image about its centre.
export const MAX_PITCH_RADIANS = (89 * Math.PI) / 180;

export function add(a: Vec3, b: Vec3): Vec3 {
  return [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
}
export function sub(a: Vec3, b: Vec3): Vec3 {
  return [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
}
export function scale(a: Vec3, s: number): Vec3 {
  return [a[0] * s, a[1] * s, a[2] * s];
}
export function dot(a: Vec3, b: Vec3): number {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
export function cross(a: Vec3, b: Vec3): Vec3 {
  return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
}
export function length(a: Vec3): number {
  return Math.sqrt(dot(a, a));
}

export function upVector(axis: UpAxis): Vec3 {
  if (axis === "z") return [0, 0, 1];
  return axis === "y" ? [0, 1, 0] : [0, -1, 0];
}

/** The horizontal frame: e1 x e2 = up (never x: up is z, y or -y). */
export function horizontalAxes(axis: UpAxis): { e1: Vec3; e2: Vec3; up: Vec3 } {
  const up = upVector(axis);
  const e1: Vec3 = [1, 0, 0];
  return { e1, e2: cross(up, e1), up };
}

export function heading(yaw: number, axis: UpAxis): Vec3 {
  const { e1, e2 } = horizontalAxes(axis);
  return add(scale(e1, Math.cos(yaw)), scale(e2, Math.sin(yaw)));
}

export function forwardVector(yaw: number, pitch: number, axis: UpAxis): Vec3 {
  return add(scale(heading(yaw, axis), Math.cos(pitch)), scale(upVector(axis), Math.sin(pitch)));
}

/** Camera-to-world matrix of a yaw/pitch view (trajectory_flights.cpp flight_pose). */
export function viewMatrix(yaw: number, pitch: number, axis: UpAxis): Mat3 {
  const h = heading(yaw, axis);
  const up = upVector(axis);
  const right = cross(h, up);
  const forward = forwardVector(yaw, pitch, axis);
  const down = cross(forward, right);
  return [right[0], down[0], forward[0], right[1], down[1], forward[1], right[2], down[2], forward[2]];
}

/** camera.cpp camera_to_world_quaternion: largest pivot, w >= 0. */
export function matrixToQuaternion(m: Mat3): Quat {
  const at = (i: number, j: number) => m[3 * i + j];
  const trace = at(0, 0) + at(1, 1) + at(2, 2);
  let q: Quat;
  if (trace > 0) {
    const s = Math.sqrt(trace + 1) * 2;
    q = [0.25 * s, (at(2, 1) - at(1, 2)) / s, (at(0, 2) - at(2, 0)) / s, (at(1, 0) - at(0, 1)) / s];
  } else if (at(0, 0) > at(1, 1) && at(0, 0) > at(2, 2)) {
    const s = Math.sqrt(1 + at(0, 0) - at(1, 1) - at(2, 2)) * 2;
    q = [(at(2, 1) - at(1, 2)) / s, 0.25 * s, (at(0, 1) + at(1, 0)) / s, (at(0, 2) + at(2, 0)) / s];
  } else if (at(1, 1) > at(2, 2)) {
    const s = Math.sqrt(1 + at(1, 1) - at(0, 0) - at(2, 2)) * 2;
    q = [(at(0, 2) - at(2, 0)) / s, (at(0, 1) + at(1, 0)) / s, 0.25 * s, (at(1, 2) + at(2, 1)) / s];
  } else {
    const s = Math.sqrt(1 + at(2, 2) - at(0, 0) - at(1, 1)) * 2;
    q = [(at(1, 0) - at(0, 1)) / s, (at(0, 2) + at(2, 0)) / s, (at(1, 2) + at(2, 1)) / s, 0.25 * s];
  }
  return q[0] < 0 ? [-q[0], -q[1], -q[2], -q[3]] : q;
}

/** Camera-to-world matrix of a quaternion, normalised first (camera.cpp pose_from_quaternion). */
export function quaternionToMatrix(q: Quat): Mat3 {
  const n = Math.hypot(q[0], q[1], q[2], q[3]);
  if (!(n > 0) || !Number.isFinite(n)) throw new Error("camera quaternion has zero or non-finite norm");
  const [w, x, y, z] = [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
  return [
    1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
    2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
    2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
  ];
}

export function viewQuaternion(yaw: number, pitch: number, axis: UpAxis): Quat {
  return matrixToQuaternion(viewMatrix(yaw, pitch, axis));
}

/** Column `c` of a camera-to-world matrix: 0 right, 1 down, 2 forward. */
export function cameraAxis(m: Mat3, c: 0 | 1 | 2): Vec3 {
  return [m[c], m[3 + c], m[6 + c]];
}

/** The yaw and pitch whose view looks along the quaternion's forward axis (roll is dropped). */
export function yawPitchOf(q: Quat, axis: UpAxis): { yaw: number; pitch: number } {
  const forward = cameraAxis(quaternionToMatrix(q), 2);
  const { e1, e2, up } = horizontalAxes(axis);
  const vertical = Math.max(-1, Math.min(1, dot(forward, up)));
  return { yaw: Math.atan2(dot(forward, e2), dot(forward, e1)), pitch: Math.asin(vertical) };
}

/** Shortest-arc spherical interpolation (for playing trajectories between their samples). */
export function slerp(a: Quat, b: Quat, t: number): Quat {
  let cosine = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
  let bb: Quat = b;
  if (cosine < 0) {
    cosine = -cosine;
    bb = [-b[0], -b[1], -b[2], -b[3]];
  }
  // Nearly parallel: the sine below vanishes, and linear interpolation is exact enough.
  const linearBelow = 1e-6;
  let wa = 1 - t;
  let wb = t;
  if (1 - cosine > linearBelow) {
    const angle = Math.acos(cosine);
    wa = Math.sin((1 - t) * angle) / Math.sin(angle);
    wb = Math.sin(t * angle) / Math.sin(angle);
  }
  const q: Quat = [wa * a[0] + wb * bb[0], wa * a[1] + wb * bb[1], wa * a[2] + wb * bb[2], wa * a[3] + wb * bb[3]];
  const n = Math.hypot(q[0], q[1], q[2], q[3]);
  return [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
}

/** Angle in radians between two rotations. */
export function rotationAngle(a: Quat, b: Quat): number {
  const d = Math.abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]);
  return 2 * Math.acos(Math.min(1, d));
}
