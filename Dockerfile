# One image for every Foresight service (see compose.yaml); tools/compose_check.sh builds and runs it.
# The install steps are the Makefile's: torch 2.13.0 (the CPU build) first, then the project itself.
#
# Builds anywhere, including behind an intercepting proxy and without Docker Hub (docs/docker.md):
#   BASE_IMAGE       a Debian-based image with Python 3.11+ (default: the official python:3.11-slim); where
#                    Docker Hub cannot be reached, tools/compose_check.sh makes one with debootstrap
#   WHEELHOUSE       an image or build context whose root holds wheels to prefer (e.g. torch's CPU wheel from a
#                    local mirror): `--build-context wheelhouse=DIR` (BuildKit >= 0.10), or an image
#                    `--build-arg WHEELHOUSE=foresight-wheelhouse:local` (older engines); default: none
#   secret "ca"      extra CA certificates (PEM) that pip and apt must trust, e.g. a proxy's:
#                    `--secret id=ca,src=/etc/ssl/certs/ca-certificates.crt`; used while building, never stored
#   secret "pipconf" a pip.conf (another index, credentials): `--secret id=pipconf,src=pip.conf`; never stored
#   TORCH_INDEX_URL  where torch comes from when the wheelhouse has none (default: PyTorch's CPU index;
#                    empty: pip's own indexes)
# BuildKit is needed (RUN --mount): Docker >= 23 uses it by default, Docker 20.10 with DOCKER_BUILDKIT=1.
ARG BASE_IMAGE=python:3.11-slim
ARG WHEELHOUSE=scratch

FROM ${WHEELHOUSE} AS wheelhouse

FROM ${BASE_IMAGE}
ARG TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    MPLBACKEND=Agg \
    VIRTUAL_ENV=/opt/venv \
    PATH=/opt/venv/bin:$PATH \
    USER=foresight \
    HOME=/home/foresight \
    TORCHINDUCTOR_CACHE_DIR=/tmp/torchinductor

WORKDIR /app

# setpriv (the entrypoint steps down with it; util-linux, or its own package on newer Debian), a C++ compiler and
# Python's headers for torch.compile (inductor): the planner's fused cost is compiled at
# start-up (without them it falls back to eager mode, about 3x slower per cost evaluation); venv and headers
# come with python:3.11-slim, a bare Debian base image gets them from its packages
RUN --mount=type=secret,id=ca \
    set -e; \
    extra=/usr/local/share/ca-certificates/foresight-build-extra.crt; \
    if [ -s /run/secrets/ca ] && command -v update-ca-certificates >/dev/null; then \
        cp /run/secrets/ca "$extra"; update-ca-certificates >/dev/null; fi; \
    pkgs="g++ ca-certificates"; \
    python3 -c "import venv, ensurepip" 2>/dev/null || pkgs="$pkgs python3-venv"; \
    python3 -c "import os, sysconfig as s; assert os.path.isfile(s.get_paths()['include'] + '/Python.h')" 2>/dev/null \
        || pkgs="$pkgs python3-dev"; \
    apt-get update; \
    command -v setpriv >/dev/null 2>&1 \
        || pkgs="$pkgs $(apt-cache show setpriv >/dev/null 2>&1 && echo setpriv || echo util-linux)"; \
    apt-get install -y --no-install-recommends $pkgs; \
    command -v setpriv >/dev/null; \
    rm -rf /var/lib/apt/lists/*; \
    if [ -f "$extra" ]; then rm "$extra"; update-ca-certificates --fresh >/dev/null; fi

RUN python3 -m venv /opt/venv \
 && useradd --create-home --uid 1000 --user-group foresight \
 && mkdir -p /app/models /app/runs /tmp/torchinductor \
 && chown foresight:foresight /app/models /app/runs \
 && chmod 1777 /tmp/torchinductor

# torch first, pinned to the CPU build (an unpinned torch pulls a multi-GB CUDA build): the wheelhouse's
# when it has one (that wheel and no other: an unusable one fails here, never falls back to PyPI's CUDA
# build), its dependencies from the index; else TORCH_INDEX_URL's
RUN --mount=type=secret,id=ca --mount=type=secret,id=pipconf,target=/etc/pip.conf \
    --mount=type=bind,from=wheelhouse,target=/wheelhouse \
    set -e; \
    if [ -s /run/secrets/ca ]; then cat /etc/ssl/certs/ca-certificates.crt /run/secrets/ca > /tmp/ca.pem; \
        export PIP_CERT=/tmp/ca.pem; fi; \
    pip install --quiet --upgrade pip; \
    if ls /wheelhouse/torch-2.13.0* >/dev/null 2>&1; then \
        pip install --no-deps --no-index --find-links /wheelhouse "torch==2.13.0"; \
        pip install "torch==2.13.0"; \
    elif [ -n "$TORCH_INDEX_URL" ]; then \
        pip install --index-url "$TORCH_INDEX_URL" "torch==2.13.0"; \
    else \
        pip install "torch==2.13.0"; \
    fi; \
    rm -f /tmp/ca.pem

COPY pyproject.toml README.md ./
COPY shared ./shared
COPY services ./services
COPY tools ./tools
RUN --mount=type=secret,id=ca --mount=type=secret,id=pipconf,target=/etc/pip.conf \
    --mount=type=bind,from=wheelhouse,target=/wheelhouse \
    set -e; \
    if [ -s /run/secrets/ca ]; then cat /etc/ssl/certs/ca-certificates.crt /run/secrets/ca > /tmp/ca.pem; \
        export PIP_CERT=/tmp/ca.pem; fi; \
    pip install --find-links /wheelhouse . ; \
    rm -f /tmp/ca.pem; \
    foresight --help >/dev/null

# started as root, every command runs as the owner of the mounted runs/ (tools/docker_entrypoint.sh; the image's
# own /app/runs is uid 1000's, so a container without mounts runs as foresight)
COPY --chmod=755 tools/docker_entrypoint.sh /usr/local/bin/foresight-entrypoint
ENTRYPOINT ["/usr/local/bin/foresight-entrypoint"]

# every service is a `foresight` sub-command; compose.yaml picks one per container
CMD ["foresight", "--help"]
