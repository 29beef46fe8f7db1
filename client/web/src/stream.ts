// One RenderService.Stream over the server's WebSocket endpoint (docs/web.md): every binary
// message up is a serialized StreamRequest (open first, then frames), every one down a Frame.
// The stream ends with a close code: 1000 OK, 4000 + the gRPC status otherwise, 4016 for a bad
// token. Shared by the page and the node client (which passes the `ws` package's WebSocket).
import { create, fromBinary, toBinary } from "@bufbuild/protobuf";
import {
  Frame, FrameSchema, FrameRequestSchema, PoseSchema, SessionConfig, StreamRequestSchema, TimedPoseSchema,
  Vec3Schema,
} from "../gen/catgs/v1/catgs_pb";
import { Quat, Vec3 } from "./pose";

/** The subset of the WebSocket API that the browser's and the `ws` package's share. */
export interface SocketLike {
  binaryType: string;
  readyState: number;
  onopen: ((ev: unknown) => void) | null;
  onmessage: ((ev: { data: unknown }) => void) | null;
  onclose: ((ev: { code: number; reason: string }) => void) | null;
  onerror: ((ev: unknown) => void) | null;
  send(data: Uint8Array): void;
  close(code?: number, reason?: string): void;
}
export type SocketFactory = (url: string) => SocketLike;

const OPEN = 1;
export const CLOSE_OK = 1000;
/** The server's close code for a stream that ended with a gRPC status. */
export const CLOSE_STATUS_BASE = 4000;
export const GRPC_UNAUTHENTICATED = 16;
export const GRPC_INVALID_ARGUMENT = 3;
export const GRPC_FAILED_PRECONDITION = 9;
export const GRPC_NOT_FOUND = 5;

export interface TimedPose {
  position: Vec3;
  orientation: Quat;
  clientTimestampUs: bigint;
}

export interface PoseUpdate {
  position: Vec3;
  orientation: Quat;
  /** world units per second */
  velocity?: Vec3;
  /** radians per second */
  angularSpeed?: number;
  flightPlan?: TimedPose[];
}

export interface StreamEnd {
  code: number;
  reason: string;
  /** the gRPC status when the server ended the stream (code >= 4000), else undefined */
  grpcStatus?: number;
  /** true when the caller closed it */
  byClient: boolean;
}

export interface StreamHandlers {
  onOpen?: () => void;
  onFrame: (frame: Frame, receivedUs: bigint) => void;
  onEnd: (end: StreamEnd) => void;
}

/** Monotonic microseconds, the clock of FrameRequest.client_timestamp_us. */
export function nowUs(): bigint {
  return BigInt(Math.round(performance.now() * 1000));
}

/**
 * ws(s)://host/ws/stream[?token=...][&session=...] for a page served from `base`
 * (http(s)://host/...). `session` is the affinity key Envoy hashes on (docs/web.md): a browser
 * cannot set the x-catgs-session header on a WebSocket, and the same key brings a reconnection
 * back to the server that holds the scene.
 */
export function streamUrl(base: string, token: string | undefined, session?: string): string {
  const url = new URL("/ws/stream", base);
  url.protocol = url.protocol === "https:" ? "wss:" : "ws:";
  // encodeURIComponent, not searchParams: a space must be %20, since a '+' may be read literally.
  const query: string[] = [];
  if (token) query.push(`token=${encodeURIComponent(token)}`);
  if (session) query.push(`session=${encodeURIComponent(session)}`);
  url.search = query.length > 0 ? `?${query.join("&")}` : "";
  return url.toString();
}

/** A random affinity key for this page (not crypto.randomUUID: pages served over plain http
 *  from another host are not a secure context, where it is missing). */
export function newSessionKey(): string {
  let key = "";
  for (let i = 0; i < 16; ++i) key += Math.floor(Math.random() * 16).toString(16);
  return key;
}

export class RenderStream {
  private readonly socket: SocketLike;
  private sequence = 0n;
  private lastReceived = 0n;
  private closedByClient = false;
  private ended = false;

  constructor(url: string, config: SessionConfig, factory: SocketFactory, private readonly handlers: StreamHandlers) {
    this.socket = factory(url);
    this.socket.binaryType = "arraybuffer";
    this.socket.onopen = () => {
      this.socket.send(toBinary(StreamRequestSchema, create(StreamRequestSchema, {
        kind: { case: "open", value: config },
      })));
      handlers.onOpen?.();
    };
    this.socket.onmessage = (ev) => this.receive(ev.data);
    this.socket.onclose = (ev) => this.end(ev.code, ev.reason);
    // An error is always followed by a close event, which reports it.
    this.socket.onerror = () => {};
  }

  get isOpen(): boolean {
    return this.socket.readyState === OPEN && !this.ended;
  }

  get lastSequence(): bigint {
    return this.sequence;
  }

  /** Sends one frame request; returns its sequence number, or 0n when the socket is not open. */
  sendPose(p: PoseUpdate): bigint {
    if (!this.isOpen) return 0n;
    this.sequence += 1n;
    const request = create(FrameRequestSchema, {
      sequence: this.sequence,
      pose: poseMessage(p.position, p.orientation),
      clientTimestampUs: nowUs(),
      lastReceivedSequence: this.lastReceived,
    });
    if (p.velocity) request.linearVelocity = create(Vec3Schema, { x: p.velocity[0], y: p.velocity[1], z: p.velocity[2] });
    if (p.angularSpeed !== undefined) request.angularSpeed = p.angularSpeed;
    for (const planned of p.flightPlan ?? [])
      request.flightPlan.push(create(TimedPoseSchema, {
        pose: poseMessage(planned.position, planned.orientation), clientTimestampUs: planned.clientTimestampUs,
      }));
    this.socket.send(toBinary(StreamRequestSchema, create(StreamRequestSchema, { kind: { case: "frame", value: request } })));
    return this.sequence;
  }

  close(): void {
    this.closedByClient = true;
    if (this.socket.readyState <= OPEN) this.socket.close(CLOSE_OK, "viewer closed the stream");
  }

  private receive(data: unknown): void {
    if (!(data instanceof ArrayBuffer)) {
      this.socket.close(1003, "the viewer expects binary Frame messages");
      return;
    }
    let frame: Frame;
    try {
      frame = fromBinary(FrameSchema, new Uint8Array(data));
    } catch (error) {
      this.socket.close(1007, "undecodable Frame");
      this.end(1007, `the server sent a message that is not a catgs.v1.Frame: ${String(error)}`);
      return;
    }
    if (frame.sequence > this.lastReceived) this.lastReceived = frame.sequence;
    this.handlers.onFrame(frame, nowUs());
  }

  private end(code: number, reason: string): void {
    if (this.ended) return;
    this.ended = true;
    const grpcStatus = code >= CLOSE_STATUS_BASE && code < CLOSE_STATUS_BASE + 100 ? code - CLOSE_STATUS_BASE : undefined;
    this.handlers.onEnd({ code, reason, grpcStatus, byClient: this.closedByClient });
  }
}

function poseMessage(position: Vec3, q: Quat) {
  return create(PoseSchema, {
    position: { x: position[0], y: position[1], z: position[2] },
    orientation: { w: q[0], x: q[1], y: q[2], z: q[3] },
  });
}

/** Words for a close the server did not explain (1006: the connection dropped). */
export function describeEnd(end: StreamEnd): string {
  if (end.reason) return end.reason;
  if (end.code === 1006) return "the connection dropped (no close frame: server stopped or network lost)";
  return `closed with code ${end.code}`;
}
