// The page's poses against catgs_core's: the table comes from client/web/tools/pose_table.cpp,
// fresh from the built tool when ctest passes CATGS_POSE_TABLE_TOOL, else the committed copy.
import { test } from "node:test";
import assert from "node:assert/strict";
import { execFileSync } from "node:child_process";
import { readFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { Mat3, Quat, quaternionToMatrix, UpAxis, Vec3, viewQuaternion, yawPitchOf, matrixToQuaternion, viewMatrix } from "../src/pose";
import { orbitFlight } from "../src/trajectory";

interface Table {
  views: { up: UpAxis; yaw: number; pitch_degrees: number; wxyz: Quat }[];
  quaternions: { wxyz: Quat; camera_to_world: Mat3 }[];
  orbits: { up: UpAxis; speed: number; fps: number; altitude: number; min: Vec3; max: Vec3;
            cameras: { t: number; position: Vec3; wxyz: Quat }[] }[];
}

const tool = process.env.CATGS_POSE_TABLE_TOOL;
const table: Table = JSON.parse(tool ? execFileSync(tool, { encoding: "utf8" })
  : readFileSync(join(dirname(fileURLToPath(import.meta.url)), "pose_table.json"), "utf8"));

// Both sides compute in double with the same formulas; what may differ is the order of a few
// roundings (and libm's last bit).
const TOLERANCE = 1e-12;

function close(actual: readonly number[], expected: readonly number[], what: string): void {
  assert.equal(actual.length, expected.length, what);
  actual.forEach((v, i) => assert.ok(Math.abs(v - expected[i]) <= TOLERANCE,
    `${what}[${i}]: page ${v}, catgs_core ${expected[i]} (all: page ${actual}, catgs_core ${expected})`));
}

test("the table is the one expected (not empty)", () => {
  assert.equal(table.views.length, 48);
  assert.equal(table.quaternions.length, 5);
  assert.equal(table.orbits.length, 3);
});

test("yaw/pitch views give catgs_core's look_at quaternions for every up axis", () => {
  for (const v of table.views) {
    const q = viewQuaternion(v.yaw, (v.pitch_degrees * Math.PI) / 180, v.up);
    close(q, v.wxyz, `up ${v.up} yaw ${v.yaw} pitch ${v.pitch_degrees}`);
  }
});

test("quaternions map to catgs_core's camera-to-world matrices (normalised, w x y z order)", () => {
  for (const row of table.quaternions) close(quaternionToMatrix(row.wxyz), row.camera_to_world, `q ${row.wxyz}`);
});

test("matrixToQuaternion inverts quaternionToMatrix up to sign, w >= 0", () => {
  for (const row of table.quaternions) {
    const q = matrixToQuaternion(quaternionToMatrix(row.wxyz));
    assert.ok(q[0] >= 0);
    close(quaternionToMatrix(q), row.camera_to_world, `round trip of ${row.wxyz}`);
  }
});

test("the built-in orbit matches make_trajectory(builtin:orbit)", () => {
  for (const o of table.orbits) {
    const path = orbitFlight({ min: o.min, max: o.max },
                             { up: o.up, speed: o.speed, fps: o.fps, altitude: o.altitude, frames: o.cameras.length });
    assert.equal(path.length, o.cameras.length);
    path.forEach((c, i) => {
      assert.ok(Math.abs(c.t - o.cameras[i].t) <= TOLERANCE);
      close(c.position, o.cameras[i].position, `orbit up ${o.up} camera ${i} position`);
      close(c.orientation, o.cameras[i].wxyz, `orbit up ${o.up} camera ${i} orientation`);
    });
  }
});

test("camera axes: +x right, +y down (world up is image up), +z forward", () => {
  const m = viewMatrix(0.3, -0.5, "z");
  const down: Vec3 = [m[1], m[4], m[7]];
  assert.ok(down[2] < 0, "image down points against world up");
  const forward: Vec3 = [m[2], m[5], m[8]];
  assert.ok(Math.abs(forward[2] - Math.sin(-0.5)) < 1e-15, "pitch -0.5 looks down");
});

test("yawPitchOf recovers the view's yaw and pitch", () => {
  for (const up of ["z", "y", "-y"] as UpAxis[]) {
    const { yaw, pitch } = yawPitchOf(viewQuaternion(2.0, -0.7, up), up);
    assert.ok(Math.abs(yaw - 2.0) < 1e-12 && Math.abs(pitch + 0.7) < 1e-12, `${up}: ${yaw} ${pitch}`);
  }
});
