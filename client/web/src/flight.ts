// The flown camera: WASD moves horizontally along the heading, Q/E along the world's up, a
// drag turns (yaw, pitch), the wheel scales the speed; touch: one finger turns, two fingers
// pinch to move forward/back and pan to strafe and climb. The integration is pure (step) so
// that the page and tests share it; bindInput attaches the DOM events.
import { add, cross, forwardVector, heading, MAX_PITCH_RADIANS, Quat, scale, upVector, UpAxis, Vec3, viewQuaternion } from "./pose";

export interface CameraState {
  position: Vec3;
  yaw: number;
  pitch: number;
}

// Radians per CSS pixel of drag: a full-width drag on a laptop screen turns about 180 degrees.
const LOOK_RADIANS_PER_PX = 0.004;
// One wheel notch (deltaY 100) changes the speed by this factor.
const WHEEL_SPEED_FACTOR = 1.25;
const WHEEL_NOTCH = 100;
const MIN_SPEED = 0.2;
const MAX_SPEED = 2000;
// Metres moved per CSS pixel of two-finger pan/pinch, as a fraction of the flying speed.
const TOUCH_MOVE_PER_PX = 0.02;

export const KEY_BINDINGS: Record<string, [number, number, number]> = {
  // [forward, right, up]
  KeyW: [1, 0, 0], KeyS: [-1, 0, 0], KeyA: [0, -1, 0], KeyD: [0, 1, 0], KeyE: [0, 0, 1], KeyQ: [0, 0, -1],
  ArrowUp: [1, 0, 0], ArrowDown: [-1, 0, 0], ArrowLeft: [0, -1, 0], ArrowRight: [0, 1, 0],
};

export class FlightControl {
  readonly pressed = new Set<string>();
  speed: number;
  state: CameraState;
  /** the last step's motion, for FrameRequest.linear_velocity and the adaptive quality */
  velocity: Vec3 = [0, 0, 0];
  angularSpeed = 0;
  private pendingYaw = 0;
  private pendingPitch = 0;
  private pendingMove: [number, number, number] = [0, 0, 0];

  constructor(start: CameraState, speed: number, public up: UpAxis) {
    this.state = { ...start, position: [...start.position] };
    this.speed = speed;
  }

  orientation(): Quat {
    return viewQuaternion(this.state.yaw, this.state.pitch, this.up);
  }

  look(dxPx: number, dyPx: number): void {
    this.pendingYaw -= dxPx * LOOK_RADIANS_PER_PX;
    this.pendingPitch -= dyPx * LOOK_RADIANS_PER_PX;
  }

  wheel(deltaY: number): void {
    const factor = WHEEL_SPEED_FACTOR ** (-deltaY / WHEEL_NOTCH);
    this.speed = Math.min(MAX_SPEED, Math.max(MIN_SPEED, this.speed * factor));
  }

  /** Two-finger gesture: pinch (spread grows: forward) and pan, in CSS pixels. */
  touchMove(spreadPx: number, panXPx: number, panYPx: number): void {
    const metres = this.speed * TOUCH_MOVE_PER_PX;
    this.pendingMove = [this.pendingMove[0] + spreadPx * metres, this.pendingMove[1] - panXPx * metres,
                        this.pendingMove[2] + panYPx * metres];
  }

  /** Advances by dt seconds; returns true when the pose changed. */
  step(dt: number): boolean {
    let forward = 0, right = 0, upward = 0;
    for (const code of this.pressed) {
      const b = KEY_BINDINGS[code];
      if (!b) continue;
      forward += b[0];
      right += b[1];
      upward += b[2];
    }
    const h = heading(this.state.yaw, this.up);
    const r = cross(h, upVector(this.up));
    const distance = this.speed * dt;
    let move: Vec3 = add(add(scale(h, forward * distance), scale(r, right * distance)),
                         scale(upVector(this.up), upward * distance));
    const [f, s, u] = this.pendingMove;
    move = add(move, add(add(scale(h, f), scale(r, s)), scale(upVector(this.up), u)));
    this.pendingMove = [0, 0, 0];
    const yawChange = this.pendingYaw;
    const oldPitch = this.state.pitch;
    this.state.yaw += this.pendingYaw;
    this.state.pitch = Math.max(-MAX_PITCH_RADIANS, Math.min(MAX_PITCH_RADIANS, this.state.pitch + this.pendingPitch));
    this.pendingYaw = this.pendingPitch = 0;
    this.state.position = add(this.state.position, move);
    const turned = Math.hypot(yawChange * Math.cos(oldPitch), this.state.pitch - oldPitch);
    this.velocity = dt > 0 ? scale(move, 1 / dt) : [0, 0, 0];
    this.angularSpeed = dt > 0 ? turned / dt : 0;
    return move[0] !== 0 || move[1] !== 0 || move[2] !== 0 || turned !== 0;
  }

  forward(): Vec3 {
    return forwardVector(this.state.yaw, this.state.pitch, this.up);
  }
}

/** Mouse, keyboard and touch events of `element` drive `control`. */
export function bindInput(element: HTMLElement, control: FlightControl, onUserInput: () => void): void {
  const editable = (t: EventTarget | null) =>
    t instanceof HTMLInputElement || t instanceof HTMLSelectElement || t instanceof HTMLTextAreaElement;
  window.addEventListener("keydown", (e) => {
    if (editable(e.target) || !(e.code in KEY_BINDINGS)) return;
    control.pressed.add(e.code);
    onUserInput();
    e.preventDefault();
  });
  window.addEventListener("keyup", (e) => control.pressed.delete(e.code));
  window.addEventListener("blur", () => control.pressed.clear());

  let dragging: { x: number; y: number } | null = null;
  element.addEventListener("mousedown", (e) => {
    dragging = { x: e.clientX, y: e.clientY };
    onUserInput();
  });
  window.addEventListener("mouseup", () => (dragging = null));
  window.addEventListener("mousemove", (e) => {
    if (!dragging) return;
    control.look(e.clientX - dragging.x, e.clientY - dragging.y);
    dragging = { x: e.clientX, y: e.clientY };
  });
  element.addEventListener("wheel", (e) => {
    control.wheel(e.deltaY);
    e.preventDefault();
  }, { passive: false });

  let touches: Touch[] = [];
  const centre = (t: Touch[]) => ({ x: (t[0].clientX + t[1].clientX) / 2, y: (t[0].clientY + t[1].clientY) / 2 });
  const spread = (t: Touch[]) => Math.hypot(t[0].clientX - t[1].clientX, t[0].clientY - t[1].clientY);
  const remember = (e: TouchEvent) => (touches = Array.from(e.touches));
  element.addEventListener("touchstart", (e) => {
    remember(e);
    onUserInput();
    e.preventDefault();
  }, { passive: false });
  element.addEventListener("touchend", remember);
  element.addEventListener("touchcancel", remember);
  element.addEventListener("touchmove", (e) => {
    const now = Array.from(e.touches);
    if (now.length === 1 && touches.length === 1) {
      control.look(now[0].clientX - touches[0].clientX, now[0].clientY - touches[0].clientY);
    } else if (now.length >= 2 && touches.length >= 2) {
      const a = centre(touches), b = centre(now);
      control.touchMove(spread(now) - spread(touches), b.x - a.x, b.y - a.y);
    }
    touches = now;
    e.preventDefault();
  }, { passive: false });
}
