// The viewer's session logic: one RenderStream at a time, reopened when the adaptive quality
// changes the resolution (a session's size is fixed at open), reconnected with backoff when it
// is lost, resuming the last pose; stills through a second short PNG session. DOM-free except
// for what the callbacks do.
import { create } from "@bufbuild/protobuf";
import { Encoding, Frame, SceneInfo, SessionConfig, SessionConfigSchema } from "../gen/catgs/v1/catgs_pb";
import { AdaptiveQuality, Resolution } from "./adaptive";
import { Backoff } from "./backoff";
import { FlightControl } from "./flight";
import { Quat, Vec3, yawPitchOf } from "./pose";
import { describeEnd, GRPC_INVALID_ARGUMENT, GRPC_NOT_FOUND, GRPC_UNAUTHENTICATED, PoseUpdate, RenderStream, SocketFactory, StreamEnd, TimedPose, nowUs } from "./stream";
import { PathCamera, sampleAt } from "./trajectory";

export const FOV_X_DEGREES = 70;
const CLIENT_NAME = "catgs web viewer";
// Poses of the follow path sent ahead as FrameRequest.flight_plan (the proto's maximum).
const FLIGHT_PLAN_POSES = 16;
const FLIGHT_PLAN_STEP_S = 1 / 30;
// A still that takes longer is reported as failed rather than left pending.
const STILL_TIMEOUT_MS = 30000;

export type ConnectionState = "connecting" | "live" | "lost" | "failed";

export interface ViewerCallbacks {
  onFrame(frame: Frame, latencyMs: number): void;
  onStatus(state: ConnectionState, message: string): void;
  /** a frame request was answered with FrameError: the session stays open */
  onFrameError(message: string): void;
}

export interface Timers {
  set(fn: () => void, ms: number): unknown;
  clear(handle: unknown): void;
}

export interface Still {
  png: Uint8Array;
  width: number;
  height: number;
}

// Statuses for which reconnecting cannot help until the user changes something.
const FATAL_STATUSES = new Set([GRPC_UNAUTHENTICATED, GRPC_INVALID_ARGUMENT, GRPC_NOT_FOUND]);

export class Viewer {
  readonly adaptive: AdaptiveQuality;
  follow: { path: PathCamera[]; startMs: number; name: string } | null = null;
  connection: ConnectionState = "connecting";
  /** what the open session renders at */
  sessionResolution: Resolution | null = null;
  lastSent: { position: Vec3; orientation: Quat; sequence: bigint } | null = null;
  framesReceived = 0;
  reconnects = 0;
  private stream: RenderStream | null = null;
  private readonly backoff = new Backoff();
  /** The reconnection timer; tests put a fake clock here. */
  timers: Timers = { set: (fn, ms) => setTimeout(fn, ms), clear: (handle) => clearTimeout(handle as ReturnType<typeof setTimeout>) };
  private retryTimer: unknown = null;
  private poseDirty = true;
  private lastTickMs: number | null = null;
  private followPose: { position: Vec3; orientation: Quat } | null = null;

  constructor(private readonly url: string, public scene: SceneInfo, readonly control: FlightControl,
              fullWidth: number, fullHeight: number, private readonly factory: SocketFactory,
              private readonly callbacks: ViewerCallbacks) {
    this.adaptive = new AdaptiveQuality(fullWidth, fullHeight);
  }

  start(): void {
    this.open();
  }

  stop(): void {
    if (this.retryTimer !== null) this.timers.clear(this.retryTimer);
    this.retryTimer = null;
    this.stream?.close();
    this.stream = null;
  }

  /** A new scene, or a new full size: a new session. */
  reset(scene: SceneInfo, fullWidth: number, fullHeight: number): void {
    this.scene = scene;
    this.adaptive.setFullSize(fullWidth, fullHeight);
    this.stop();
    this.backoff.reset();
    this.open();
  }

  resize(fullWidth: number, fullHeight: number): void {
    this.adaptive.setFullSize(fullWidth, fullHeight);
    const r = this.adaptive.resolution();
    if (this.connection === "live" && (r.width !== this.sessionResolution?.width || r.height !== this.sessionResolution?.height))
      this.reopen();
  }

  /** The pose to render now: the follow path's or the flown camera's. */
  currentPose(): { position: Vec3; orientation: Quat } {
    return this.followPose ?? { position: this.control.state.position, orientation: this.control.orientation() };
  }

  startFollow(path: PathCamera[], name: string, nowMs: number): void {
    this.follow = { path, startMs: nowMs, name };
  }

  stopFollow(): void {
    this.follow = null;
    if (!this.followPose) return;
    // The flown camera takes over where the path left it (without the path's roll).
    const { yaw, pitch } = yawPitchOf(this.followPose.orientation, this.control.up);
    this.control.state = { position: [...this.followPose.position], yaw, pitch };
    this.followPose = null;
    this.poseDirty = true;
  }

  /** Called every animation frame. */
  tick(nowMs: number): void {
    const dt = this.lastTickMs === null ? 0 : Math.min(0.1, (nowMs - this.lastTickMs) / 1000);
    this.lastTickMs = nowMs;
    let moved: boolean;
    let update: PoseUpdate;
    if (this.follow) {
      const t = (nowMs - this.follow.startMs) / 1000;
      const c = sampleAt(this.follow.path, t);
      moved = this.followPose === null || c.position.some((v, i) => v !== this.followPose!.position[i]) ||
              c.orientation.some((v, i) => v !== this.followPose!.orientation[i]);
      this.followPose = { position: c.position, orientation: c.orientation };
      const base = nowUs();
      const plan: TimedPose[] = [];
      for (let k = 1; k <= FLIGHT_PLAN_POSES; ++k) {
        const p = sampleAt(this.follow.path, t + k * FLIGHT_PLAN_STEP_S);
        plan.push({ position: p.position, orientation: p.orientation,
                    clientTimestampUs: base + BigInt(Math.round(k * FLIGHT_PLAN_STEP_S * 1e6)) });
      }
      update = { ...this.followPose, flightPlan: plan };
    } else {
      moved = this.control.step(dt);
      update = { ...this.currentPose(), velocity: this.control.velocity, angularSpeed: this.control.angularSpeed };
    }
    if (moved) {
      this.poseDirty = true;
      if (this.adaptive.onMotion(nowMs)) this.reopen();
    }
    if (this.adaptive.update(nowMs)) this.reopen();
    if (this.poseDirty && this.stream?.isOpen) {
      const sequence = this.stream.sendPose(update);
      if (sequence > 0n) {
        this.poseDirty = false;
        this.lastSent = { position: [...update.position], orientation: [...update.orientation], sequence };
      }
    }
  }

  /** One full-quality PNG of the current pose, through a second short session. */
  still(fullWidth: number, fullHeight: number): Promise<Still> {
    const pose = this.currentPose();
    const config = this.config(fullWidth, fullHeight, 0, Encoding.PNG);
    return new Promise<Still>((resolve, reject) => {
      const timer = setTimeout(() => {
        s.close();
        reject(new Error(`still: no frame within ${STILL_TIMEOUT_MS / 1000} s`));
      }, STILL_TIMEOUT_MS);
      const s = new RenderStream(this.url, config, this.factory, {
        onOpen: () => s.sendPose(pose),
        onFrame: (frame) => {
          clearTimeout(timer);
          s.close();
          if (frame.error) reject(new Error(`still: ${frame.error.message}`));
          else resolve({ png: frame.data, width: frame.width, height: frame.height });
        },
        onEnd: (end) => {
          clearTimeout(timer);
          if (!end.byClient) reject(new Error(`still: ${describeEnd(end)}`));
        },
      });
    });
  }

  private config(width: number, height: number, jpegQuality: number, encoding: Encoding): SessionConfig {
    return create(SessionConfigSchema, {
      sceneId: this.scene.sceneId, width, height, horizontalFovDegrees: FOV_X_DEGREES,
      encoding: { encoding, jpegQuality }, maxUnackedFrames: 2, clientName: CLIENT_NAME,
    });
  }

  private reopen(): void {
    if (!this.stream) return;
    this.stream?.close();
    this.open();
  }

  private open(): void {
    this.retryTimer = null;
    const r = this.adaptive.resolution();
    this.sessionResolution = r;
    // A lost connection keeps its message (it says a reconnection is under way) until a frame.
    if (this.connection !== "live" && this.connection !== "lost")
      this.setStatus("connecting", `connecting to scene ${this.scene.sceneId}…`);
    const stream: RenderStream = new RenderStream(this.url, this.config(r.width, r.height, r.jpegQuality, Encoding.JPEG),
                                                  this.factory, {
      onOpen: () => {
        // The session's first frame is the pose the viewer is at, also after a reconnect.
        this.poseDirty = true;
      },
      onFrame: (frame, receivedUs) => this.frame(stream, frame, receivedUs),
      onEnd: (end) => this.ended(stream, end),
    });
    this.stream = stream;
  }

  private frame(stream: RenderStream, frame: Frame, receivedUs: bigint): void {
    if (stream !== this.stream) return;
    if (frame.error) {
      this.callbacks.onFrameError(`frame ${frame.sequence}: code ${frame.error.code}: ${frame.error.message}`);
      return;
    }
    this.backoff.reset();
    if (this.connection !== "live") this.setStatus("live", "");
    ++this.framesReceived;
    const latencyMs = Number(receivedUs - frame.clientTimestampUs) / 1000;
    this.adaptive.onFrame(latencyMs);
    this.callbacks.onFrame(frame, latencyMs);
  }

  private ended(stream: RenderStream, end: StreamEnd): void {
    if (stream !== this.stream || end.byClient) return;
    this.stream = null;
    if (end.grpcStatus !== undefined && FATAL_STATUSES.has(end.grpcStatus)) {
      this.setStatus("failed", describeEnd(end));
      return;
    }
    const delay = this.backoff.next();
    ++this.reconnects;
    this.setStatus("lost", `Connection lost: ${describeEnd(end)}. Reconnecting in ${(delay / 1000).toFixed(1)} s ` +
                           `(attempt ${this.backoff.attemptCount}); the view resumes where it was.`);
    this.retryTimer = this.timers.set(() => this.open(), delay);
  }

  private setStatus(state: ConnectionState, message: string): void {
    this.connection = state;
    this.callbacks.onStatus(state, message);
  }
}
