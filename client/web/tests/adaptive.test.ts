import { test } from "node:test";
import assert from "node:assert/strict";
import { AdaptiveQuality, DEFAULT_OPTIONS, LEVELS } from "../src/adaptive";

const FULL_W = 1280, FULL_H = 720;

/** Moves every 16 ms from t0 for durationMs, feeding frames of `latency`; returns the end time. */
function fly(a: AdaptiveQuality, t0: number, durationMs: number, latency: number): number {
  let t = t0;
  for (; t < t0 + durationMs; t += 16) {
    a.onMotion(t);
    a.onFrame(latency);
    a.update(t);
  }
  return t;
}

test("starts at full quality and drops at once when the camera moves", () => {
  const a = new AdaptiveQuality(FULL_W, FULL_H);
  assert.deepEqual(a.resolution(), { width: 1280, height: 720, jpegQuality: LEVELS[0].jpegQuality, level: 0, moving: false });
  assert.equal(a.onMotion(1000), true);
  const r = a.resolution();
  assert.equal(r.level, 1);
  assert.equal(r.width, 960);
  assert.equal(r.height, 540);
  assert.ok(r.jpegQuality < LEVELS[0].jpegQuality);
});

test("comes back to full after stillAfterMs without motion, not before", () => {
  const a = new AdaptiveQuality(FULL_W, FULL_H);
  a.onMotion(1000);
  assert.equal(a.update(1000 + DEFAULT_OPTIONS.stillAfterMs - 1), false);
  assert.equal(a.resolution().level, 1);
  assert.equal(a.update(1000 + DEFAULT_OPTIONS.stillAfterMs), true);
  assert.equal(a.resolution().level, 0);
  assert.equal(a.resolution().width, FULL_W);
});

test("high latency while moving steps down one level per dwell, to the floor and no further", () => {
  const a = new AdaptiveQuality(FULL_W, FULL_H);
  const end = fly(a, 0, 10 * DEFAULT_OPTIONS.minDwellMs, 400);
  const r = a.resolution();
  assert.equal(r.level, LEVELS.length - 1);
  assert.ok(Math.min(r.width, r.height) >= DEFAULT_OPTIONS.minShortSidePx, `${r.width}x${r.height}`);
  assert.ok(end > 0);
});

test("one dwell of high latency changes at most one level (hysteresis in time)", () => {
  const a = new AdaptiveQuality(FULL_W, FULL_H);
  fly(a, 0, DEFAULT_OPTIONS.minDwellMs - 16, 400);
  assert.equal(a.resolution().level, 1);
  fly(a, DEFAULT_OPTIONS.minDwellMs, DEFAULT_OPTIONS.minDwellMs - 16, 400);
  assert.equal(a.resolution().level, 2);
});

test("latency between the thresholds keeps the level (hysteresis band)", () => {
  const a = new AdaptiveQuality(FULL_W, FULL_H);
  fly(a, 0, 3 * DEFAULT_OPTIONS.minDwellMs, 400);
  const level = a.resolution().level;
  const middle = (DEFAULT_OPTIONS.stepDownLatencyMs + DEFAULT_OPTIONS.stepUpLatencyMs) / 2;
  fly(a, 3 * DEFAULT_OPTIONS.minDwellMs, 10 * DEFAULT_OPTIONS.minDwellMs, middle);
  assert.equal(a.resolution().level, level);
});

test("low latency steps back up while moving, never to full while moving", () => {
  const a = new AdaptiveQuality(FULL_W, FULL_H);
  fly(a, 0, 10 * DEFAULT_OPTIONS.minDwellMs, 400);
  fly(a, 10 * DEFAULT_OPTIONS.minDwellMs, 10 * DEFAULT_OPTIONS.minDwellMs, 5);
  assert.equal(a.resolution().level, 1);
});

test("the next motion starts at the level the last one ended at", () => {
  const a = new AdaptiveQuality(FULL_W, FULL_H);
  const end = fly(a, 0, 3 * DEFAULT_OPTIONS.minDwellMs, 400);
  const level = a.resolution().level;
  assert.ok(level > 1);
  a.update(end + 1000);
  assert.equal(a.resolution().level, 0);
  a.onMotion(end + 2000);
  assert.equal(a.resolution().level, level);
});

test("the floor keeps a small window's moving frames at the minimum short side", () => {
  const a = new AdaptiveQuality(390, 300);
  fly(a, 0, 10 * DEFAULT_OPTIONS.minDwellMs, 400);
  const r = a.resolution();
  assert.equal(r.height, DEFAULT_OPTIONS.minShortSidePx);
  assert.equal(r.width, 2 * Math.round((390 * (DEFAULT_OPTIONS.minShortSidePx / 300)) / 2));
});

test("a window smaller than the floor is never scaled down", () => {
  const a = new AdaptiveQuality(160, 120);
  a.onMotion(0);
  assert.deepEqual([a.resolution().width, a.resolution().height], [160, 120]);
});
