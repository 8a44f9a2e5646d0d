# One image for every Foresight service (see compose.yaml). The install steps are the Makefile's / README's:
# torch 2.13.0 (the CPU build) first, then the project itself.
FROM python:3.11-slim

# Where the torch CPU wheel comes from; build with --build-arg TORCH_INDEX_URL= to take it from PyPI instead.
ARG TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    MPLBACKEND=Agg

WORKDIR /app

# a C++ compiler for torch.compile (inductor): the planner's fused cost is compiled at start-up
# (without one it falls back to eager mode, about 3x slower per cost evaluation)
RUN apt-get update \
 && apt-get install -y --no-install-recommends g++ \
 && rm -rf /var/lib/apt/lists/*

# torch first, pinned to the CPU wheel (an unpinned torch pulls a multi-GB CUDA build)
RUN python -m pip install --upgrade pip \
 && if [ -n "$TORCH_INDEX_URL" ]; then \
        python -m pip install --index-url "$TORCH_INDEX_URL" "torch==2.13.0"; \
    else \
        python -m pip install "torch==2.13.0"; \
    fi

COPY pyproject.toml README.md ./
COPY shared ./shared
COPY services ./services
COPY tools ./tools
RUN python -m pip install . \
 && mkdir -p /app/models /app/runs

# every service is a `foresight` sub-command; compose.yaml picks one per container
CMD ["foresight", "--help"]
