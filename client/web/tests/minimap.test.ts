import { test } from "node:test";
import assert from "node:assert/strict";
import { viewFootprint, groundHeightOf } from "../src/minimap";
import { viewMatrix } from "../src/pose";

test("looking straight down, the footprint is the image rectangle scaled by the height", () => {
  const height = 100, fov = 90, aspect = 2;
  // Pitch -90 degrees: forward = -up; the heading (yaw 0: +x) is the image's up direction.
  const corners = viewFootprint([10, 20, 5 + height], viewMatrix(0, -Math.PI / 2, "z"), fov, aspect, 5, "z", 1e6);
  const halfAcross = height * Math.tan((fov * Math.PI) / 360);
  const halfAlong = halfAcross / aspect;
  const expected = [[10 + halfAlong, 20 + halfAcross], [10 + halfAlong, 20 - halfAcross],
                    [10 - halfAlong, 20 - halfAcross], [10 - halfAlong, 20 + halfAcross]];
  corners.forEach((c, i) => {
    assert.ok(Math.abs(c[0] - expected[i][0]) < 1e-9 && Math.abs(c[1] - expected[i][1]) < 1e-9,
              `corner ${i}: ${c} expected ${expected[i]}`);
    assert.ok(Math.abs(c[2] - 5) < 1e-9, "on the ground");
  });
});

test("rays above the horizon stop at maxDistance", () => {
  const corners = viewFootprint([0, 0, 50], viewMatrix(0, 0, "z"), 70, 16 / 9, 0, "z", 300);
  // Level view: the top corners look up and never reach the ground.
  for (const c of [corners[0], corners[1]]) assert.ok(Math.abs(Math.hypot(c[0], c[1], c[2] - 50) - 300) < 1e-9);
  for (const c of [corners[2], corners[3]]) assert.ok(Math.abs(c[2]) < 1e-9, "bottom corners reach the ground");
});

test("the ground is the bottom of the bounds along up, also for -y up", () => {
  const bounds = { min: [0, -30, 0] as [number, number, number], max: [10, 40, 5] as [number, number, number] };
  assert.equal(groundHeightOf(bounds, "z"), 0);
  assert.equal(groundHeightOf(bounds, "-y"), -40);
});
