import { test } from "node:test";
import assert from "node:assert/strict";
import { parseTrajectory, sampleAt } from "../src/trajectory";
import { Backoff, BASE_MS, MAX_MS } from "../src/backoff";
import { percentile, RateMeter } from "../src/stats";

const FILE = `# timestamp px py pz qw qx qy qz [fx fy cx cy width height]
0   0 0 10   1 0 0 0
1.0 10 0 10  0 0 0 2   # unnormalised: the page normalises, as the server does

2.0 10 10 10 1 0 0 0 500 500 320 240 640 480
`;

test("parses the catgs trajectory format: comments, blanks, optional intrinsics, normalised quaternions", () => {
  const path = parseTrajectory(FILE, "flight.txt");
  assert.equal(path.length, 3);
  assert.deepEqual(path[1].position, [10, 0, 10]);
  assert.deepEqual(path[1].orientation, [0, 0, 0, 1]);
  assert.equal(path[2].t, 2);
});

test("bad lines name the file, the line and the problem", () => {
  assert.throws(() => parseTrajectory("0 1 2 3 1 0 0\n", "a.txt"), /^Error: a\.txt:1: expected 8 or 14 numbers .* found 7$/);
  assert.throws(() => parseTrajectory("0 0 0 0 1 0 0 0\n1 0 x 0 1 0 0 0\n", "b.txt"), /b\.txt:2: field 3 "x" is not a finite number/);
  assert.throws(() => parseTrajectory("0 0 0 0 0 0 0 0\n", "c.txt"), /c\.txt:1: the quaternion \(qw qx qy qz\) is zero/);
  assert.throws(() => parseTrajectory("1 0 0 0 1 0 0 0\n1 0 0 0 1 0 0 0\n", "d.txt"), /d\.txt:2: timestamp 1 must be greater than the previous line's 1/);
  assert.throws(() => parseTrajectory("# nothing\n\n", "e.txt"), /e\.txt: no camera lines/);
  assert.throws(() => parseTrajectory("0 0 0 0 1 0 0 0 nan 1 1 1 1 1\n", "f.txt"), /f\.txt:1: field 9 "nan"/);
});

test("sampling interpolates positions and rotations and loops over the duration", () => {
  const path = parseTrajectory(FILE, "flight.txt");
  const mid = sampleAt(path, 0.5);
  assert.deepEqual(mid.position, [5, 0, 10]);
  const half = Math.SQRT1_2;
  mid.orientation.forEach((v, i) => assert.ok(Math.abs(v - [half, 0, 0, half][i]) < 1e-12, `${mid.orientation}`));
  assert.deepEqual(sampleAt(path, 2.5).position, sampleAt(path, 0.5).position);
  assert.deepEqual(sampleAt(path, 1.5).position, [10, 5, 10]);
});

test("backoff doubles from BASE_MS up to MAX_MS and restarts after reset", () => {
  const b = new Backoff(() => 0.5);  // no jitter
  const delays = Array.from({ length: 7 }, () => b.next());
  assert.deepEqual(delays, [BASE_MS, 2 * BASE_MS, 4 * BASE_MS, 8 * BASE_MS, MAX_MS, MAX_MS, MAX_MS]);
  b.reset();
  assert.equal(b.next(), BASE_MS);
  const jittered = new Backoff(() => 1);
  assert.ok(jittered.next() > BASE_MS);
});

test("percentiles by nearest rank and a sliding frame rate", () => {
  const values = [5, 1, 4, 2, 3, 10, 9, 8, 7, 6];
  assert.equal(percentile(values, 50), 5);
  assert.equal(percentile(values, 90), 9);
  assert.equal(percentile(values, 99), 10);
  assert.ok(Number.isNaN(percentile([], 50)));
  const r = new RateMeter(1000);
  for (let t = 0; t <= 2000; t += 100) r.add(t);
  assert.equal(r.rate(2000), 11);
  assert.equal(r.rate(5000), 0);
});
