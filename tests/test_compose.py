"""compose.yaml and Dockerfile: schema-valid compose file, configuration that the services understand,
no multicast scouting, and the Dockerfile installing what the Makefile installs (no Docker engine here)."""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import io
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from ruamel.yaml import YAML  # comes with check-jsonschema (dev extra), which this test needs anyway

from shared.cli import COMMANDS
from shared.config import ConfigError, ZenohConfig, parse_value

REPO = Path(__file__).resolve().parents[1]
COMPOSE = REPO / "compose.yaml"
CHECK = shutil.which("check-jsonschema") or str(Path(sys.executable).parent / "check-jsonschema")

# service section -> its config dataclass, for the sections that exist as services
SECTIONS = {
    "zenoh": "shared.config:ZenohConfig",
    "executor": "services.executor.core:ExecutorConfig",
    "replayer": "services.replayer.core:ReplayerConfig",
    "predictor": "services.predictor.core:PredictorConfig",
    "planner": "services.planner.core:PlannerConfig",
}


def compose() -> dict:
    return YAML(typ="safe").load(COMPOSE.read_text())


def _check(path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([CHECK, "--builtin-schema", "vendor.compose-spec", str(path)], capture_output=True,
                          text=True, timeout=120)


def test_compose_file_is_valid_against_the_compose_spec(tmp_path) -> None:
    ok = _check(COMPOSE)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    # the validator does catch mistakes
    bad = tmp_path / "compose.yaml"
    bad.write_text(COMPOSE.read_text().replace("condition: service_completed_successfully",
                                               "condition: when_it_feels_like_it", 1))
    res = _check(bad)
    assert res.returncode != 0 and "when_it_feels_like_it" in res.stdout + res.stderr


def test_services_router_volumes_and_dependencies() -> None:
    c = compose()
    services = c["services"]
    assert {"router", "train", "replayer", "predictor", "planner", "executor"} <= set(services)
    assert services["router"]["image"].startswith("eclipse/zenoh:")
    assert "--no-multicast-scouting" in services["router"]["command"]
    assert "tcp/0.0.0.0:7447" in services["router"]["command"]
    for name, svc in services.items():
        for dep in svc.get("depends_on", {}):
            assert dep in services, f"{name} depends on unknown service {dep}"
        if name == "router":
            continue
        assert svc["image"] == services["executor"]["image"] and svc["build"]["context"] == "."
        assert "./models:/app/models" in svc["volumes"] and "./runs:/app/runs" in svc["volumes"]
    assert services["predictor"]["depends_on"]["train"]["condition"] == "service_completed_successfully"
    assert set(services["executor"]["depends_on"]) >= {"router", "replayer", "predictor", "planner"}


def _env_items():
    for name, svc in compose()["services"].items():
        for key, value in (svc.get("environment") or {}).items():
            if key.startswith("FORESIGHT_"):
                yield name, key, value


@pytest.mark.parametrize("service, key, value", list(_env_items()))
def test_environment_variables_name_real_options(service, key, value) -> None:
    section, _, field = key[len("FORESIGHT_"):].lower().partition("_")
    target = SECTIONS.get(section)
    assert target is not None, f"{service}: {key} names no known section"
    module, cls_name = target.split(":")
    try:
        cls = getattr(importlib.import_module(module), cls_name)
    except (ImportError, AttributeError):
        pytest.skip(f"{module}.{cls_name} does not exist yet")
    import typing

    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    assert field in fields, f"{service}: {key}: {cls_name} has no option {field!r} (has {sorted(fields)})"
    try:
        parse_value(key, hints[field], str(value), fields[field].metadata.get("choices"))
    except ConfigError as exc:
        pytest.fail(f"{service}: {exc}")


def test_every_service_is_a_zenoh_client_of_the_router_without_scouting() -> None:
    for name, svc in compose()["services"].items():
        if name in ("router", "train"):
            continue
        env = svc["environment"]
        assert env["FORESIGHT_ZENOH_CONNECT"] == "tcp/router:7447"
        assert env["FORESIGHT_ZENOH_MULTICAST_SCOUTING"] == "false"
        z = ZenohConfig(mode=env["FORESIGHT_ZENOH_MODE"], connect=[env["FORESIGHT_ZENOH_CONNECT"]],
                        listen=parse_value("listen", list[str], env["FORESIGHT_ZENOH_LISTEN"]))
        z.validate()


def _foresight_invocations():
    for name, svc in compose()["services"].items():
        cmd = svc.get("command")
        if not cmd or name == "router":
            continue
        text = cmd[-1] if cmd[0] == "sh" else shlex.join(cmd)
        for part in re.split(r"&&|\|\||;|\{|\}", text):
            tokens = shlex.split(part)
            if tokens and tokens[0] == "foresight":
                yield name, tokens[1:]


@pytest.mark.parametrize("service, args", list(_foresight_invocations()))
def test_commands_and_flags_exist(service, args) -> None:
    command = args[0]
    if command not in COMMANDS:
        pytest.skip(f"foresight {command} is not registered yet")
    module = importlib.import_module(COMMANDS[command][0])
    sub = [args[1]] if len(args) > 1 and not args[1].startswith("-") else []
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as exc:
        module.main([*sub, "--help"], prog=f"foresight {command}")
    assert exc.value.code == 0
    for flag in (a for a in args[1:] if a.startswith("--")):
        assert flag in out.getvalue(), f"{service}: foresight {command} {' '.join(sub)} has no {flag}"


def test_dockerfile_installs_what_the_makefile_installs() -> None:
    docker = (REPO / "Dockerfile").read_text()
    make = (REPO / "Makefile").read_text()
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text())
    torch_make = set(re.findall(r"^TORCH_VERSION \?= ([\w.+]+)$", make, re.M))
    torch_docker = set(re.findall(r"torch==([\w.+]+)", docker))
    assert len(torch_make) == 1 and torch_docker == torch_make
    # the same default build: PyTorch's CPU index
    index_make = re.search(r"^TORCH_INDEX \?= (\S+)$", make, re.M)
    index_docker = re.search(r"^ARG TORCH_INDEX_URL=(\S+)$", docker, re.M)
    assert index_make and index_docker and index_make[1] == index_docker[1] == "https://download.pytorch.org/whl/cpu"
    # base image: python:3.11-slim, which satisfies requires-python
    base = re.search(r"^FROM\s+python:(\d+)\.(\d+)-slim\s*$", docker, re.M)
    assert base is not None
    need = re.match(r">=\s*(\d+)\.(\d+)", pyproject["project"]["requires-python"])
    assert (int(base[1]), int(base[2])) >= (int(need[1]), int(need[2]))
    # torch before the project (as in the Makefile), then the project from the copied sources
    runs = [ln for ln in re.findall(r"^RUN (.*(?:\n .*)*)", docker, re.M)]
    flat = " ".join(runs)
    assert flat.index("torch==") < flat.index("pip install .")
    stamp = re.search(r"^\$\(STAMP\):.*\n((?:\t.*\n)+)", make, re.M)
    assert stamp is not None and stamp[1].index("torch") < stamp[1].index('install --quiet -e ".[dev]"')
    assert '--index-url "$(TORCH_INDEX)"' in make and 'install "torch==$(TORCH_VERSION)"' in make
    copied = re.findall(r"^COPY (\S+)", docker, re.M)
    assert {"pyproject.toml", "shared", "services"} <= set(copied)
    # the build context keeps out what the image must not carry
    ignored = (REPO / ".dockerignore").read_text().split()
    assert {".venv", ".git", "models", "runs"} <= set(ignored)
    assert "shared" not in ignored and "services" not in ignored
