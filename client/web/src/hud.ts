// The HUD's numbers: what the last frames cost and what the viewer is showing.
import type { Frame } from "../gen/catgs/v1/catgs_pb";
import { LEVELS, Resolution } from "./adaptive";
import { percentile, RateMeter, Recent } from "./stats";

// Frames the averages and percentiles are taken over: about two seconds at 30 fps.
const RECENT_FRAMES = 60;

export class HudModel {
  readonly rate = new RateMeter();
  readonly latencies = new Recent(RECENT_FRAMES);
  readonly bytes = new Recent(RECENT_FRAMES);
  last: Frame | null = null;
  lastLatencyMs = NaN;

  add(frame: Frame, latencyMs: number, nowMs: number): void {
    this.rate.add(nowMs);
    this.latencies.add(latencyMs);
    this.bytes.add(frame.data.length);
    this.last = frame;
    this.lastLatencyMs = latencyMs;
  }

  lines(nowMs: number, resolution: Resolution | null, speed: number, follow: string | null): string[] {
    const f = this.last;
    const ms = (v: number | undefined) => (v === undefined || Number.isNaN(v) ? "–" : v.toFixed(1));
    const kind = !f ? "–" : f.cache?.reusedPrevious ? "re-sent (same pose)" :
                 `${f.cache?.keyFrame ? "key" : "cached"} frame, W=${f.cache?.window ?? 0}`;
    const level = !resolution ? "–" : resolution.level === 0 ? "full" :
                  `moving ${resolution.level}/${LEVELS.length - 1}`;
    const kb = this.bytes.mean() / 1024;
    const fps = this.rate.rate(nowMs);
    // A still camera sends no pose, so no frame comes: say so rather than show a bare 0.
    return [
      fps === 0 && !resolution?.moving && f ? "fps – (camera still: the last frame stands)" : `fps ${fps.toFixed(1)}`,
      `latency ${ms(this.lastLatencyMs)} ms (p50 ${ms(percentile(this.latencies.values, 50))}, ` +
        `p90 ${ms(percentile(this.latencies.values, 90))})`,
      kind,
      `render ${ms(f?.timings?.renderMs)} ms · encode ${ms(f?.timings?.encodeMs)} ms`,
      `${Number.isNaN(kb) ? "–" : kb.toFixed(1)} KiB/frame`,
      !resolution ? "quality –" : `quality ${level}: ${resolution.width}×${resolution.height} JPEG q${resolution.jpegQuality}`,
      follow ? `follow: ${follow}` : `speed ${speed.toFixed(1)} m/s (wheel)`,
    ];
  }
}
