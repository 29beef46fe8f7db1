// End-to-end: catgs-server (CPU backend, a small built-in city, --token-file) serves the built
// viewer; Debian's chromium, headless through puppeteer-core, loads it and flies. Checks: the
// page connects; frames arrive and change; the canvas is not blank (pixel statistics of a
// screenshot); the HUD updates; the resolution drops while moving and comes back when still;
// a still is a full-size PNG; a server restart shows the message, then the page reconnects and
// resumes its pose; a bad token shows the error.
//   node tests/e2e.mjs --dist DIR [--screenshots DIR] [--gaussians N]
// Env: CATGS_SERVER (the catgs-server binary), CATGS_CHROMIUM (default /usr/bin/chromium).
import { spawn } from "node:child_process";
import { mkdtempSync, mkdirSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { parseArgs } from "node:util";
import puppeteer from "puppeteer-core";
import { WebSocket } from "ws";
import { PNG } from "pngjs";

const { values: args } = parseArgs({
  options: { dist: { type: "string" }, screenshots: { type: "string" }, gaussians: { type: "string", default: "20000" } },
});
const server = process.env.CATGS_SERVER;
const chromium = process.env.CATGS_CHROMIUM ?? "/usr/bin/chromium";
if (!server || !args.dist) {
  console.error("e2e: needs CATGS_SERVER=<catgs-server> and --dist <built viewer>");
  process.exit(2);
}
const TOKEN = "e2e-token-0123456789";
// Small enough for the CPU backend on 2 shared cores to answer within tens of milliseconds.
const VIEWPORT = { width: 600, height: 338 };
const MAX_WIDTH = 480;
// Generous bounds: CI machines are slow and shared (a 480x270 CPU frame takes 0.1 to 1 s); none
// of them is a timing assertion, each step waits for its condition.
const CONNECT_MS = 30000;
const STEP_MS = 20000;

const work = mkdtempSync(join(tmpdir(), "catgs-web-e2e-"));
writeFileSync(join(work, "token"), `${TOKEN}\n`);
let serverProcess = null;
let serverLog = "";
let browser = null;
const browserLog = [];

function startServer(webAddress) {
  return new Promise((resolve, reject) => {
    const p = spawn(server, [
      "--backend", "cpu", "--scene", `city=builtin:city?gaussians=${args.gaussians}`,
      "--scene", "small=builtin:city?gaussians=10000&seed=2", "--address", "127.0.0.1:0",
      "--web-address", webAddress, "--web-root", args.dist, "--token-file", join(work, "token"),
      "--drain-ms", "300", "--shutdown-grace-ms", "300", "--render-threads", "2",
    ], { stdio: ["ignore", "pipe", "pipe"] });
    serverProcess = p;
    const timer = setTimeout(() => reject(new Error(`catgs-server printed no web address within ${CONNECT_MS} ms`)), CONNECT_MS);
    const scan = (chunk) => {
      serverLog += chunk;
      const m = /web viewer on (https?:\/\/[^\s]+)/.exec(serverLog.slice(-4000));
      if (m) {
        clearTimeout(timer);
        resolve(m[1].endsWith("/") ? m[1] : `${m[1]}/`);
      }
    };
    p.stdout.setEncoding("utf8").on("data", scan);
    p.stderr.setEncoding("utf8").on("data", scan);
    p.on("exit", (code) => {
      clearTimeout(timer);
      reject(new Error(`catgs-server exited (${code}) before printing its web address`));
    });
  });
}

function stopServer() {
  const p = serverProcess;
  serverProcess = null;
  if (!p || p.exitCode !== null) return Promise.resolve();
  return new Promise((resolve) => {
    p.removeAllListeners("exit");
    p.on("exit", () => resolve());
    p.kill("SIGTERM");
  });
}

const state = (page) => page.evaluate(() => window.catgsViewer.state());

async function waitFor(page, what, predicate, timeoutMs = STEP_MS) {
  const deadline = Date.now() + timeoutMs;
  let s;
  while (Date.now() < deadline) {
    s = await state(page);
    if (predicate(s)) return s;
    await new Promise((r) => setTimeout(r, 50));
  }
  throw new Error(`timed out after ${timeoutMs} ms waiting for ${what}; page state: ${JSON.stringify(s)}`);
}

function check(condition, message) {
  if (!condition) throw new Error(message);
  console.log(`ok: ${message}`);
}

/** Mean and standard deviation of the luminance, and the share of distinct colours. */
async function pixelStats(page) {
  const png = PNG.sync.read(Buffer.from(await page.screenshot({ type: "png" })));
  let sum = 0, sum2 = 0;
  const colours = new Set();
  const n = png.width * png.height;
  for (let i = 0; i < n; ++i) {
    const [r, g, b] = [png.data[4 * i], png.data[4 * i + 1], png.data[4 * i + 2]];
    const y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    sum += y;
    sum2 += y * y;
    colours.add(((r >> 3) << 10) | ((g >> 3) << 5) | (b >> 3));
  }
  const mean = sum / n;
  return { mean, std: Math.sqrt(Math.max(0, sum2 / n - mean * mean)), colours: colours.size };
}

async function newPage(url, viewport = VIEWPORT) {
  const page = await browser.newPage();
  await page.setViewport(viewport);
  page.on("console", (m) => browserLog.push(`console.${m.type()}: ${m.text()}`));
  page.on("pageerror", (e) => browserLog.push(`pageerror: ${e.message}`));
  await page.goto(url, { waitUntil: "load" });
  return page;
}

async function fly(page) {
  const before = await waitFor(page, "a full-quality frame", (s) => s.lastFrame?.width === MAX_WIDTH && s.session?.level === 0);
  const hashes = new Set([before.frameHash]);
  let movingFrame = null;
  await page.keyboard.down("KeyW");
  await page.keyboard.down("KeyD");
  // Flies until frames of the moving level have arrived and changed (at least 1.5 s).
  const start = Date.now();
  while (Date.now() - start < STEP_MS) {
    const s = await state(page);
    if (s.session?.moving && s.lastFrame && s.lastFrame.width < MAX_WIDTH) {
      movingFrame ??= s.lastFrame;
      hashes.add(s.frameHash);
    }
    if (movingFrame && hashes.size >= 3 && Date.now() - start > 1500) break;
    await new Promise((r) => setTimeout(r, 50));
  }
  await page.keyboard.up("KeyW");
  await page.keyboard.up("KeyD");
  const moved = await state(page);
  check(moved.lastSent.position.some((v, i) => Math.abs(v - before.lastSent.position[i]) > 1),
        `the scripted keys moved the camera (${before.lastSent.position.map((v) => v.toFixed(1))} -> ` +
        `${moved.lastSent.position.map((v) => v.toFixed(1))})`);
  check(movingFrame !== null, `frames while moving came at a lower resolution (${movingFrame?.width}x${movingFrame?.height})`);
  check(hashes.size >= 3, `frames arrive and change while flying (${hashes.size} different frames, ` +
                          `${((Date.now() - start) / 1000).toFixed(1)} s)`);
  const still = await waitFor(page, "full resolution after stopping", (s) => s.session?.level === 0 && s.lastFrame?.width === MAX_WIDTH &&
                              s.lastFrame.sequence > 0);
  check(still.lastFrame.width === MAX_WIDTH, `full resolution again once still (${still.lastFrame.width}x${still.lastFrame.height})`);
}

async function pickScene(page) {
  const before = await state(page);
  check(before.scenes.join(",") === "city,small", `the scene picker lists the server's scenes (${before.scenes})`);
  await page.select("#scene", "small");
  const after = await waitFor(page, "a frame of the picked scene",
                              (s) => s.scene === "small" && s.connection === "live" && s.frames > before.frames);
  check(after.frameHash !== before.frameHash, "picking a scene opens a session on it and shows its frames");
}

async function restart(page, webAddress) {
  const before = await state(page);
  await stopServer();
  const lost = await waitFor(page, "the connection-lost message", (s) => s.connection === "lost" && /Connection lost/.test(s.status));
  check(/Reconnecting in/.test(lost.status), `a stopped server shows: "${lost.status}", with the retry to come`);
  await startServer(webAddress);
  const back = await waitFor(page, "reconnection", (s) => s.connection === "live" && s.frames > before.frames && s.status === "", CONNECT_MS);
  check(back.reconnects >= 1, `reconnected after ${back.reconnects} attempt(s), the message cleared`);
  check(back.lastSent.position.every((v, i) => v === before.lastSent.position[i]),
        "the reconnected session resumed the last pose");
}

async function screenshots(url, dir) {
  mkdirSync(dir, { recursive: true });
  for (const [name, viewport] of [["viewer-1080p.png", { width: 1920, height: 1080 }],
                                  ["viewer-phone.png", { width: 390, height: 844, deviceScaleFactor: 2, isMobile: true, hasTouch: true }]]) {
    const page = await newPage(`${url}?token=${TOKEN}`, viewport);
    await waitFor(page, `a full-quality frame at ${viewport.width}x${viewport.height}`,
                  (s) => s.session?.level === 0 && s.frames >= 1 && s.lastFrame?.width === s.session.width, 90000);
    await new Promise((r) => setTimeout(r, 1200));  // the HUD's rates settle
    await page.screenshot({ path: join(dir, name) });
    console.log(`screenshot: ${join(dir, name)}`);
    await page.close();
  }
}

async function main() {
  const t0 = Date.now();
  const url = await startServer("127.0.0.1:0");
  const webAddress = new URL(url).host;
  browser = await puppeteer.launch({
    executablePath: chromium, headless: true,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           `--user-data-dir=${join(work, "profile")}`],
  });
  if (args.screenshots) return screenshots(url, args.screenshots);
  const page = await newPage(`${url}?token=${TOKEN}&max-width=${MAX_WIDTH}`);
  const first = await waitFor(page, "the first frames", (s) => s.connection === "live" && s.frames >= 1, CONNECT_MS);
  check(first.lastFrame.width === MAX_WIDTH, `the page connected and shows ${first.lastFrame.width}x${first.lastFrame.height} frames`);
  await new Promise((r) => setTimeout(r, 300));
  const stats = await pixelStats(page);
  check(stats.std > 10 && stats.colours > 200,
        `the canvas is not blank (luminance mean ${stats.mean.toFixed(1)}, std ${stats.std.toFixed(1)}, ${stats.colours} colours)`);
  const hud1 = (await state(page)).hud;
  check(/fps \d/.test(hud1) && /latency \d/.test(hud1) && /render \d/.test(hud1) && /encode \d/.test(hud1) &&
        /KiB\/frame/.test(hud1) && /(key|cached) frame, W=\d+|re-sent/.test(hud1) && /quality full/.test(hud1),
        `the HUD shows fps, latency, frame kind and W, render/encode ms, bytes, quality:\n${hud1}`);
  await fly(page);
  const hud2 = (await state(page)).hud;
  check(hud2 !== hud1, "the HUD updated");
  await page.click("#still");
  const still = await waitFor(page, "the still", (s) => s.still !== null);
  check(still.still.signature === "PNG" && still.still.width === MAX_WIDTH,
        `the still button gave a ${still.still.width}x${still.still.height} PNG (${still.still.bytes} bytes)`);
  await pickScene(page);
  await restart(page, webAddress);
  await page.close();

  const bad = await newPage(`${url}?token=wrong-token`);
  const refused = await waitFor(bad, "the bad-token error", (s) => /UNAUTHENTICATED/.test(s.status));
  check(refused.loginShown && refused.frames === 0, `a bad token shows "${refused.status}" and the token field, no frame`);
  const closed = await new Promise((resolve) => {
    const socket = new WebSocket(`${url.replace(/^http/, "ws")}ws/stream?token=wrong-token`);
    let messages = 0;
    socket.on("message", () => ++messages);
    socket.on("close", (code, reason) => resolve({ code, reason: reason.toString(), messages }));
  });
  check(closed.code === 4016 && /^UNAUTHENTICATED: /.test(closed.reason) && closed.messages === 0,
        `the WebSocket with a bad token closes with ${closed.code} "${closed.reason}" before any frame`);
  const errors = browserLog.filter((l) => l.startsWith("pageerror"));
  check(errors.length === 0, `no uncaught page errors${errors.length ? `: ${errors.join("; ")}` : ""}`);
  console.log(`e2e passed in ${((Date.now() - t0) / 1000).toFixed(1)} s`);
}

main().then(() => 0, (error) => {
  console.error(`e2e FAILED: ${error.stack ?? error}`);
  console.error(`--- browser log (last 30) ---\n${browserLog.slice(-30).join("\n")}`);
  console.error(`--- catgs-server log (last 3000 chars) ---\n${serverLog.slice(-3000)}`);
  return 1;
}).then(async (code) => {
  await browser?.close().catch(() => {});
  await stopServer();
  rmSync(work, { recursive: true, force: true });
  process.exit(code);
});
