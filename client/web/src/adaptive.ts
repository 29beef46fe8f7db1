// Adaptive quality: a lower resolution and JPEG quality while the camera moves, full ones once
// it has been still for STILL_AFTER_MS. While moving, the level follows the pose-to-frame
// latency with hysteresis (separate step-down and step-up thresholds, a minimum dwell between
// changes, a minimum number of samples) and a floor, so it neither flaps nor locks at a tiny
// size. Pure logic, driven by the caller's clock, so tests/adaptive.test.ts can step it.

export interface QualityLevel {
  /** of the full resolution, per axis */
  scale: number;
  jpegQuality: number;
}

// Level 0 is full quality; the others are the moving levels, coarser as the index grows. 90 is
// visually lossless for these scenes; the moving levels trade sharpness for latency, which an
// eye in motion notices less.
export const LEVELS: readonly QualityLevel[] = [
  { scale: 1, jpegQuality: 90 },
  { scale: 0.75, jpegQuality: 75 },
  { scale: 0.5, jpegQuality: 65 },
  { scale: 0.35, jpegQuality: 55 },
];

export interface AdaptiveOptions {
  /** still this long: full quality (the "about 0.2 s") */
  stillAfterMs: number;
  /** moving, latency above this: one level coarser */
  stepDownLatencyMs: number;
  /** moving, latency below this: one level finer (well below stepDown: hysteresis) */
  stepUpLatencyMs: number;
  /** no level change within this time of the last, except the instant drop when motion starts and full quality when still */
  minDwellMs: number;
  /** latency samples at a level before it may change */
  minSamples: number;
  /** the floor: the shorter image side never goes below this (unless the full size does) */
  minShortSidePx: number;
}

export const DEFAULT_OPTIONS: AdaptiveOptions = {
  stillAfterMs: 200,
  // A tenth of a second is where a flown camera starts to feel attached to rubber bands.
  stepDownLatencyMs: 100,
  stepUpLatencyMs: 45,
  minDwellMs: 700,
  minSamples: 4,
  minShortSidePx: 180,
};

// Weight of a new latency sample: about the last five frames.
const LATENCY_SMOOTHING = 0.3;
const FIRST_MOVING_LEVEL = 1;

export interface Resolution {
  width: number;
  height: number;
  jpegQuality: number;
  level: number;
  moving: boolean;
}

export class AdaptiveQuality {
  private level = 0;
  private movingLevel = FIRST_MOVING_LEVEL;
  private lastMotionMs = -Infinity;
  private lastChangeMs = -Infinity;
  private latencyMs = 0;
  private samples = 0;

  constructor(private fullWidth: number, private fullHeight: number,
              private readonly options: AdaptiveOptions = DEFAULT_OPTIONS) {}

  setFullSize(width: number, height: number): void {
    this.fullWidth = width;
    this.fullHeight = height;
  }

  /** The camera moved at `nowMs`. Returns true when the level changed. */
  onMotion(nowMs: number): boolean {
    this.lastMotionMs = nowMs;
    if (this.level !== 0) return false;
    return this.setLevel(this.movingLevel, nowMs);
  }

  /** A frame arrived with this pose-to-frame latency. */
  onFrame(latencyMs: number): void {
    this.latencyMs = this.samples === 0 ? latencyMs : this.latencyMs + LATENCY_SMOOTHING * (latencyMs - this.latencyMs);
    ++this.samples;
  }

  /** Call on every tick. Returns true when the level changed. */
  update(nowMs: number): boolean {
    if (this.level === 0) return false;
    if (nowMs - this.lastMotionMs >= this.options.stillAfterMs) return this.setLevel(0, nowMs);
    if (this.samples < this.options.minSamples || nowMs - this.lastChangeMs < this.options.minDwellMs) return false;
    if (this.latencyMs > this.options.stepDownLatencyMs && this.level + 1 < LEVELS.length && !this.atFloor())
      return this.setLevel(this.level + 1, nowMs);
    if (this.latencyMs < this.options.stepUpLatencyMs && this.level > FIRST_MOVING_LEVEL)
      return this.setLevel(this.level - 1, nowMs);
    return false;
  }

  resolution(): Resolution {
    const { width, height } = this.sizeAt(this.level);
    return { width, height, jpegQuality: LEVELS[this.level].jpegQuality, level: this.level, moving: this.level !== 0 };
  }

  private atFloor(): boolean {
    const next = this.sizeAt(this.level + 1);
    const current = this.sizeAt(this.level);
    return next.width === current.width && next.height === current.height;
  }

  private sizeAt(level: number): { width: number; height: number } {
    const shortSide = Math.min(this.fullWidth, this.fullHeight);
    const floorScale = Math.min(1, this.options.minShortSidePx / shortSide);
    const s = Math.max(LEVELS[level].scale, floorScale);
    // Even sizes: 4:2:0 JPEG works on 2x2 blocks.
    const even = (v: number) => Math.max(2, 2 * Math.round((v * s) / 2));
    return { width: even(this.fullWidth), height: even(this.fullHeight) };
  }

  private setLevel(level: number, nowMs: number): boolean {
    if (level === this.level) return false;
    this.level = level;
    if (level !== 0) this.movingLevel = level;
    this.lastChangeMs = nowMs;
    this.samples = 0;
    return true;
  }
}
