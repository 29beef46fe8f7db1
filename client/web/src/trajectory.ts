// Camera paths for follow mode: the trajectory text format of catgs-client --trajectory
// (renderer/include/catgs/trajectory.hpp) and the built-in orbit of make_trajectory.
import { add, horizontalAxes, Quat, scale, slerp, UpAxis, Vec3, viewQuaternion, dot } from "./pose";

export interface PathCamera {
  /** seconds */
  t: number;
  position: Vec3;
  orientation: Quat;
}

export interface SceneBounds {
  min: Vec3;
  max: Vec3;
}

// Each line: timestamp px py pz qw qx qy qz [fx fy cx cy width height]; the page renders at its
// own resolution, so the optional intrinsics are read and checked but not used.
const POSE_FIELDS = 8;
const WITH_INTRINSICS_FIELDS = 14;

/** Parses a trajectory file; errors name the file, the line and the problem. */
export function parseTrajectory(text: string, fileName: string): PathCamera[] {
  const cameras: PathCamera[] = [];
  const lines = text.split(/\r?\n/);
  lines.forEach((raw, index) => {
    const where = `${fileName}:${index + 1}`;
    const line = raw.replace(/#.*/, "").trim();
    if (line === "") return;
    const fields = line.split(/\s+/);
    if (fields.length !== POSE_FIELDS && fields.length !== WITH_INTRINSICS_FIELDS)
      throw new Error(`${where}: expected ${POSE_FIELDS} or ${WITH_INTRINSICS_FIELDS} numbers ` +
                      `(timestamp px py pz qw qx qy qz [fx fy cx cy width height]), found ${fields.length}`);
    const numbers = fields.map((field, column) => {
      const value = Number(field);
      if (!Number.isFinite(value)) throw new Error(`${where}: field ${column + 1} "${field}" is not a finite number`);
      return value;
    });
    const [t, px, py, pz, qw, qx, qy, qz] = numbers;
    if (Math.hypot(qw, qx, qy, qz) === 0) throw new Error(`${where}: the quaternion (qw qx qy qz) is zero`);
    const previous = cameras[cameras.length - 1];
    if (previous && !(t > previous.t))
      throw new Error(`${where}: timestamp ${t} must be greater than the previous line's ${previous.t}`);
    cameras.push({ t, position: [px, py, pz], orientation: normalised([qw, qx, qy, qz]) });
  });
  if (cameras.length === 0) throw new Error(`${fileName}: no camera lines (only comments or blank lines)`);
  return cameras;
}

function normalised(q: Quat): Quat {
  const n = Math.hypot(q[0], q[1], q[2], q[3]);
  return [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
}

export interface OrbitOptions {
  up: UpAxis;
  /** m/s along the circle */
  speed: number;
  /** m above the bounds' bottom along up */
  altitude: number;
  fps: number;
  frames: number;
}

// trajectory_flights.cpp: 0.6 of the larger horizontal extent, facing the centre, looking at
// the centre at ground level.
const ORBIT_RADIUS_FRACTION = 0.6;

/** make_trajectory("builtin:orbit?...") for the same bounds and options. */
export function orbitFlight(bounds: SceneBounds, o: OrbitOptions): PathCamera[] {
  const { e1, e2, up } = horizontalAxes(o.up);
  const size: Vec3 = [bounds.max[0] - bounds.min[0], bounds.max[1] - bounds.min[1], bounds.max[2] - bounds.min[2]];
  const mid: Vec3 = [(bounds.max[0] + bounds.min[0]) / 2, (bounds.max[1] + bounds.min[1]) / 2,
                     (bounds.max[2] + bounds.min[2]) / 2];
  const bottom = dot(mid, up) - 0.5 * Math.abs(dot(size, up));
  const centre = add(mid, scale(up, bottom - dot(mid, up)));
  const radius = ORBIT_RADIUS_FRACTION * Math.max(Math.abs(dot(size, e1)), Math.abs(dot(size, e2)));
  if (!(radius > 0)) throw new Error("orbit: the scene bounds have no horizontal extent to fly over");
  const pitch = -Math.atan2(o.altitude, radius);
  const cameras: PathCamera[] = [];
  for (let i = 0; i < o.frames; ++i) {
    const theta = ((o.speed / radius) * i) / o.fps;
    const position = add(add(centre, scale(e1, radius * Math.cos(theta))),
                         add(scale(e2, radius * Math.sin(theta)), scale(up, o.altitude)));
    const yaw = theta + Math.PI;
    cameras.push({ t: i / o.fps, position, orientation: viewQuaternion(yaw, pitch, o.up) });
  }
  return cameras;
}

/** The camera at time t (seconds, wrapped to the path's duration): linear position, slerp. */
export function sampleAt(path: PathCamera[], t: number): PathCamera {
  if (path.length === 1) return path[0];
  const start = path[0].t;
  const duration = path[path.length - 1].t - start;
  const local = start + (((t % duration) + duration) % duration);
  let i = 0;
  while (i + 2 < path.length && path[i + 1].t <= local) ++i;
  const a = path[i];
  const b = path[i + 1];
  const f = Math.min(1, Math.max(0, (local - a.t) / (b.t - a.t)));
  return {
    t: local,
    position: add(scale(a.position, 1 - f), scale(b.position, f)),
    orientation: slerp(a.orientation, b.orientation, f),
  };
}
