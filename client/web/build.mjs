// Builds the viewer: TypeScript from proto/catgs/v1/catgs.proto (protoc + protoc-gen-es, into
// gen/, not committed: the proto is the one source, and Debian's protoc runs at build time), a type check (tsc), then esbuild bundles
//   <build-dir>/dist/          the page the server serves (index.html, styles.css, app.js)
//   <build-dir>/node/          catgs-web-client.mjs, the node command-line client
//   <build-dir>/tests/         the unit tests, for node --test
// Usage: node build.mjs [--build-dir DIR] [--tests-only] [--no-typecheck]
import { execFileSync } from "node:child_process";
import { copyFileSync, existsSync, mkdirSync, readFileSync, readdirSync, renameSync, rmSync, writeFileSync } from "node:fs";
import { dirname, join, resolve } from "node:path";
import { fileURLToPath } from "node:url";
import * as esbuild from "esbuild";

const here = dirname(fileURLToPath(import.meta.url));
const args = process.argv.slice(2);
const option = (name, fallback) => {
  const i = args.indexOf(name);
  return i >= 0 && args[i + 1] ? args[i + 1] : fallback;
};
const buildDir = resolve(option("--build-dir", join(here, "build")));
const testsOnly = args.includes("--tests-only");
const repo = resolve(here, "../..");

// protoc writes into a private folder of the build; gen/ is updated only where the output
// differs, so that builds from several build folders sharing this source tree never see a
// half-written gen/.
function generateProto() {
  const scratch = join(buildDir, "gen");
  rmSync(scratch, { recursive: true, force: true });
  mkdirSync(scratch, { recursive: true });
  execFileSync("protoc", [
    `--plugin=protoc-gen-es=${join(here, "node_modules/.bin/protoc-gen-es")}`,
    `--es_out=${scratch}`, "--es_opt=target=ts", `-I${join(repo, "proto")}`, "catgs/v1/catgs.proto",
  ], { stdio: "inherit" });
  const file = "catgs/v1/catgs_pb.ts";
  const fresh = readFileSync(join(scratch, file));
  const target = join(here, "gen", file);
  if (!existsSync(target) || !readFileSync(target).equals(fresh)) {
    mkdirSync(dirname(target), { recursive: true });
    writeFileSync(`${target}.${process.pid}`, fresh);
    renameSync(`${target}.${process.pid}`, target);
  }
}

const common = { bundle: true, sourcemap: true, logLevel: "warning", absWorkingDir: here };

async function build() {
  generateProto();
  if (!args.includes("--no-typecheck"))
    execFileSync(process.execPath, [join(here, "node_modules/typescript/bin/tsc"), "-p", join(here, "tsconfig.json")],
                 { stdio: "inherit" });
  const tests = readdirSync(join(here, "tests")).filter((f) => f.endsWith(".test.ts"));
  rmSync(join(buildDir, "tests"), { recursive: true, force: true });
  await esbuild.build({
    ...common, entryPoints: tests.map((f) => join(here, "tests", f)), outdir: join(buildDir, "tests"),
    platform: "node", format: "esm", target: "node18", outExtension: { ".js": ".mjs" },
  });
  copyFileSync(join(here, "tests/fixtures/pose_table.json"), join(buildDir, "tests/pose_table.json"));
  if (testsOnly) return;
  const dist = join(buildDir, "dist");
  rmSync(dist, { recursive: true, force: true });
  mkdirSync(dist, { recursive: true });
  await esbuild.build({
    ...common, entryPoints: [join(here, "src/main.ts")], outfile: join(dist, "app.js"), platform: "browser",
    format: "esm", target: ["chrome100", "firefox100", "safari15"], minify: true,
  });
  for (const f of ["index.html", "styles.css"]) copyFileSync(join(here, f), join(dist, f));
  await esbuild.build({
    ...common, entryPoints: [join(here, "src/node-client.ts")], outfile: join(buildDir, "node/catgs-web-client.mjs"),
    platform: "node", format: "esm", target: "node18",
    // ws's optional native helpers are not installed; it falls back to JavaScript.
    external: ["bufferutil", "utf-8-validate"],
    banner: { js: "import { createRequire } from 'node:module'; const require = createRequire(import.meta.url);" },
  });
}

build().catch((error) => {
  console.error(`client/web/build.mjs: ${error.message ?? error}`);
  process.exit(1);
});
