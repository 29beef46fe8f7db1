// Rolling numbers for the HUD and the node client: frames per second over a sliding window and
// latency percentiles.

export class RateMeter {
  private readonly times: number[] = [];
  constructor(private readonly windowMs = 1000) {}

  add(nowMs: number): void {
    this.times.push(nowMs);
    this.trim(nowMs);
  }

  rate(nowMs: number): number {
    this.trim(nowMs);
    return (this.times.length * 1000) / this.windowMs;
  }

  private trim(nowMs: number): void {
    while (this.times.length > 0 && nowMs - this.times[0] > this.windowMs) this.times.shift();
  }
}

/** Nearest-rank percentile (p in [0, 100]) of unsorted values; NaN when empty. */
export function percentile(values: readonly number[], p: number): number {
  if (values.length === 0) return NaN;
  const sorted = [...values].sort((a, b) => a - b);
  const rank = Math.max(1, Math.ceil((p / 100) * sorted.length));
  return sorted[Math.min(sorted.length, rank) - 1];
}

/** The last `capacity` values. */
export class Recent {
  readonly values: number[] = [];
  constructor(private readonly capacity: number) {}
  add(v: number): void {
    this.values.push(v);
    if (this.values.length > this.capacity) this.values.shift();
  }
  mean(): number {
    return this.values.length === 0 ? NaN : this.values.reduce((a, b) => a + b, 0) / this.values.length;
  }
}
