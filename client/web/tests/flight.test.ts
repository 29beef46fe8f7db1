import { test } from "node:test";
import assert from "node:assert/strict";
import { FlightControl } from "../src/flight";
import { MAX_PITCH_RADIANS } from "../src/pose";

const near = (a: number, b: number) => Math.abs(a - b) < 1e-9;

test("W flies along the horizontal heading at the speed, also when looking down", () => {
  const c = new FlightControl({ position: [0, 0, 50], yaw: Math.PI / 2, pitch: -0.8 }, 10, "z");
  c.pressed.add("KeyW");
  assert.equal(c.step(0.5), true);
  const [x, y, z] = c.state.position;
  assert.ok(near(x, 0) && near(y, 5) && near(z, 50), `${c.state.position}`);
  assert.ok(near(c.velocity[1], 10));
});

test("D strafes right of the heading and E climbs along up (-y up too)", () => {
  const c = new FlightControl({ position: [0, 0, 0], yaw: 0, pitch: 0 }, 4, "-y");
  c.pressed.add("KeyD");
  c.pressed.add("KeyE");
  c.step(1);
  // up = -y, e1 = +x, right = heading x up = x x (-y) = -z.
  assert.deepEqual(c.state.position.map((v) => Math.round(v * 1e9) / 1e9), [0, -4, -4]);
});

test("nothing pressed, nothing dragged: the pose does not change", () => {
  const c = new FlightControl({ position: [1, 2, 3], yaw: 0.3, pitch: -0.2 }, 10, "z");
  assert.equal(c.step(0.016), false);
  assert.deepEqual(c.state.position, [1, 2, 3]);
});

test("a drag turns: right drag yaws clockwise seen from above, down drag pitches down, clamped", () => {
  const c = new FlightControl({ position: [0, 0, 0], yaw: 0, pitch: 0 }, 10, "z");
  c.look(100, 50);
  assert.equal(c.step(0.016), true);
  assert.ok(c.state.yaw < 0 && c.state.pitch < 0);
  assert.ok(c.angularSpeed > 0);
  c.look(0, 100000);
  c.step(0.016);
  assert.equal(c.state.pitch, -MAX_PITCH_RADIANS);
});

test("the wheel scales the speed by notches, within its bounds", () => {
  const c = new FlightControl({ position: [0, 0, 0], yaw: 0, pitch: 0 }, 10, "z");
  c.wheel(-100);
  assert.ok(near(c.speed, 12.5));
  c.wheel(200);
  assert.ok(near(c.speed, 8));
  c.wheel(1e6);
  assert.equal(c.speed, 0.2);
  c.wheel(-1e6);
  assert.equal(c.speed, 2000);
});

test("two fingers: spreading moves forward; the scene follows a pan", () => {
  const c = new FlightControl({ position: [0, 0, 0], yaw: 0, pitch: 0 }, 50, "z");
  c.touchMove(100, 0, 0);
  c.step(0.016);
  assert.ok(c.state.position[0] > 0 && near(c.state.position[1], 0) && near(c.state.position[2], 0));
  const before = [...c.state.position];
  c.touchMove(0, -20, 30);
  c.step(0.016);
  // The scene follows the fingers: a pan to the left moves the camera right (heading x up = -y),
  // a pan down moves it up.
  assert.ok(c.state.position[1] < before[1] && c.state.position[2] > before[2], `${before} -> ${c.state.position}`);
});
