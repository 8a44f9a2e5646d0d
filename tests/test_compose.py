"""compose.yaml and Dockerfile: schema-valid compose file, configuration that the services understand,
no multicast scouting, a stack that starts in any order, runs the scenario of `foresight demo` (its prepared
config file) and ends with its executor, and the Dockerfile installing what the Makefile installs (each container's
command and the addresses they share, the secure variant: tests/test_compose_commands.py; the run itself:
tests/test_compose_run.py, where a Docker engine answers)."""

from __future__ import annotations

import importlib
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from ruamel.yaml import YAML  # comes with check-jsonschema (dev extra), which this test needs anyway

from shared.config import ConfigError, ZenohConfig, config_options, parse_value, resolve_config

REPO = Path(__file__).resolve().parents[1]
COMPOSE = REPO / "compose.yaml"
CHECK = shutil.which("check-jsonschema") or str(Path(sys.executable).parent / "check-jsonschema")

# service section -> its config dataclass, for the sections that exist as services
SECTIONS = {
    "zenoh": "shared.config:ZenohConfig",
    "executor": "services.executor.config:ExecutorConfig",
    "replayer": "services.replayer.core:ReplayerConfig",
    "predictor": "services.predictor.core:PredictorConfig",
    "planner": "services.planner.config:PlannerServiceConfig",
}


def compose() -> dict:
    return YAML(typ="safe").load(COMPOSE.read_text())


def schema_check(path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([CHECK, "--builtin-schema", "vendor.compose-spec", str(path)], capture_output=True,
                          text=True, timeout=120)


def test_compose_file_is_valid_against_the_compose_spec(tmp_path) -> None:
    ok = schema_check(COMPOSE)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    # the validator does catch mistakes
    bad = tmp_path / "compose.yaml"
    bad.write_text(COMPOSE.read_text().replace("condition: service_completed_successfully",
                                               "condition: when_it_feels_like_it", 1))
    res = schema_check(bad)
    assert res.returncode != 0 and "when_it_feels_like_it" in res.stdout + res.stderr


def test_services_router_volumes_and_dependencies() -> None:
    c = compose()
    services = c["services"]
    assert {"router", "prepare", "replayer", "predictor", "planner", "executor"} <= set(services)
    # the router comes from the project image (Docker Hub may be out of reach): `foresight router`
    assert services["router"]["command"][:2] == ["foresight", "router"]
    assert "--no-multicast-scouting" in services["router"]["command"]
    assert "tcp/0.0.0.0:7447" in services["router"]["command"]  # its port published, checked, connected to: see
    # tests/test_compose_commands.py
    for name, svc in services.items():
        for dep in svc.get("depends_on", {}):
            assert dep in services, f"{name} depends on unknown service {dep}"
        assert svc["image"] == services["executor"]["image"] and svc["build"]["context"] == "."
        binds = {v["source"]: v for v in svc["volumes"] if isinstance(v, dict) and v.get("type") == "bind"}
        for d in ("models", "runs"):  # never made by the engine (as root): the clone holds them
            assert binds[f"./{d}"]["target"] == f"/app/{d}" and binds[f"./{d}"]["bind"]["create_host_path"] is False
            assert (REPO / d / ".gitkeep").is_file()
        assert svc["init"] is True and "user" not in svc  # the entrypoint runs it as the owner of runs/
    for name in FORESIGHT_SERVICES:
        deps = services[name]["depends_on"]
        assert deps["prepare"]["condition"] == "service_completed_successfully", name
        assert deps["router"]["condition"] == "service_healthy", name
    assert set(services["executor"]["depends_on"]) >= {"router", "replayer", "predictor", "planner"}
    assert services["prepare"]["command"] == ["foresight", "demo", "--prepare", "models/compose"]


FORESIGHT_SERVICES = ("replayer", "predictor", "planner", "executor")


def service_config(name: str, prepared: Path | None = None):
    """``(section config, zenoh config)`` of a compose service, resolved from its environment as the
    service itself resolves it (defaults < the prepared file, when given < environment)."""
    module, cls_name = SECTIONS[name].split(":")
    cls = getattr(importlib.import_module(module), cls_name)
    env = {k: str(v) for k, v in compose()["services"][name]["environment"].items()}
    env.pop("FORESIGHT_CONFIG")
    return resolve_config(name, cls, None, env=env, config_file=prepared)


def test_the_stack_starts_in_any_order() -> None:
    """Nothing relies on start order: a client retries until the router listens (bounded, logged), the
    executor waits for the other three's liveliness, and any service_healthy condition has a healthcheck."""
    services = compose()["services"]
    for name in FORESIGHT_SERVICES:
        _, z = service_config(name)
        assert z.mode == "client" and z.connect == ["tcp/router:7447"], name
        assert z.connect_timeout_s > 0, f"{name}: a client that starts before the router listens must retry"
        assert services[name]["environment"]["FORESIGHT_CONFIG"] == "models/compose/foresight.toml", name
    executor, _ = service_config("executor")
    assert set(executor.wait_for) == {"replayer", "predictor", "planner"} and executor.startup_timeout_s > 0
    for name, svc in services.items():
        for dep, spec in (svc.get("depends_on") or {}).items():
            if spec["condition"] == "service_healthy":
                assert "healthcheck" in services[dep], f"{name} waits for {dep} to be healthy; it has no healthcheck"


@pytest.fixture(scope="module")
def prepared(tmp_path_factory) -> tuple[Path, dict[str, list[str]]]:
    return prepared_file(tmp_path_factory.mktemp("prepared"))


def prepared_file(directory: Path) -> tuple[Path, dict[str, list[str]]]:
    """The config file `foresight demo --prepare` writes for the demo's defaults, and the flags the demo passes."""
    import tomli_w

    from services.demo import DemoConfig
    from services.demo_prepare import config_tables
    from services.demo_services import service_options

    options = service_options(DemoConfig(), Path("models/demo-x.npz"), Path("models/compose/human.npz"), 5, None)
    path = directory / "foresight.toml"
    path.write_text(tomli_w.dumps(config_tables({name: options[name] for name in (*FORESIGHT_SERVICES, "view")})))
    return path, options


def test_the_prepared_file_gives_each_service_the_demos_options(prepared) -> None:
    """Each service resolves from the prepared file exactly what it resolves from the demo's flags, so that the
    compose stack runs the demo's scenario (tools/compose_check.sh compares their step tables for real)."""
    import argparse

    from shared.config import add_config_arguments

    path, options = prepared
    for name in FORESIGHT_SERVICES:
        module, cls_name = SECTIONS[name].split(":")
        cls = getattr(importlib.import_module(module), cls_name)
        parser = argparse.ArgumentParser()
        add_config_arguments(parser, name, cls, with_zenoh=False)
        from_flags, _ = resolve_config(name, cls, parser.parse_args(options[name]), env={}, with_zenoh=False)
        from_file, _ = resolve_config(name, cls, None, env={}, config_file=path, with_zenoh=False)
        assert from_file == from_flags, name
        assert from_file != cls(), f"{name}: the demo sets none of its options?"
    # and compose's own variables on top leave the scenario as it is
    planner, _ = service_config("planner", path)
    executor, _ = service_config("executor", path)
    assert planner.planner.velocity_scale == 0.1 and planner.mode == executor.mode == "lockstep"
    assert executor.step_period_s == 0.5 and executor.finish_path and executor.steps == 20


def test_the_run_ends_cleanly_with_its_executor(prepared) -> None:
    services = compose()["services"]
    path, _ = prepared
    executor, _ = service_config("executor", path)
    assert executor.steps > 0 and services["executor"].get("restart", "no") == "no"
    assert services["prepare"].get("restart", "no") == "no"
    for name in ("replayer", "predictor", "planner"):
        cfg, _ = service_config(name, path)
        assert "executor" in cfg.stop_with, f"{name} would run on after the executor ends"
        assert services[name].get("restart", "no") == "no", f"{name} would be restarted after it ends"
    # lock-step throughout: a real-time planner never answers the executor's ticks
    assert executor.mode == "lockstep"
    assert service_config("planner", path)[0].mode == service_config("replayer", path)[0].mode == "lockstep"


def _env_items():
    for name, svc in compose()["services"].items():
        for key, value in (svc.get("environment") or {}).items():
            if key.startswith("FORESIGHT_"):
                yield name, key, value


@pytest.mark.parametrize("service, key, value", list(_env_items()))
def test_environment_variables_name_real_options(service, key, value) -> None:
    from shared.config_names import OTHER_VARIABLES

    if key in OTHER_VARIABLES:
        return
    section = key[len("FORESIGHT_"):].lower().partition("_")[0]
    target = SECTIONS.get(section)
    assert target is not None, f"{service}: {key} names no known section"
    module, cls_name = target.split(":")
    try:
        cls = getattr(importlib.import_module(module), cls_name)
    except (ImportError, AttributeError):
        pytest.skip(f"{module}.{cls_name} does not exist yet")
    options = {o.env: o for o in config_options(section, cls)}
    assert key in options, f"{service}: {key}: {cls_name} has no such option (has {sorted(options)})"
    try:
        parse_value(key, options[key].tp, str(value), options[key].choices)
    except ConfigError as exc:
        pytest.fail(f"{service}: {exc}")


def test_every_service_is_a_zenoh_client_of_the_router_without_scouting() -> None:
    for name, svc in compose()["services"].items():
        if name in ("router", "prepare"):
            continue
        env = svc["environment"]
        assert env["FORESIGHT_ZENOH_CONNECT"] == "tcp/router:7447"
        assert env["FORESIGHT_ZENOH_MULTICAST_SCOUTING"] == "false"
        z = ZenohConfig(mode=env["FORESIGHT_ZENOH_MODE"], connect=[env["FORESIGHT_ZENOH_CONNECT"]],
                        listen=parse_value("listen", list[str], env["FORESIGHT_ZENOH_LISTEN"]))
        z.validate()


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
    base = re.search(r"^ARG BASE_IMAGE=python:(\d+)\.(\d+)-slim\s*$", docker, re.M)
    assert base is not None
    need = re.match(r">=\s*(\d+)\.(\d+)", pyproject["project"]["requires-python"])
    assert (int(base[1]), int(base[2])) >= (int(need[1]), int(need[2]))
    # torch before the project (as in the Makefile), then the project from the copied sources
    runs = [ln for ln in re.findall(r"^RUN (.*(?:\n .*)*)", docker, re.M)]
    flat = " ".join(runs)
    assert flat.index("torch==") < flat.index("pip install --find-links /wheelhouse .")
    stamp = re.search(r"^\$\(STAMP\):.*\n((?:\t.*\n)+)", make, re.M)
    assert stamp is not None and stamp[1].index("torch") < stamp[1].index('-e ".[dev]"')
    assert '--index-url "$(TORCH_INDEX)"' in make and 'install "torch==$(TORCH_VERSION)"' in make
    copied = re.findall(r"^COPY (\S+)", docker, re.M)
    assert {"pyproject.toml", "shared", "services", "tools"} <= set(copied)
    # the build context keeps out what the image must not carry
    ignored = (REPO / ".dockerignore").read_text().split()
    assert {".venv", ".git", "models", "runs"} <= set(ignored)
    assert not {"shared", "services", "tools"} & set(ignored)


def _strip_ms(table: str, tmp_path: Path) -> str:
    """The check's ``strip_ms`` (tools/compose_check.sh) applied to ``table``."""
    path = tmp_path / "table.txt"
    path.write_text(table)
    line = next(x for x in (REPO / "tools/compose_check.sh").read_text().splitlines() if x.startswith("strip_ms()"))
    return subprocess.run(["bash", "-c", f'{line}\nstrip_ms "$1"', "strip", str(path)], capture_output=True, text=True,
                          check=True, timeout=30).stdout


def test_the_checks_table_comparison_drops_the_plan_times_and_keeps_the_beliefs(tmp_path) -> None:
    """It dropped each row's last field, which became the belief (p=0.13) when that column was filled: the plan
    times stayed in and the check failed on every machine."""
    from services.run_table import table_header, table_row

    goals = ["red_cup", "blue_cup"]

    def table(ms: float, belief: str) -> str:
        rows = [table_row({"step": s, "t_s": 0.5 * s, "chosen": "red_cup", "planning_ms": ms * (s + 1),
                           "cost_total": {"red_cup": 1.5 / (s + 1), "blue_cup": 2.0}}, goals, belief if s else "")
                for s in range(3)]
        return "\n".join([table_header(goals), *rows, "switch step: none"]) + "\n"

    long = ["the_very_long_cup_name", "red_cup"]  # wider than the table's columns: cut by position, it lost letters
    rows = [table_header(long), table_row({"step": 1, "t_s": 0.5, "chosen": "the_very_long_cup_name",
                                           "planning_ms": 12345.0, "cost_total": {n: 1.25 for n in long}}, long,
                                          "far_left p=0.13")]
    assert _strip_ms("\n".join(rows) + "\n", tmp_path).splitlines()[1].split() == [
        "1", "0.50", "the_very_long_cup_name", "1.250", "1.250", "far_left", "p=0.13"]
    first = _strip_ms(table(7125.0, "far_left p=0.13"), tmp_path)
    assert first == _strip_ms(table(74.0, "far_left p=0.13"), tmp_path)  # only the plan times differ
    assert first != _strip_ms(table(74.0, "far_left p=0.99"), tmp_path)  # a belief differs
    assert "7125" not in first and "p=0.13" in first and "1.500" in first and "switch step: none" in first
