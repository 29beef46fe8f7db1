#!/usr/bin/env bash
# Offline checks of deploy/ (no cluster, no Docker engine, no Envoy needed):
#   1. yamllint (tests/deploy/.yamllint.yaml) on every YAML file of deploy/ and tests/deploy/;
#   2. kubectl kustomize deploy/k8s (and the CPU overlay example where kubectl's kustomize is
#      v3 or later);
#   3. node validate.mjs: every rendered object against the Kubernetes API schema
#      (kubernetes-models) and types (kubernetes-types + TypeScript: unknown fields fail),
#      project invariants across the manifests, the Envoy configs (structure: route timeout
#      0s, LEAST_REQUEST, hash policy on x-catgs-session, HTTP/2 upstream, health checks),
#      the compose file (Compose spec schema), and the Dockerfile (syntax, and its build steps
#      against README's commands, deploy/install-deps.sh and the CMake targets);
#   4. builds the image's health probe with deploy/docker/build-health-probe.sh (when
#      libgrpc++-dev is installed) and, when a built catgs-server is at hand, probes a live
#      server: SERVING, an unknown service, and after SIGTERM.
# Exit status: 0 when everything holds; 1 on any failure, with a FAIL line saying what.
#
# Usage: tests/deploy/check-manifests.sh [--mutations] [--server-bin PATH] [--no-npm]
#                                        [--no-probe] [--root DIR]
#   --mutations      afterwards, break a copy of deploy/ in known ways, one at a time, and
#                    require every broken copy to fail for the expected reason (proves the
#                    checks fail loudly; ~1 minute)
#   --server-bin P   catgs-server for the live probe test (default: build/server/catgs-server
#                    when it exists, else the live test is skipped)
#   --no-npm         do not run `npm ci` (node_modules must be there)
#   --no-probe       skip step 4
#   --root DIR       check the repository copy at DIR (used by --mutations)
# Needs: node (>= 18) and npm, yamllint, kubectl (KUBECTL=... to choose one); see
# tests/deploy/install-deps.sh, which installs them on Debian 12.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/../.." && pwd)
mutations=0 run_npm=1 run_probe=1 server_bin=""
while [ $# -gt 0 ]; do
  case $1 in
    --mutations) mutations=1 ;;
    --no-npm) run_npm=0 ;;
    --no-probe) run_probe=0 ;;
    --server-bin) server_bin=$2; shift ;;
    --root) root=$(cd "$2" && pwd); shift ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "check-manifests: unknown argument '$1'" >&2; exit 2 ;;
  esac
  shift
done

passed=0 failed=0 skipped=0
ok() { echo "PASS $*"; passed=$((passed + 1)); }
bad() { echo "FAIL $*" >&2; failed=$((failed + 1)); }
skip() { echo "SKIP $*"; skipped=$((skipped + 1)); }
die() { echo "FAIL $*" >&2; echo "check-manifests: $passed passed, $((failed + 1)) failed, $skipped skipped" >&2; exit 1; }

tmp=$(mktemp -d)
server_pid=""
cleanup() {
  if [ -n "$server_pid" ]; then kill "$server_pid" 2>/dev/null || true; fi
  rm -rf "$tmp"
}
trap cleanup EXIT

# ---------------------------------------------------------------- tools
kubectl=${KUBECTL:-kubectl}
for tool in node npm yamllint "$kubectl"; do
  command -v "$tool" >/dev/null ||
    die "'$tool' is missing: run 'bash tests/deploy/install-deps.sh' (Debian 12: nodejs npm yamllint kubernetes-client)"
done

# ---------------------------------------------------------------- npm packages (pinned)
if [ $run_npm = 1 ]; then
  stamp="$here/node_modules/.catgs-lock.sha256"
  want=$(sha256sum "$here/package-lock.json" | cut -d' ' -f1)
  if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    (cd "$here" && npm ci --no-audit --no-fund --loglevel=error) || die "npm ci in tests/deploy failed"
    echo "$want" > "$stamp"
  fi
fi
[ -d "$here/node_modules/kubernetes-models" ] || die "tests/deploy/node_modules is missing (run without --no-npm)"

# ---------------------------------------------------------------- 1. yamllint
cd "$root"
mapfile -t yaml_files < <(find deploy tests/deploy -path '*/node_modules' -prune -o \
  -type f \( -name '*.yaml' -o -name '*.yml' \) -print | sort)
if yamllint --strict -c "$root/tests/deploy/.yamllint.yaml" "${yaml_files[@]}"; then
  ok "yamllint: ${#yaml_files[@]} files"
else
  bad "yamllint (above)"
fi

# ---------------------------------------------------------------- 2. render
renders=()
if "$kubectl" kustomize deploy/k8s > "$tmp/base.yaml" 2> "$tmp/kustomize.err"; then
  ok "kubectl kustomize deploy/k8s: $(grep -c '^kind:' "$tmp/base.yaml") objects"
  renders+=(--render "base=$tmp/base.yaml")
else
  cat "$tmp/kustomize.err" >&2
  bad "kubectl kustomize deploy/k8s"
fi
minor=$("$kubectl" version --client -o json 2>/dev/null | node -e \
  'let s="";process.stdin.on("data",d=>s+=d).on("end",()=>{try{console.log(parseInt(JSON.parse(s).clientVersion.minor,10)||0)}catch{console.log(0)}})')
if [ "$minor" -ge 21 ]; then
  if "$kubectl" kustomize tests/deploy/fixtures/cpu-overlay > "$tmp/cpu.yaml" 2> "$tmp/kustomize.err"; then
    ok "kubectl kustomize tests/deploy/fixtures/cpu-overlay"
    renders+=(--render "cpu-overlay=$tmp/cpu.yaml")
  else
    cat "$tmp/kustomize.err" >&2
    bad "kubectl kustomize tests/deploy/fixtures/cpu-overlay"
  fi
else
  skip "cpu-overlay example: kubectl 1.$minor's kustomize (v2) renders neither directory resources nor patches"
fi

# ---------------------------------------------------------------- 3. validate
if node "$here/validate.mjs" --root "$root" "${renders[@]}"; then
  ok "validate.mjs (schemas, types, invariants, Envoy, compose, Dockerfile)"
else
  bad "validate.mjs (above)"
fi

# ---------------------------------------------------------------- 4. health probe
if [ $run_probe = 0 ]; then
  :
elif ! command -v pkg-config >/dev/null || ! pkg-config --exists grpc++; then
  skip "health probe build: libgrpc++-dev is not installed (bash deploy/install-deps.sh)"
elif ! CXXFLAGS=-Werror bash deploy/docker/build-health-probe.sh "$tmp/catgs-health-probe" > "$tmp/probe.log" 2>&1; then
  cat "$tmp/probe.log" >&2
  bad "deploy/docker/build-health-probe.sh"
else
  ok "deploy/docker/build-health-probe.sh builds catgs-health-probe"
  probe="$tmp/catgs-health-probe"
  [ -n "$server_bin" ] || { [ -x "$root/build/server/catgs-server" ] && server_bin="$root/build/server/catgs-server"; } || true
  if [ -z "$server_bin" ]; then
    skip "live probe test: no built catgs-server (build/server/catgs-server or --server-bin)"
  else
    # The shell opens a background command's redirections in the child, after '&' returns:
    # create the log first, or the first sed below can race the child and find no file.
    : > "$tmp/server.err"
    "$server_bin" --address 127.0.0.1:0 --health-address 127.0.0.1:0 --backend cpu \
      --scene 'city=builtin:city?gaussians=10000' --render-workers 1 --encode-workers 1 \
      > "$tmp/server.out" 2> "$tmp/server.err" &
    server_pid=$!
    health_port=""
    for _ in $(seq 1 100); do
      health_port=$(sed -n 's/.*health on port \([0-9]*\).*/\1/p' "$tmp/server.err" | head -1)
      [ -n "$health_port" ] && break
      kill -0 "$server_pid" 2>/dev/null || break
      sleep 0.1
    done
    if [ -z "$health_port" ]; then
      cat "$tmp/server.err" >&2
      bad "live probe test: $server_bin did not start"
    else
      live_ok=1
      "$probe" --addr "127.0.0.1:$health_port" > /dev/null || { live_ok=0; echo "probe: expected SERVING" >&2; }
      "$probe" --addr "127.0.0.1:$health_port" --service catgs.v1.RenderService > /dev/null ||
        { live_ok=0; echo "probe: expected SERVING for catgs.v1.RenderService" >&2; }
      if "$probe" --addr "127.0.0.1:$health_port" --service no.such.Service 2> /dev/null; then
        live_ok=0; echo "probe: an unknown service must not be healthy" >&2
      fi
      kill -TERM "$server_pid"
      status=0
      wait "$server_pid" || status=$?
      server_pid=""
      [ "$status" = 0 ] || { live_ok=0; echo "server: exit status $status after SIGTERM, expected 0" >&2; }
      if "$probe" --addr "127.0.0.1:$health_port" --timeout-ms 500 2> /dev/null; then
        live_ok=0; echo "probe: a stopped server must not be healthy" >&2
      fi
      if [ $live_ok = 1 ]; then ok "live probe test against $server_bin"; else bad "live probe test (above)"; fi
    fi
  fi
fi

# ---------------------------------------------------------------- --mutations
# Each case: file, Python regex, replacement, and a pattern the failure output must contain.
# The copy holds what the checks read; node_modules is the real one.
if [ $mutations = 1 ]; then
  cases=(
    "deploy/k8s/catgs-server-deployment.yaml|readOnlyRootFilesystem: true|readOnlyRootFilesytem: true|does not exist in type 'SecurityContext'"
    "deploy/k8s/catgs-server-deployment.yaml|failureThreshold: 120|failureThreshold: \"120\"|must be integer"
    "deploy/k8s/catgs-server-hpa.yaml|maxReplicas: 8|maxReplica: 8|does not exist in type 'HorizontalPodAutoscalerSpec'"
    "deploy/k8s/catgs-server-service.yaml|  clusterIP: None|  clusterIP: None\n   selector: {}|yamllint"
    "deploy/k8s/kustomization.yaml|  - catgs-server-pdb.yaml|  - catgs-server-pdbs.yaml|kubectl kustomize deploy/k8s"
    "deploy/k8s/catgs-server-deployment.yaml|            - --max-sessions|            - --max-session|has no flag --max-session"
    "deploy/k8s/catgs-server-deployment.yaml|(readinessProbe:\n            grpc:\n              port:) 8081|\\1 8082|gRPC probe on the health port"
    "deploy/k8s/catgs-server-deployment.yaml|limits:\n              memory: 32Gi\n              nvidia.com/gpu: 1|limits:\n              memory: 32Gi|nvidia.com/gpu must be 1"
    "deploy/k8s/envoy.yaml|(cluster: catgs_least_request\n\s+)timeout: 0s|\\1timeout: 15s|timeout must be \"0s\""
    "deploy/k8s/envoy.yaml|lb_policy: LEAST_REQUEST|lb_policy: ROUND_ROBIN|LEAST_REQUEST"
    "deploy/k8s/envoy.yaml|header_name: x-catgs-session|header_name: x-session|x-catgs-session"
    "deploy/k8s/envoy.yaml|lb_policy: MAGLEV|lb_policy: RANDOM|needs a MAGLEV or RING_HASH cluster"
    "deploy/envoy-host.yaml|http_connection_manager.v3.HttpConnectionManager\n|http_connection_manager.v3.HttpConnectionManagr\n|unknown type URL"
    "deploy/envoy-host.yaml|port_value: 50062|port_value: 50063|deploy/envoy-host.yaml expects"
    "deploy/docker/compose.yaml|stop_grace_period: 15s|stop_grace_periods: 15s|schema"
    "deploy/Dockerfile|RUN bash deploy/install-deps.sh|RUN apt-get update|bash deploy/install-deps.sh"
    "deploy/Dockerfile|RUN cmake -S . -B build |RUN cmake -S . -B out |cmake -S . -B build"
    "deploy/Dockerfile|HEALTHCHECK --interval=15s|HEALTHCHECK --interval=15q|deploy/Dockerfile:"
    "deploy/Dockerfile|build/renderer/catgs-bench|build/renderer/catgs-benchmark|no add_executable(catgs-benchmark)"
    "deploy/k8s/envoy.yaml|(- upgrade_type: websocket\n\s+)enabled: true|\\1enabled: false|needs upgrade_configs [{upgrade_type: websocket}]"
    "deploy/envoy-host.yaml|name: session\n|name: sid\n|must hash on query_parameter 'session'"
    "deploy/k8s/envoy.yaml|path: /healthz|path: /|HTTP health check on /healthz"
    "deploy/docker/compose.yaml|--web-address=127.0.0.1:8182|--web-address=127.0.0.1:8183|catgs_web endpoints"
    "deploy/k8s/catgs-server-deployment.yaml|- 0.0.0.0:8088|- 0.0.0.0:8089|--web-address must listen on containerPort web"
    "README.md|(<!-- main-command -->\n\`\`\`\nbash deploy/install-deps.sh && )cmake -S . -B build|\\1cmake -S . -B build-release|has no 'cmake -S . -B build'"
  )
  echo "--- mutations: ${#cases[@]} broken copies, each must fail"
  copy="$tmp/copy"
  mkdir -p "$copy/tests" "$copy/server" "$copy/client" "$copy/renderer"
  cp -r "$root/deploy" "$root/README.md" "$root/CMakeLists.txt" "$copy/"
  cp -r "$root/server/src" "$root/server/CMakeLists.txt" "$copy/server/"
  cp "$root/client/CMakeLists.txt" "$copy/client/"
  cp "$root/renderer/CMakeLists.txt" "$copy/renderer/"
  mkdir -p "$copy/tests/deploy"
  (cd "$root/tests/deploy" && cp -r .yamllint.yaml fixtures "$copy/tests/deploy/")
  mutation_failures=0
  for c in "${cases[@]}"; do
    IFS='|' read -r file pattern replacement expect <<< "$c"
    rm -rf "$tmp/m" && cp -r "$copy" "$tmp/m"
    if ! python3 - "$tmp/m/$file" "$pattern" "$replacement" <<'EOF'
import re, sys
path, pattern, repl = sys.argv[1], sys.argv[2], sys.argv[3].replace("\\n", "\n")
text = open(path).read()
new, n = re.subn(pattern.replace("\\n", "\n"), repl, text, count=1)
if n != 1:
    sys.exit(f"pattern not found in {path}: {pattern}")
open(path, "w").write(new)
EOF
    then
      bad "mutation of $file could not be applied (the case is stale)"
      mutation_failures=$((mutation_failures + 1))
      continue
    fi
    status=0
    # The copy's own checks, against the real node_modules (validate.mjs resolves packages
    # from its own location, so the real one runs with --root pointing at the copy).
    out=$(KUBECTL="$kubectl" bash "$here/check-manifests.sh" --root "$tmp/m" --no-npm --no-probe 2>&1) || status=$?
    if [ $status = 0 ]; then
      bad "mutation NOT caught: $file: $pattern -> $replacement"
      mutation_failures=$((mutation_failures + 1))
    elif ! grep -qF -- "$expect" <<< "$out"; then
      echo "$out" | grep -E '^FAIL' | head -5 >&2
      bad "mutation failed, but not with '$expect': $file: $pattern"
      mutation_failures=$((mutation_failures + 1))
    else
      echo "  caught: $file: $(grep -m1 -F -- "$expect" <<< "$out" | cut -c1-150)"
    fi
  done
  if [ $mutation_failures = 0 ]; then ok "mutations: all ${#cases[@]} broken copies failed as expected"; fi
fi

echo "check-manifests: $passed passed, $failed failed, $skipped skipped"
[ $failed = 0 ]
