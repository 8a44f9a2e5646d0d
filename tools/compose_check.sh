#!/usr/bin/env bash
# `docker compose up` of the whole stack for real: build the image (anywhere: a local base image when Docker Hub
# cannot be reached, a local wheelhouse and the machine's CA certificates when pip's are local or behind a
# proxy), run the stack, wait for the executor, check the run's MCAP from the host, compare its step table with
# `foresight demo`'s, `docker compose down`, and check that nothing is left running. docs/docker.md.
#
#   tools/compose_check.sh [--twice] [--no-demo] [--secure]
#     --twice    run the stack a second time after `down` (it must reuse the trained model)
#     --no-demo  skip the comparison with a `foresight demo` run on the host
#     --secure   with compose.secure.yaml: mutual TLS and access control, with certificates made for the check in a
#                temporary directory outside the clone, removed at the end (runs/ and models/ are mounted into every
#                container: a CA key there was every container's to read)
#
# Environment: FORESIGHT_BASE_IMAGE (default python:3.11-slim, else a debootstrap image), FORESIGHT_WHEELHOUSE_DIR
# (default: pip's find-links directory, if local), FORESIGHT_CA_BUNDLE (default: pip's / requests' CA bundle),
# FORESIGHT (the host's foresight command, default .venv/bin/foresight). Exit status: 0 passed, 1 failed,
# 3 cannot run here (no Docker engine, no compose plugin), with one line saying why.
set -euo pipefail
cd "$(dirname "$0")/.."

PROJECT=foresight-check
IMAGE=foresight:0.1.0
LOCAL_BASE=foresight-base:bookworm
WHEELHOUSE_IMAGE=foresight-wheelhouse:local
FORESIGHT=${FORESIGHT:-.venv/bin/foresight}
PY=$(dirname "$FORESIGHT")/python
OUT=runs/compose-check
TWICE=0; DEMO=1; FILES=(-f compose.yaml)
for arg in "$@"; do
  case $arg in
    --twice) TWICE=1 ;; --no-demo) DEMO=0 ;; --secure) FILES=(-f compose.yaml -f compose.secure.yaml) ;;
    *) echo "compose check: unknown argument $arg (see the top of $0)"; exit 2 ;;
  esac
done

say() { echo "compose check: $*"; }
cannot() { say "cannot run here: $*"; exit 3; }
fail() { say "FAILED: $*"; exit 1; }
now() { date +%s.%N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", b - a }'; }

command -v docker >/dev/null || cannot "no docker command (README, 'Docker')"
docker info >/dev/null 2>&1 || cannot "no Docker engine answers ($(docker info 2>&1 | grep -m1 -iE 'cannot|error' || true)); start one: README, 'Docker'"
docker compose version >/dev/null 2>&1 || cannot "no compose v2 plugin (\`docker compose\`)"
[ -x "$FORESIGHT" ] || cannot "no foresight command on the host to check the log with ($FORESIGHT: make setup)"
mkdir -p models runs "$OUT"
compose() { docker compose -p "$PROJECT" "${FILES[@]}" "$@"; }
STACK_UP=0 SECURITY=""
on_exit() {  # whatever happens, nothing is left running and the check's certificates are gone
  if [ "$STACK_UP" = 1 ]; then compose down --remove-orphans >/dev/null 2>&1 || true; fi
  if [ -n "$SECURITY" ]; then rm -rf "$SECURITY"; fi
}
trap on_exit EXIT
if [ -d "$OUT/security" ]; then  # where an earlier check made them: in runs/, which every container mounts
  rm -rf "$OUT/security"
  say "removed $OUT/security: an earlier check's certificates, which every container could read (runs/ is mounted)"
fi
if [ ${#FILES[@]} -gt 2 ]; then  # the secure variant: a CA and one certificate per role, the router's for `router`
  # outside the clone, so that no container mounts more than compose.secure.yaml gives it: its role's files
  SECURITY=$(mktemp -d "${TMPDIR:-/tmp}/foresight-check-security.XXXXXX")
  export FORESIGHT_SECURITY_DIR=$SECURITY/security
  "$FORESIGHT" security init "$FORESIGHT_SECURITY_DIR" --hosts router >/dev/null
  # the containers run as the owner of runs/, and each key is readable by its maker only
  if [ "$(id -u)" = 0 ]; then chown -R "$(stat -c %u:%g runs)" "$SECURITY"; fi
  say "secure variant: mutual TLS and access control, certificates in $FORESIGHT_SECURITY_DIR (removed at the end)"
fi

# 1. the base image: the default one if it is here or can be pulled, else one made with debootstrap
BASE=${FORESIGHT_BASE_IMAGE:-python:3.11-slim}
if ! docker image inspect "$BASE" >/dev/null 2>&1 && ! docker pull -q "$BASE" >/dev/null 2>&1; then
  if [ -n "${FORESIGHT_BASE_IMAGE:-}" ]; then fail "base image $BASE is neither here nor pullable"; fi
  BASE=$LOCAL_BASE
  if ! docker image inspect "$BASE" >/dev/null 2>&1; then
    command -v debootstrap >/dev/null || cannot "python:3.11-slim cannot be pulled and debootstrap is missing to make a base image (apt-get install debootstrap)"
    [ "$(id -u)" = 0 ] || cannot "python:3.11-slim cannot be pulled; making a base image with debootstrap needs root"
    say "python:3.11-slim cannot be pulled: making $BASE (debootstrap bookworm, Python 3.11)"
    root=$(mktemp -d)
    debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates bookworm "$root" \
      http://deb.debian.org/debian > "$OUT/debootstrap.log" 2>&1 || fail "debootstrap (see $OUT/debootstrap.log)"
    tar -C "$root" -c . | docker import --change 'CMD ["/bin/bash"]' - "$BASE" >/dev/null
    rm -rf "$root"
  fi
fi

# 2. extra wheels (pip's local find-links) and extra CA certificates (pip's / requests'), when this machine has them
WHEELS=${FORESIGHT_WHEELHOUSE_DIR:-${PIP_FIND_LINKS:-$(python3 -m pip config get global.find-links 2>/dev/null || true)}}
WHEELHOUSE=scratch
if [ -n "$WHEELS" ] && [ -d "$WHEELS" ]; then
  printf 'FROM scratch\nCOPY . /\n' | DOCKER_BUILDKIT=1 docker build -q -f - -t "$WHEELHOUSE_IMAGE" "$WHEELS" >/dev/null
  WHEELHOUSE=$WHEELHOUSE_IMAGE
fi
CA=${FORESIGHT_CA_BUNDLE:-${PIP_CERT:-${REQUESTS_CA_BUNDLE:-${SSL_CERT_FILE:-}}}}
SECRET=()
if [ -n "$CA" ] && [ -f "$CA" ]; then SECRET=(--secret "id=ca,src=$CA"); fi

# 3. the image
say "building $IMAGE on $BASE (wheelhouse: $WHEELHOUSE${WHEELS:+ from $WHEELS}; extra CA: ${CA:-none})"
t=$(now)
DOCKER_BUILDKIT=1 docker build --build-arg "BASE_IMAGE=$BASE" --build-arg "WHEELHOUSE=$WHEELHOUSE" ${SECRET[@]+"${SECRET[@]}"} \
  -t "$IMAGE" . > "$OUT/build.log" 2>&1 || fail "docker build (see $OUT/build.log)"
size=$(docker image inspect "$IMAGE" --format '{{.Size}}' | awk '{ printf "%.2f GB", $1 / 1e9 }')
say "built $IMAGE in $(secs "$t" "$(now)") s, $size"

# 4. up, wait for the executor, down
run_stack() {  # $1: label; sets MCAP, UP_S (up -> executor done), FIRST_PLAN_S (up -> first plan)
  local label=$1 t0 code
  compose down --remove-orphans >/dev/null 2>&1 || true
  t0=$(now)
  STACK_UP=1  # whatever happens next, nothing is left running (on_exit)
  FORESIGHT_BASE_IMAGE=$BASE FORESIGHT_WHEELHOUSE=$WHEELHOUSE compose up -d --no-build > "$OUT/up-$label.log" 2>&1 \
    || { compose logs --no-color > "$OUT/compose-$label.log" 2>&1; compose down >/dev/null 2>&1; fail "up (see $OUT/up-$label.log, $OUT/compose-$label.log)"; }
  timeout 900 docker compose -p "$PROJECT" "${FILES[@]}" wait executor > /dev/null 2>&1 || true
  UP_S=$(secs "$t0" "$(now)")
  code=$(docker inspect "$(compose ps -a -q executor)" --format '{{if .State.Running}}still running{{else}}{{.State.ExitCode}}{{end}}' \
    2>/dev/null || echo "unknown (no executor container)")
  compose logs --no-color --timestamps > "$OUT/compose-$label.log" 2>&1 || true
  PREPARE_S=$(docker inspect "$(compose ps -a -q prepare)" --format '{{.State.StartedAt}} {{.State.FinishedAt}}' \
    | "$PY" -c "import sys, datetime as d; a, b = (d.datetime.fromisoformat(x[:26].rstrip('Z')) for x in sys.stdin.read().split()); print(f'{(b - a).total_seconds():.1f}')" \
    2>/dev/null || echo "?")
  compose down --remove-orphans > "$OUT/down-$label.log" 2>&1 || fail "down (see $OUT/down-$label.log)"
  STACK_UP=0
  left=$(docker ps -q --filter "label=com.docker.compose.project=$PROJECT")
  [ -z "$left" ] || fail "containers still running after down: $left"
  [ "$code" = 0 ] || fail "executor exited with '$code' (see $OUT/compose-$label.log)"
  MCAP=$(grep -o 'mcap: runs/[^ ]*\.mcap' "$OUT/compose-$label.log" | tail -1 | cut -d' ' -f2 || true)
  [ -n "$MCAP" ] && [ -f "$MCAP" ] || fail "the executor named no MCAP in runs/ (see $OUT/compose-$label.log)"
  FIRST_PLAN_S=$("$PY" - "$MCAP" "$t0" <<'EOF'
import sys
from mcap.reader import make_reader
with open(sys.argv[1], "rb") as f:
    first = min(m.log_time for _, c, m in make_reader(f).iter_messages(topics=["foresight/planner/plan"]))
print(f"{first / 1e9 - float(sys.argv[2]):.1f}")
EOF
)
  "$FORESIGHT" log info "$MCAP" > "$OUT/info-$label.txt" || fail "foresight log info $MCAP"
  grep -q "complete" "$OUT/info-$label.txt" || fail "$MCAP is not complete: $(head -1 "$OUT/info-$label.txt")"
  "$FORESIGHT" log table "$MCAP" > "$OUT/table-$label.txt" || fail "foresight log table $MCAP"
  say "$label: up -> first plan $FIRST_PLAN_S s, up -> executor done $UP_S s (prepare $PREPARE_S s); $MCAP complete; down: nothing left running"
}

# the step table without its plan times (a row's last whole number: the costs and times have a decimal point, the
# belief after it none): they differ from run to run, the belief does not; by position it failed with long goal names
strip_ms() { awk '/^ *[0-9]+ / { for (i = NF; i > 1; i--) if ($i ~ /^[0-9]+$/) { $i = ""; break } } { print }' "$1"; }

run_stack first
cat "$OUT/table-first.txt"
if [ "$DEMO" = 1 ]; then
  say "the same scenario with foresight demo on the host"
  "$FORESIGHT" demo --json --run-dir "$OUT/demo" > "$OUT/demo.json" 2> "$OUT/demo.log" || fail "foresight demo (see $OUT/demo.log)"
  demo_mcap=$("$PY" -c "import json, sys; print(json.load(open(sys.argv[1]))['mcap_path'])" "$OUT/demo.json")
  "$FORESIGHT" log table "$demo_mcap" > "$OUT/table-demo.txt"
  if diff <(strip_ms "$OUT/table-demo.txt") <(strip_ms "$OUT/table-first.txt") > "$OUT/table.diff"; then
    say "step table (goal and costs per step, switch step, reached step, interference) identical to foresight demo's"
  else
    fail "the step table differs from foresight demo's (see $OUT/table.diff)"
  fi
fi
if [ "$TWICE" = 1 ]; then
  first_prepare=$PREPARE_S
  models_before=$(ls -l --time-style=+%s.%N models/*.npz 2>/dev/null || true)
  run_stack second
  diff <(strip_ms "$OUT/table-first.txt") <(strip_ms "$OUT/table-second.txt") > /dev/null \
    || fail "the second run's table differs from the first's"
  [ "$(ls -l --time-style=+%s.%N models/*.npz 2>/dev/null || true)" = "$models_before" ] || fail "the second up wrote models/ again"
  say "second up: the trained model reused (models/ untouched; prepare $PREPARE_S s, first $first_prepare s), the same table"
fi
say "passed"
