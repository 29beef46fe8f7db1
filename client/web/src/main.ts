// The page: finds the scenes, flies the camera, shows the frames, the HUD and the minimap.
// URL parameters: token (with --token-file), scene (an id), max-width (cap of the full
// resolution in pixels, default 1920), up (z, y or -y: the scene's up axis, default z).
import type { Frame, SceneInfo } from "../gen/catgs/v1/catgs_pb";
import { ApiError, getScene, listScenes } from "./api";
import { FlightControl, bindInput } from "./flight";
import { HudModel } from "./hud";
import { drawMinimap } from "./minimap";
import { UP_AXES, UpAxis, Vec3, add, quaternionToMatrix, scale, upVector, yawPitchOf } from "./pose";
import { GRPC_UNAUTHENTICATED, newSessionKey, SocketLike, streamUrl } from "./stream";
import { PathCamera, SceneBounds, orbitFlight, parseTrajectory } from "./trajectory";
import { ConnectionState, FOV_X_DEGREES, Viewer } from "./viewer";

const params = new URLSearchParams(location.search);
let token = params.get("token") ?? undefined;
// One affinity key for the page's life: its reconnections and quality changes reach the same server.
const pageSessionKey = newSessionKey();
const up: UpAxis = (UP_AXES as readonly string[]).includes(params.get("up") ?? "") ? params.get("up") as UpAxis : "z";
// 1080p: what a CPU-backend demo server still renders at a few frames per second.
const DEFAULT_MAX_WIDTH = 1920;
const maxWidth = Math.max(64, Number(params.get("max-width")) || DEFAULT_MAX_WIDTH);
// The opening view and the follow orbit fly at this fraction of the scene's larger extent
// above its ground, and at this fraction of it per second.
const ALTITUDE_FRACTION = 0.35;
const SPEED_FRACTION = 0.1;
const ORBIT_FRAMES = 900;
const ORBIT_FPS = 30;

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const canvas = $<HTMLCanvasElement>("view");
const hudElement = $("hud"), statusElement = $("status"), minimap = $<HTMLCanvasElement>("minimap");
const scenePicker = $<HTMLSelectElement>("scene"), followPicker = $<HTMLSelectElement>("follow");
const trajectoryInput = $<HTMLInputElement>("trajectory-file");
const hud = new HudModel();
let viewer: Viewer | null = null;
let lastFrameHash = 0;
let lastStill: { width: number; height: number; bytes: number; signature: string } | null = null;
let frameError = "";

function fullSize(): { width: number; height: number } {
  const dpr = Math.min(window.devicePixelRatio || 1, 2);
  let width = Math.round(canvas.clientWidth * dpr), height = Math.round(canvas.clientHeight * dpr);
  if (width > maxWidth) {
    height = Math.round((height * maxWidth) / width);
    width = maxWidth;
  }
  return { width: Math.max(2, width), height: Math.max(2, height) };
}

function showStatus(state: ConnectionState | "error", message: string): void {
  statusElement.hidden = message === "";
  statusElement.textContent = message;
  statusElement.className = state;
}

function boundsOf(scene: SceneInfo): SceneBounds {
  const v = (p: { x: number; y: number; z: number } | undefined): Vec3 => [p?.x ?? 0, p?.y ?? 0, p?.z ?? 0];
  return { min: v(scene.bounds?.min), max: v(scene.bounds?.max) };
}

function maxExtent(b: SceneBounds): number {
  return Math.max(b.max[0] - b.min[0], b.max[1] - b.min[1], b.max[2] - b.min[2], 1);
}

/** Throws for bounds without horizontal extent. */
function orbitFor(scene: SceneInfo): PathCamera[] {
  const b = boundsOf(scene);
  const extent = maxExtent(b);
  return orbitFlight(b, { up, speed: SPEED_FRACTION * extent, altitude: ALTITUDE_FRACTION * extent,
                          fps: ORBIT_FPS, frames: ORBIT_FRAMES });
}

// FNV-1a over a sample of the bytes: enough to tell frames apart (tests, not security).
function sampleHash(data: Uint8Array): number {
  let h = 0x811c9dc5;
  const step = Math.max(1, Math.floor(data.length / 4096));
  for (let i = 0; i < data.length; i += step) h = Math.imul(h ^ data[i], 0x01000193) >>> 0;
  return h;
}

let drawing = false;
let pendingFrame: Frame | null = null;
async function draw(frame: Frame): Promise<void> {
  // Decoding is asynchronous: draw the newest frame, skip the ones that arrived meanwhile.
  if (drawing) {
    pendingFrame = frame;
    return;
  }
  drawing = true;
  try {
    const type = frame.encoding === 2 ? "image/png" : "image/jpeg";
    const bitmap = await createImageBitmap(new Blob([frame.data as Uint8Array<ArrayBuffer>], { type }));
    const { width, height } = fullSize();
    if (canvas.width !== width || canvas.height !== height) [canvas.width, canvas.height] = [width, height];
    const ctx = canvas.getContext("2d")!;
    ctx.imageSmoothingQuality = "high";
    ctx.drawImage(bitmap, 0, 0, canvas.width, canvas.height);
    bitmap.close();
  } catch (error) {
    frameError = `frame ${frame.sequence}: cannot decode the image (${String(error)})`;
  } finally {
    drawing = false;
  }
  const next = pendingFrame;
  pendingFrame = null;
  if (next) await draw(next);
}

function renderHud(nowMs: number): void {
  if (!viewer) return;
  const lines = hud.lines(nowMs, viewer.sessionResolution, viewer.control.speed, viewer.follow?.name ?? null);
  if (frameError) lines.push(`⚠ ${frameError}`);
  hudElement.textContent = lines.join("\n");
  const pose = viewer.currentPose();
  drawMinimap(minimap, { bounds: boundsOf(viewer.scene), up, position: pose.position,
                         cameraToWorld: quaternionToMatrix(pose.orientation), fovXDegrees: FOV_X_DEGREES,
                         aspect: canvas.clientWidth / Math.max(1, canvas.clientHeight) });
}

// Where a scene without horizontal extent (one point, a vertical line) is seen from: above it,
// looking down at this pitch.
const FLAT_SCENE_PITCH = (-60 * Math.PI) / 180;

function startPose(scene: SceneInfo): { position: Vec3; yaw: number; pitch: number } {
  try {
    const start = orbitFor(scene)[0];
    return { position: start.position, ...yawPitchOf(start.orientation, up) };
  } catch {
    const b = boundsOf(scene);
    const centre: Vec3 = [(b.min[0] + b.max[0]) / 2, (b.min[1] + b.max[1]) / 2, (b.min[2] + b.max[2]) / 2];
    return { position: add(centre, scale(upVector(up), maxExtent(b) * 2)), yaw: 0, pitch: FLAT_SCENE_PITCH };
  }
}

function startViewer(scene: SceneInfo): void {
  const { position, yaw, pitch } = startPose(scene);
  const speed = SPEED_FRACTION * maxExtent(boundsOf(scene));
  const { width, height } = fullSize();
  if (viewer) {
    viewer.stopFollow();
    viewer.control.state = { position, yaw, pitch };
    viewer.control.speed = speed;
    viewer.reset(scene, width, height);
    return;
  }
  const control = new FlightControl({ position, yaw, pitch }, speed, up);
  viewer = new Viewer(streamUrl(location.href, token, pageSessionKey), scene, control, width, height,
                      (url) => new WebSocket(url) as unknown as SocketLike, {
    onFrame: (frame, latencyMs) => {
      hud.add(frame, latencyMs, performance.now());
      lastFrameHash = sampleHash(frame.data);
      frameError = "";
      void draw(frame);
    },
    onStatus: (state, message) => {
      showStatus(state, message);
      if (state === "failed" && message.startsWith("UNAUTHENTICATED")) $("login").hidden = false;
    },
    onFrameError: (message) => (frameError = message),
  });
  bindInput(canvas, control, () => viewer?.stopFollow());
  viewer.start();
  const loop = (now: number) => {
    viewer?.tick(now);
    renderHud(now);
    requestAnimationFrame(loop);
  };
  requestAnimationFrame(loop);
}

async function selectScene(sceneId: string): Promise<void> {
  try {
    const scene = await getScene(location.href, sceneId, token);
    followPicker.value = "";
    startViewer(scene);
  } catch (error) {
    showApiError(error);
  }
}

function showApiError(error: unknown): void {
  const message = error instanceof Error ? error.message : String(error);
  const unauthenticated = error instanceof ApiError && error.grpcStatus === GRPC_UNAUTHENTICATED;
  showStatus("failed", unauthenticated ? `${message}. Enter the server's token below.` : message);
  if (unauthenticated) $("login").hidden = false;
}

async function loadScenes(): Promise<void> {
  let scenes: SceneInfo[];
  showStatus("connecting", "loading the server's scenes…");
  try {
    scenes = await listScenes(location.href, token);
  } catch (error) {
    showApiError(error);
    return;
  }
  if (scenes.length === 0) {
    showStatus("failed", "The server holds no scenes: start catgs-server with --scene, or load one with catgs-client load.");
    return;
  }
  scenePicker.replaceChildren(...scenes.map((s) => new Option(`${s.sceneId} (${s.gaussianCount} Gaussians)`, s.sceneId)));
  const wanted = params.get("scene");
  scenePicker.value = scenes.some((s) => s.sceneId === wanted) ? wanted! : scenes[0].sceneId;
  await selectScene(scenePicker.value);
}

scenePicker.addEventListener("change", () => void selectScene(scenePicker.value));
followPicker.addEventListener("change", () => {
  if (!viewer) return;
  if (followPicker.value === "orbit") {
    try {
      viewer.startFollow(orbitFor(viewer.scene), "built-in orbit", performance.now());
    } catch (error) {
      followPicker.value = "";
      frameError = error instanceof Error ? error.message : String(error);
    }
  }
  else if (followPicker.value === "file") trajectoryInput.click();
  else viewer.stopFollow();
});
trajectoryInput.addEventListener("change", async () => {
  const file = trajectoryInput.files?.[0];
  if (!file || !viewer) return;
  try {
    viewer.startFollow(parseTrajectory(await file.text(), file.name), file.name, performance.now());
  } catch (error) {
    followPicker.value = "";
    showStatus("error", `Cannot follow the trajectory: ${error instanceof Error ? error.message : String(error)}`);
    setTimeout(() => showStatus("error", ""), 6000);
  }
  trajectoryInput.value = "";
});
$("still").addEventListener("click", async () => {
  if (!viewer) return;
  const { width, height } = fullSize();
  try {
    const still = await viewer.still(width, height);
    lastStill = { width: still.width, height: still.height, bytes: still.png.length,
                  signature: Array.from(still.png.slice(1, 4), (c) => String.fromCharCode(c)).join("") };
    const link = document.createElement("a");
    link.href = URL.createObjectURL(new Blob([still.png as Uint8Array<ArrayBuffer>], { type: "image/png" }));
    link.download = `catgs-${viewer.scene.sceneId}-${new Date().toISOString().replace(/[:.]/g, "-")}.png`;
    link.click();
    setTimeout(() => URL.revokeObjectURL(link.href), 10000);
  } catch (error) {
    frameError = error instanceof Error ? error.message : String(error);
  }
});
$("login").addEventListener("submit", (e) => {
  e.preventDefault();
  token = $<HTMLInputElement>("token").value;
  const url = new URL(location.href);
  url.searchParams.set("token", token);
  // A fresh page: the token is then part of every request, the WebSocket's URL included.
  location.replace(url.toString());
});
window.addEventListener("resize", () => {
  const { width, height } = fullSize();
  viewer?.resize(width, height);
});

// For the end-to-end test (tests/e2e.mjs) and for curious users in the console.
Object.assign(window, {
  catgsViewer: {
    state: () => ({
      connection: viewer?.connection ?? "none",
      scene: viewer?.scene.sceneId ?? null,
      scenes: Array.from(scenePicker.options, (o) => o.value),
      status: statusElement.hidden ? "" : statusElement.textContent,
      hud: hudElement.textContent,
      frames: viewer?.framesReceived ?? 0,
      frameHash: lastFrameHash,
      session: viewer?.sessionResolution ?? null,
      lastFrame: hud.last ? { width: hud.last.width, height: hud.last.height, sequence: Number(hud.last.sequence) } : null,
      lastSent: viewer?.lastSent ? { position: viewer.lastSent.position, orientation: viewer.lastSent.orientation } : null,
      reconnects: viewer?.reconnects ?? 0,
      still: lastStill,
      loginShown: !$("login").hidden,
    }),
  },
});

void loadScenes();
