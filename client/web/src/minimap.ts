// The minimap: the scene's bounds seen from above (along -up), the camera's position, its
// heading and the footprint of its view on the ground (the bottom of the bounds).
import { add, cameraAxis, dot, horizontalAxes, Mat3, scale, UpAxis, Vec3 } from "./pose";
import type { SceneBounds } from "./trajectory";

/** Where the rays through the image corners meet the ground plane, in world coordinates. Rays
 *  that never reach the ground (above the horizon) stop at maxDistance, so the polygon stays
 *  finite and shows the view reaching far away. Corners in image order: top-left, top-right,
 *  bottom-right, bottom-left. */
export function viewFootprint(position: Vec3, cameraToWorld: Mat3, fovXDegrees: number, aspect: number,
                              groundHeight: number, up: UpAxis, maxDistance: number): Vec3[] {
  const { up: upVec } = horizontalAxes(up);
  const tanX = Math.tan((fovXDegrees * Math.PI) / 360);
  const tanY = tanX / aspect;
  const right = cameraAxis(cameraToWorld, 0), down = cameraAxis(cameraToWorld, 1), forward = cameraAxis(cameraToWorld, 2);
  const corners: [number, number][] = [[-1, -1], [1, -1], [1, 1], [-1, 1]];
  const height = dot(position, upVec) - groundHeight;
  return corners.map(([sx, sy]) => {
    const ray = add(forward, add(scale(right, sx * tanX), scale(down, sy * tanY)));
    const descent = -dot(ray, upVec);
    const rayLength = Math.hypot(ray[0], ray[1], ray[2]);
    let t = maxDistance / rayLength;
    if (descent > 0 && height > 0) t = Math.min(t, height / descent);
    return add(position, scale(ray, t));
  });
}

export function groundHeightOf(bounds: SceneBounds, up: UpAxis): number {
  const { up: u } = horizontalAxes(up);
  return Math.min(dot(bounds.min, u), dot(bounds.max, u));
}

export interface MinimapView {
  bounds: SceneBounds;
  up: UpAxis;
  position: Vec3;
  cameraToWorld: Mat3;
  fovXDegrees: number;
  aspect: number;
}

// Pixels of margin inside the minimap canvas, and the heading arrow's length.
const MARGIN_PX = 10;
const ARROW_PX = 16;

export function drawMinimap(canvas: HTMLCanvasElement, v: MinimapView): void {
  const ctx = canvas.getContext("2d");
  if (!ctx) return;
  const { e1, e2 } = horizontalAxes(v.up);
  // The map shows the bounds and the camera, also when it flies outside them.
  const corners: Vec3[] = [v.bounds.min, v.bounds.max];
  const a = corners.map((c) => dot(c, e1)), b = corners.map((c) => dot(c, e2));
  const [boxA0, boxA1, boxB0, boxB1] = [Math.min(...a), Math.max(...a), Math.min(...b), Math.max(...b)];
  const camA = dot(v.position, e1), camB = dot(v.position, e2);
  const [aMin, aMax] = [Math.min(boxA0, camA), Math.max(boxA1, camA)];
  const [bMin, bMax] = [Math.min(boxB0, camB), Math.max(boxB1, camB)];
  const span = Math.max(aMax - aMin, bMax - bMin, 1e-9);
  const px = (canvas.width - 2 * MARGIN_PX) / span;
  // Seen from above: e1 to the right, e2 up the screen (e1 x e2 = up points at the viewer).
  const toScreen = (p: Vec3): [number, number] => [
    MARGIN_PX + (dot(p, e1) - aMin) * px + ((canvas.width - 2 * MARGIN_PX) - (aMax - aMin) * px) / 2,
    canvas.height - MARGIN_PX - (dot(p, e2) - bMin) * px - ((canvas.height - 2 * MARGIN_PX) - (bMax - bMin) * px) / 2,
  ];
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.fillStyle = "rgba(10, 14, 20, 0.75)";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  const lo = toScreen(add(scale(e1, boxA0), scale(e2, boxB0))), hi = toScreen(add(scale(e1, boxA1), scale(e2, boxB1)));
  ctx.strokeStyle = "#6f8aa8";
  ctx.lineWidth = 1;
  ctx.strokeRect(lo[0], hi[1], hi[0] - lo[0], lo[1] - hi[1]);

  const ground = groundHeightOf(v.bounds, v.up);
  const footprint = viewFootprint(v.position, v.cameraToWorld, v.fovXDegrees, v.aspect, ground, v.up, 2 * span);
  ctx.save();
  ctx.beginPath();
  ctx.rect(0, 0, canvas.width, canvas.height);
  ctx.clip();
  ctx.beginPath();
  footprint.forEach((p, i) => (i === 0 ? ctx.moveTo(...toScreen(p)) : ctx.lineTo(...toScreen(p))));
  ctx.closePath();
  ctx.fillStyle = "rgba(255, 200, 60, 0.25)";
  ctx.strokeStyle = "rgba(255, 200, 60, 0.8)";
  ctx.fill();
  ctx.stroke();
  ctx.restore();

  const at = toScreen(v.position);
  const forward = cameraAxis(v.cameraToWorld, 2);
  const flat = Math.hypot(dot(forward, e1), dot(forward, e2));
  ctx.fillStyle = "#ff5a3c";
  ctx.beginPath();
  ctx.arc(at[0], at[1], 4, 0, 2 * Math.PI);
  ctx.fill();
  if (flat > 1e-6) {
    const dx = dot(forward, e1) / flat, dy = dot(forward, e2) / flat;
    ctx.strokeStyle = "#ff5a3c";
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(at[0], at[1]);
    ctx.lineTo(at[0] + dx * ARROW_PX, at[1] - dy * ARROW_PX);
    ctx.stroke();
  }
}
