// RenderStream and the Viewer's session logic against a fake socket: what goes on the wire,
// acknowledgements, close codes, reconnection with backoff resuming the pose, fatal errors.
import { test } from "node:test";
import assert from "node:assert/strict";
import { create, fromBinary, toBinary } from "@bufbuild/protobuf";
import { FrameSchema, SceneInfoSchema, SessionConfigSchema, StreamRequest, StreamRequestSchema } from "../gen/catgs/v1/catgs_pb";
import { RenderStream, SocketLike, streamUrl, StreamEnd } from "../src/stream";
import { FlightControl } from "../src/flight";
import { Viewer } from "../src/viewer";

class FakeSocket implements SocketLike {
  binaryType = "blob";
  readyState = 0;
  onopen: ((ev: unknown) => void) | null = null;
  onmessage: ((ev: { data: unknown }) => void) | null = null;
  onclose: ((ev: { code: number; reason: string }) => void) | null = null;
  onerror: ((ev: unknown) => void) | null = null;
  readonly sent: StreamRequest[] = [];
  closedWith: number | null = null;
  constructor(readonly url: string) {}
  send(data: Uint8Array): void {
    this.sent.push(fromBinary(StreamRequestSchema, data));
  }
  close(code?: number): void {
    this.closedWith = code ?? 1005;
    this.readyState = 3;
  }
  // server side
  accept(): void {
    this.readyState = 1;
    this.onopen?.({});
  }
  frame(sequence: bigint, clientTimestampUs = 0n): void {
    const f = create(FrameSchema, { sequence, width: 8, height: 6, data: new Uint8Array([1, 2, 3]), clientTimestampUs });
    const bytes = toBinary(FrameSchema, f);
    this.onmessage?.({ data: bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength) });
  }
  serverClose(code: number, reason: string): void {
    this.readyState = 3;
    this.onclose?.({ code, reason });
  }
}

function factory(list: FakeSocket[]) {
  return (url: string) => {
    const s = new FakeSocket(url);
    list.push(s);
    return s;
  };
}

test("streamUrl: ws for http, wss for https, the token as a query parameter", () => {
  assert.equal(streamUrl("http://h:8080/index.html?x=1", undefined), "ws://h:8080/ws/stream");
  assert.equal(streamUrl("https://h/", "a b+c"), "wss://h/ws/stream?token=a%20b%2Bc");
  assert.equal(streamUrl("http://h/", "t", "0123abcd"), "ws://h/ws/stream?token=t&session=0123abcd");
  assert.equal(streamUrl("http://h/", undefined, "k"), "ws://h/ws/stream?session=k");
});

test("open first, then frame requests acknowledging the newest frame received", () => {
  const sockets: FakeSocket[] = [];
  const frames: bigint[] = [];
  const config = create(SessionConfigSchema, { sceneId: "city", width: 64, height: 48 });
  const s = new RenderStream("ws://x/ws/stream", config, factory(sockets), { onFrame: (f) => frames.push(f.sequence), onEnd: () => {} });
  assert.equal(s.sendPose({ position: [0, 0, 0], orientation: [1, 0, 0, 0] }), 0n, "nothing before the socket opens");
  sockets[0].accept();
  assert.equal(sockets[0].binaryType, "arraybuffer");
  assert.equal(sockets[0].sent[0].kind.case, "open");
  assert.equal(sockets[0].sent[0].kind.value?.$typeName, "catgs.v1.SessionConfig");
  assert.equal(s.sendPose({ position: [1, 2, 3], orientation: [0, 1, 0, 0], velocity: [4, 5, 6], angularSpeed: 0.5 }), 1n);
  sockets[0].frame(1n);
  s.sendPose({ position: [1, 2, 4], orientation: [0, 1, 0, 0] });
  const [first, second] = sockets[0].sent.slice(1).map((r) => (r.kind.case === "frame" ? r.kind.value : undefined));
  assert.equal(first?.sequence, 1n);
  assert.equal(first?.lastReceivedSequence, 0n);
  assert.deepEqual([first?.pose?.position?.x, first?.pose?.position?.y, first?.pose?.position?.z], [1, 2, 3]);
  assert.deepEqual([first?.pose?.orientation?.w, first?.pose?.orientation?.x], [0, 1]);
  assert.equal(first?.linearVelocity?.z, 6);
  assert.equal(first?.angularSpeed, 0.5);
  assert.ok((first?.clientTimestampUs ?? 0n) > 0n);
  assert.equal(second?.sequence, 2n);
  assert.equal(second?.lastReceivedSequence, 1n);
  assert.equal(second?.angularSpeed, undefined, "unset when unknown");
  assert.deepEqual(frames, [1n]);
});

test("a close code of 4000 + status carries the gRPC status; a text message closes with 1003", () => {
  const sockets: FakeSocket[] = [];
  const ends: StreamEnd[] = [];
  new RenderStream("ws://x/", create(SessionConfigSchema), factory(sockets), { onFrame: () => {}, onEnd: (e) => ends.push(e) });
  sockets[0].accept();
  sockets[0].serverClose(4014, "UNAVAILABLE: server shutting down");
  assert.deepEqual(ends, [{ code: 4014, reason: "UNAVAILABLE: server shutting down", grpcStatus: 14, byClient: false }]);
  new RenderStream("ws://x/", create(SessionConfigSchema), factory(sockets), { onFrame: () => {}, onEnd: () => {} });
  sockets[1].accept();
  sockets[1].onmessage?.({ data: "hello" });
  assert.equal(sockets[1].closedWith, 1003);
});

/** A manual clock for the Viewer's reconnection timer (node 18 has no mock.timers). */
class FakeTimers {
  now = 0;
  private pending: { at: number; fn: () => void }[] = [];
  set = (fn: () => void, ms: number) => {
    const entry = { at: this.now + ms, fn };
    this.pending.push(entry);
    return entry;
  };
  clear = (handle: unknown) => {
    this.pending = this.pending.filter((e) => e !== handle);
  };
  tick(ms: number): void {
    this.now += ms;
    const due = this.pending.filter((e) => e.at <= this.now);
    this.pending = this.pending.filter((e) => e.at > this.now);
    due.forEach((e) => e.fn());
  }
}

function makeViewer(sockets: FakeSocket[], statuses: string[]) {
  const scene = create(SceneInfoSchema, { sceneId: "city" });
  const control = new FlightControl({ position: [0, 0, 50], yaw: 0, pitch: -0.5 }, 10, "z");
  const v = new Viewer("ws://x/ws/stream", scene, control, 640, 360, factory(sockets), {
    onFrame: () => {}, onStatus: (state, message) => statuses.push(`${state}: ${message}`), onFrameError: () => {},
  });
  const clock = new FakeTimers();
  v.timers = clock;
  return { v, clock };
}

test("a lost stream says so, reconnects after the backoff and resumes the last pose", () => {
  {
    const sockets: FakeSocket[] = [], statuses: string[] = [];
    const { v, clock } = makeViewer(sockets, statuses);
    v.start();
    sockets[0].accept();
    v.tick(0);
    sockets[0].frame(1n);
    assert.equal(v.connection, "live");
    v.control.pressed.add("KeyW");
    v.tick(16);
    v.control.pressed.clear();
    v.tick(32);
    v.tick(300);  // moved, then still: a moving session, then a full one
    const live = sockets[2];
    live.accept();
    v.tick(316);
    live.frame(1n);
    const before = v.lastSent!;
    assert.ok(before.position[0] > 0, "the camera moved along +x");
    live.serverClose(4014, "UNAVAILABLE: server is shutting down; reconnect");
    assert.equal(v.connection, "lost");
    assert.match(statuses.at(-1)!, /^lost: Connection lost: UNAVAILABLE: server is shutting down; reconnect\. Reconnecting in 0\.\d s \(attempt 1\)/);
    assert.equal(sockets.length, 3, "waits for the backoff");
    clock.tick(1000);
    assert.equal(sockets.length, 4);
    sockets[3].accept();
    v.tick(2000);
    const resumed = sockets[3].sent[1].kind.value as { pose?: { position?: { x: number; y: number; z: number } } };
    assert.deepEqual([resumed.pose?.position?.x, resumed.pose?.position?.y, resumed.pose?.position?.z], before.position);
    assert.equal(v.connection, "lost", "still lost until a frame arrives");
    sockets[3].frame(1n);
    assert.equal(v.connection, "live");
  }
});

test("UNAUTHENTICATED is final: the message is shown and no reconnection is tried", () => {
  {
    const sockets: FakeSocket[] = [], statuses: string[] = [];
    const { v, clock } = makeViewer(sockets, statuses);
    v.start();
    sockets[0].accept();
    sockets[0].serverClose(4016, "UNAUTHENTICATED: missing or wrong bearer token");
    assert.equal(v.connection, "failed");
    assert.equal(statuses.at(-1), "failed: UNAUTHENTICATED: missing or wrong bearer token");
    clock.tick(60000);
    assert.equal(sockets.length, 1);
  }
});

test("motion reopens the session at the moving level; stillness reopens it at full size", () => {
  const sockets: FakeSocket[] = [], statuses: string[] = [];
  const { v } = makeViewer(sockets, statuses);
  v.start();
  sockets[0].accept();
  v.tick(0);
  sockets[0].frame(1n);
  v.control.pressed.add("KeyD");
  v.tick(16);
  assert.equal(sockets.length, 2);
  assert.equal(sockets[0].closedWith, 1000);
  sockets[1].accept();
  const open = sockets[1].sent[0].kind.value as { width: number; height: number; encoding?: { jpegQuality: number } };
  assert.deepEqual([open.width, open.height], [480, 270]);
  v.control.pressed.clear();
  v.tick(32);
  v.tick(300);
  assert.equal(sockets.length, 3);
  sockets[2].accept();
  const full = sockets[2].sent[0].kind.value as { width: number; height: number };
  assert.deepEqual([full.width, full.height], [640, 360]);
});
