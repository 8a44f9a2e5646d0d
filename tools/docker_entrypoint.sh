#!/bin/sh
# The image's entrypoint: run the command as the owner of the mounted runs/ directory (docs/docker.md).
#
# A container starts as root and steps down to the user who owns /app/runs (the clone's ./runs), so what it writes
# into models/ and runs/ is that user's, whatever their uid, with nothing to set. Before, compose ran every container
# as 1000:1000: a plain `docker compose up` by any other user (root included) failed in `prepare` with
# "Permission denied" after a minute of training, and a secure cell's keys (0600, their maker's) were unreadable.
# A container started as another user already (`docker run --user`, compose `user:`) runs as that user; a runs/
# owned by root runs the command as root. FORESIGHT_RUN_AS=UID:GID names another user (FORESIGHT_RUNS_DIR: the
# directory whose owner it is, for tests). Every refusal is one line naming what was wrong.
set -eu
say() { echo "foresight-entrypoint: $*" >&2; }
# chown -R of the compile cache, a volume the other containers share: the planner compiling in one of them adds and
# removes files meanwhile, and a file gone mid-walk is no error (under set -e it ended the container, 3 starts in 20
# of a review); any other failure is one warning and the command runs regardless (the cache is only a cache)
own_cache() {
  errors=$(LC_ALL=C chown -R -h "$uid:$gid" "$1" 2>&1 >/dev/null) && return 0
  first=$(printf '%s\n' "$errors" | while IFS= read -r line; do
    case $line in *": No such file or directory" | "") ;; *) echo "$line"; break ;; esac
  done)
  if [ -n "$first" ]; then say "warning: $1 is not wholly $uid:$gid's, kernels may be compiled again: $first"; fi
}
if [ "$(id -u)" = 0 ]; then
  runs=${FORESIGHT_RUNS_DIR:-/app/runs}
  if [ -n "${FORESIGHT_RUN_AS:-}" ]; then
    owner=$FORESIGHT_RUN_AS
    case $owner in
      *[!0-9:]* | :* | *: | *:*:* | [!0-9]* ) say "FORESIGHT_RUN_AS=$owner is not UID:GID (numbers)"; exit 2 ;;
      *:*) ;;
      *) say "FORESIGHT_RUN_AS=$owner is not UID:GID (numbers)"; exit 2 ;;
    esac
  elif [ -d "$runs" ]; then
    owner=$(stat -c %u:%g "$runs")
  else
    say "$runs is not a directory: mount the clone's runs/ there (compose.yaml does), or set FORESIGHT_RUN_AS=UID:GID"
    exit 2
  fi
  uid=${owner%%:*} gid=${owner#*:}
  if [ "$uid" != 0 ]; then
    if ! command -v setpriv >/dev/null 2>&1; then
      say "setpriv (util-linux) is missing from this image: cannot run as $owner, the owner of $runs; running as root"
      exec "$@"
    fi
    HOME=/tmp/foresight-home-$uid  # the image's /home/foresight is uid 1000's
    mkdir -p "$HOME" && chown -h "$uid:$gid" "$HOME"
    cache=${TORCHINDUCTOR_CACHE_DIR:-}  # a volume kept from one up to the next, perhaps filled by another user
    if [ -n "$cache" ] && [ -d "$cache" ]; then own_cache "$cache"; fi
    export HOME USER="$uid"
    exec setpriv --reuid="$uid" --regid="$gid" --clear-groups -- "$@"
  fi
fi
exec "$@"
