#!/bin/sh
# The image's entrypoint: run the command as the owner of the mounted runs/ directory (docs/docker.md).
#
# A container starts as root and steps down to the user who owns /app/runs (the clone's ./runs), so what it writes
# into models/ and runs/ is that user's, whatever their uid, with nothing to set. Before, compose ran every container
# as 1000:1000: a plain `docker compose up` by any other user (root included) failed in `prepare` with
# "Permission denied" after a minute of training, and a secure cell's keys (0600, their maker's) were unreadable.
# A container started as another user already (`docker run --user`, compose `user:`) runs as that user; a runs/
# owned by root runs the command as root. FORESIGHT_RUN_AS=UID:GID names another user (FORESIGHT_RUNS_DIR: the
# directory whose owner it is, for tests).
set -eu
if [ "$(id -u)" = 0 ]; then
  owner=${FORESIGHT_RUN_AS:-$(stat -c %u:%g "${FORESIGHT_RUNS_DIR:-/app/runs}")}
  if [ "${owner%%:*}" != 0 ]; then
    HOME=/tmp/foresight-home-${owner%%:*}  # the image's /home/foresight is uid 1000's
    mkdir -p "$HOME" && chown "$owner" "$HOME"
    export HOME
    exec setpriv --reuid="${owner%%:*}" --regid="${owner#*:}" --clear-groups -- "$@"
  fi
fi
exec "$@"
