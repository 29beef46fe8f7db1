// catgs-web-client: streams a flight over catgs-server's WebSocket endpoint from node, with the
// page's own code (stream.ts, trajectory.ts), and prints the pose-to-frame latency. For hosts
// without a browser (the GPU machine), to compare the WebSocket path with catgs-client (gRPC).
//   node catgs-web-client.mjs --url http://127.0.0.1:8080/ [--scene city] [--token T]
//        [--width 1280] [--height 720] [--frames 300] [--pose-rate 30] [--trajectory FILE]
//        [--quality 85] [--json]
import { readFileSync } from "node:fs";
import { parseArgs } from "node:util";
import { WebSocket } from "ws";
import { create } from "@bufbuild/protobuf";
import { Encoding, SessionConfigSchema } from "../gen/catgs/v1/catgs_pb";
import { getScene } from "./api";
import { percentile } from "./stats";
import { describeEnd, RenderStream, SocketLike, streamUrl } from "./stream";
import { orbitFlight, parseTrajectory, PathCamera, sampleAt } from "./trajectory";
import type { Vec3 } from "./pose";

const usage = "usage: catgs-web-client --url http://HOST:PORT/ [--scene ID] [--token T] [--width N] [--height N] " +
              "[--frames N] [--pose-rate HZ] [--trajectory FILE] [--quality 1..100] [--json]";

function positiveInt(name: string, text: string): number {
  const v = Number(text);
  if (!Number.isInteger(v) || v < 1) throw new Error(`--${name}: "${text}" is not a positive integer`);
  return v;
}

async function main(): Promise<number> {
  const { values } = parseArgs({
    options: {
      url: { type: "string" }, scene: { type: "string", default: "city" }, token: { type: "string" },
      width: { type: "string", default: "1280" }, height: { type: "string", default: "720" },
      frames: { type: "string", default: "300" }, "pose-rate": { type: "string", default: "30" },
      trajectory: { type: "string" }, quality: { type: "string", default: "85" }, json: { type: "boolean" },
      help: { type: "boolean" },
    },
  });
  if (values.help) {
    console.log(usage);
    return 0;
  }
  if (!values.url) throw new Error(`--url is required\n${usage}`);
  const width = positiveInt("width", values.width!), height = positiveInt("height", values.height!);
  const frames = positiveInt("frames", values.frames!), poseRate = positiveInt("pose-rate", values["pose-rate"]!);
  const quality = positiveInt("quality", values.quality!);
  const token = values.token ?? process.env.CATGS_TOKEN;
  const scene = await getScene(values.url, values.scene!, token);
  const v = (p: { x: number; y: number; z: number } | undefined): Vec3 => [p?.x ?? 0, p?.y ?? 0, p?.z ?? 0];
  const bounds = { min: v(scene.bounds?.min), max: v(scene.bounds?.max) };
  const extent = Math.max(bounds.max[0] - bounds.min[0], bounds.max[1] - bounds.min[1], 1);
  // The page's opening orbit: 0.35 of the extent up, 0.1 of it per second.
  const orbit = { up: "z" as const, speed: 0.1 * extent, altitude: 0.35 * extent, fps: poseRate, frames: frames + 1 };
  const path: PathCamera[] = values.trajectory
    ? parseTrajectory(readFileSync(values.trajectory, "utf8"), values.trajectory)
    : orbitFlight(bounds, orbit);
  // The same flight through gRPC, for a comparison: catgs-client stream --trajectory <this>.
  if (!values.trajectory && !values.json)
    console.log(`flight: builtin:orbit?speed=${orbit.speed}&altitude=${orbit.altitude}&fps=${poseRate}` +
                `&frames=${frames + 1} (catgs-client stream --trajectory '...' --rate ${poseRate} flies the same)`);

  const config = create(SessionConfigSchema, {
    sceneId: scene.sceneId, width, height, horizontalFovDegrees: 70,
    encoding: { encoding: Encoding.JPEG, jpegQuality: quality }, maxUnackedFrames: 2,
    clientName: "catgs-web-client (node)",
  });
  const latencies: number[] = [];
  let bytes = 0, errors = 0, firstMs = 0, lastMs = 0;
  const result = await new Promise<{ ok: boolean; message: string }>((resolve) => {
    let sent = 0;
    let timer: ReturnType<typeof setInterval> | null = null;
    const stream: RenderStream = new RenderStream(streamUrl(values.url!, token), config,
                                                  (url) => new WebSocket(url) as unknown as SocketLike, {
      onOpen: () => {
        // Poses at the flight's own rate, as a viewer sends them; the server coalesces.
        timer = setInterval(() => {
          if (sent >= frames) return;
          const c = sampleAt(path, path[0].t + sent / poseRate);
          stream.sendPose({ position: c.position, orientation: c.orientation });
          ++sent;
        }, 1000 / poseRate);
      },
      onFrame: (frame, receivedUs) => {
        if (frame.error) {
          ++errors;
          console.error(`frame ${frame.sequence}: ${frame.error.message}`);
        } else {
          latencies.push(Number(receivedUs - frame.clientTimestampUs) / 1000);
          bytes += frame.data.length;
          lastMs = performance.now();
          if (firstMs === 0) firstMs = lastMs;
        }
        if (frame.sequence >= BigInt(frames)) {
          if (timer) clearInterval(timer);
          stream.close();
          resolve({ ok: true, message: "" });
        }
      },
      onEnd: (end) => {
        if (timer) clearInterval(timer);
        if (!end.byClient) resolve({ ok: end.code === 1000, message: describeEnd(end) });
      },
    });
  });
  const n = latencies.length;
  const summary = {
    frames: n, poses: frames, errors, width, height,
    fps: n > 1 ? ((n - 1) * 1000) / (lastMs - firstMs) : 0,
    latency_ms: { p50: percentile(latencies, 50), p90: percentile(latencies, 90), p99: percentile(latencies, 99) },
    mean_bytes: n ? Math.round(bytes / n) : 0,
  };
  if (values.json) console.log(JSON.stringify(summary));
  else
    console.log(`${n} frames of ${frames} poses, ${width}x${height}, ${summary.fps.toFixed(1)} fps, ` +
                `pose-to-frame latency p50 ${summary.latency_ms.p50.toFixed(1)} ms, p90 ${summary.latency_ms.p90.toFixed(1)} ms, ` +
                `p99 ${summary.latency_ms.p99.toFixed(1)} ms, ${summary.mean_bytes} bytes/frame`);
  if (!result.ok) {
    console.error(`catgs-web-client: the stream ended: ${result.message}`);
    return 1;
  }
  return 0;
}

main().then((code) => process.exit(code), (error) => {
  console.error(`catgs-web-client: ${error instanceof Error ? error.message : String(error)}`);
  process.exit(2);
});
