"""Each container of compose.yaml (alone and with compose.secure.yaml on top) runs a real `foresight` command whose
whole command line parses and resolves as the command itself does, and they agree on where things are: the
router listens on the port it is published on, checked on (healthcheck) and connected to, with the scheme the
clients use; the live view serves on the port it publishes; every container works in the directory its mounts
make, where the prepared file and the run's log are. The secure variant gives each service, read-only, only its
own role's files, and never makes a missing one.

A review passed the former checks with a router `--lisen` (the router was skipped), a secure router
`--securty-dir` (`--help` appended ended the parse before the unknown argument), a secure router on 7448 and its
clients on 7447, `foresight executr` (skipped), the view's port `8765:9999`, `working_dir: /srv` and the healthcheck
at 7448 (only "7447" was looked for somewhere in it).
"""

from __future__ import annotations

import ast
import contextlib
import importlib
import io
import re
import shlex
import sys
from pathlib import Path, PurePosixPath
from typing import Any

import pytest
from ruamel.yaml import YAML

import shared.config
from shared.config import ZenohConfig, config_options
from tests.test_compose import COMPOSE, FORESIGHT_SERVICES, REPO, prepared_file, schema_check
from tools.foresight import COMMANDS

SECURE = REPO / "compose.secure.yaml"
VARIANTS = {"compose.yaml": (COMPOSE,), "compose.yaml + compose.secure.yaml": (COMPOSE, SECURE)}
SECURITY_DIR = "/run/foresight/security"


def _load(path: Path) -> dict[str, Any]:
    return YAML(typ="safe").load(path.read_text())


def _interpolate(node: Any, env: dict[str, str]) -> Any:
    """``${VAR}`` and ``${VAR:-default}`` in every string, as compose substitutes them from ``env``."""
    if isinstance(node, dict):
        return {k: _interpolate(v, env) for k, v in node.items()}
    if isinstance(node, list):
        return [_interpolate(v, env) for v in node]
    if isinstance(node, str):
        return re.sub(r"\$\{(\w+)(?::-([^}]*))?\}", lambda m: env.get(m[1]) or (m[2] or ""), node)
    return node


def _target(volume: Any) -> str:
    return volume["target"] if isinstance(volume, dict) else volume.split(":")[1]


def _merge(base: Any, over: Any, key: str = "") -> Any:
    """``over`` merged onto ``base`` as compose merges its files: mappings key by key, a command or a healthcheck's test
    replaced, volumes by their target, other sequences appended."""
    if isinstance(base, dict) and isinstance(over, dict):
        return {**base, **{k: _merge(base[k], v, k) if k in base else v for k, v in over.items()}}
    if isinstance(base, list) and isinstance(over, list) and key not in ("command", "entrypoint", "test"):
        if key == "volumes":
            return [*(v for v in base if _target(v) not in {_target(o) for o in over}), *over]
        return [*base, *(v for v in over if v not in base)]
    return over


def services(files: tuple[Path, ...], env: dict[str, str] | None = None) -> dict[str, dict[str, Any]]:
    """The services of ``files`` merged in order, with the variables of ``env`` (none: every default)."""
    model: dict[str, Any] = {}
    for path in files:
        model = _merge(model, _load(path))
    return _interpolate(model, env or {})["services"]


def container_env(svc: dict[str, Any], prepared: Path) -> dict[str, str]:
    """A container's environment; the prepared config file it names (under models/compose) is ``prepared``."""
    env = {k: str(v) for k, v in (svc.get("environment") or {}).items()}
    if "FORESIGHT_CONFIG" in env:
        env["FORESIGHT_CONFIG"] = str(prepared)
    return env


class _Resolved(Exception):
    def __init__(self, configs: tuple[Any, ZenohConfig]) -> None:
        super().__init__("resolved")
        self.configs = configs


def resolve(command: Any, env: dict[str, str]) -> tuple[Any, ZenohConfig]:
    """``(section config, zenoh config)`` that a container's command runs with: the command's own ``main`` with the
    whole command line, stopped once it has resolved its options (its parser, then its file and environment: here
    ``env``), before it does anything. A command that does not exist, an argument it does not take, a bad value: a
    failure naming it."""
    assert isinstance(command, list) and command[:1] == ["foresight"], f"not a foresight command: {command}"
    name = command[1] if len(command) > 1 else ""
    assert name in COMMANDS, f"`foresight {name}`: no such command (commands: {', '.join(COMMANDS)})"
    module = importlib.import_module(COMMANDS[name][0])
    real = shared.config.resolve_config

    def stop_here(*args: Any, **kwargs: Any) -> tuple[Any, ZenohConfig]:
        raise _Resolved(real(*args, **{**kwargs, "env": env}))

    # shared.config and every module that imported it from there (a service's main's): nothing runs past it
    users = [m for m in list(sys.modules.values()) if getattr(m, "resolve_config", None) is real]
    err = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stderr(err):
        for m in users:
            mp.setattr(m, "resolve_config", stop_here)
        try:
            status = module.main(command[2:], prog=f"foresight {name}")
        except _Resolved as done:
            return done.configs
        except SystemExit as exc:
            status = exc.code
    pytest.fail(f"{shlex.join(command)}: exit status {status}: {err.getvalue().strip()}")


def _endpoint(text: str) -> tuple[str, str, int]:
    m = re.fullmatch(r"(\w+)/(.+):(\d+)", text)
    assert m, f"not an endpoint: {text}"
    return m[1], m[2], int(m[3])


def _published(entry: Any) -> tuple[str, int]:
    """``(host address, container port)`` of a ``ports`` entry."""
    if isinstance(entry, dict):
        return entry.get("host_ip", ""), int(entry["target"])
    parts = str(entry).split("/")[0].split(":")
    return (parts[0] if len(parts) == 3 else ""), int(parts[-1])


def _healthcheck_address(svc: dict[str, Any]) -> tuple[str, int]:
    """The ``(host, port)`` the healthcheck connects to (``python -c "...create_connection((HOST, PORT))..."``)."""
    test = svc["healthcheck"]["test"]
    assert test[:3] == ["CMD", "python", "-c"], test
    calls = [n for n in ast.walk(ast.parse(test[3])) if isinstance(n, ast.Call)
             and isinstance(n.func, ast.Attribute) and n.func.attr == "create_connection"]
    assert len(calls) == 1, test
    return ast.literal_eval(calls[0].args[0])


@pytest.fixture(scope="module")
def prepared(tmp_path_factory) -> Path:
    return prepared_file(tmp_path_factory.mktemp("prepared"))[0]


@pytest.mark.parametrize("variant, service", [(v, s) for v, files in VARIANTS.items() for s in services(files)])
def test_each_containers_whole_command_parses_and_resolves(variant: str, service: str, prepared: Path) -> None:
    svc = services(VARIANTS[variant])[service]
    resolve(svc["command"], container_env(svc, prepared))


@pytest.mark.parametrize("variant", VARIANTS)
def test_the_router_listens_where_it_is_published_checked_and_connected_to(variant: str, prepared: Path) -> None:
    stack = services(VARIANTS[variant])
    router = stack["router"]
    _, z = resolve(router["command"], container_env(router, prepared))
    assert len(z.listen) == 1, z.listen
    scheme, host, port = _endpoint(z.listen[0])
    assert host == "0.0.0.0"  # every address of its container: the others' connections and the published port
    assert [_published(p) for p in router["ports"]] == [("127.0.0.1", port)]
    assert _healthcheck_address(router) == ("127.0.0.1", port)
    assert scheme == ("tls" if SECURE in VARIANTS[variant] else "tcp")
    for name, svc in stack.items():
        if name in ("router", "prepare"):
            continue
        _, client = resolve(svc["command"], container_env(svc, prepared))
        assert [_endpoint(e) for e in client.connect] == [(scheme, "router", port)], name
        assert client.mode == "client" and client.listen == [] and not client.multicast_scouting, name


@pytest.mark.parametrize("variant", VARIANTS)
def test_the_live_view_serves_on_the_port_it_publishes(variant: str, prepared: Path) -> None:
    view = services(VARIANTS[variant])["view"]
    cfg, _ = resolve(view["command"], container_env(view, prepared))
    assert cfg.host == "0.0.0.0"  # inside its container, so that the port can be published
    assert [_published(p) for p in view["ports"]] == [("127.0.0.1", cfg.port)]  # on this host's loopback only


def test_the_router_is_published_on_loopback_unless_another_address_is_given(prepared: Path) -> None:
    """The secure variant is for a cell spread over several machines: the router's port must be reachable from
    them, which the loopback-only port of compose.yaml never was (FORESIGHT_ROUTER_ADDR)."""
    for files in VARIANTS.values():
        assert _published(services(files)["router"]["ports"][0]) == ("127.0.0.1", 7447)
        wide = services(files, {"FORESIGHT_ROUTER_ADDR": "0.0.0.0"})["router"]
        assert _published(wide["ports"][0]) == ("0.0.0.0", 7447)
        assert _published(wide["ports"][0])[1] == _endpoint(resolve(wide["command"], {})[1].listen[0])[2]
    for doc in (SECURE, REPO / "docs" / "docker.md", REPO / "docs" / "security.md"):
        assert "FORESIGHT_ROUTER_ADDR" in doc.read_text(), doc


def test_every_container_works_in_the_directory_its_mounts_make(prepared: Path) -> None:
    """The working directory is the image's, /app, where models/ and runs/ are mounted: the prepared file, the
    model cache and the run's log, all relative paths, are in the clone."""
    workdir = PurePosixPath(re.search(r"^WORKDIR (\S+)$", (REPO / "Dockerfile").read_text(), re.M)[1])
    stack = services((COMPOSE,))
    for name, svc in stack.items():
        assert PurePosixPath(svc["working_dir"]) == workdir, name
        binds = {PurePosixPath(v["target"]): v["source"] for v in svc["volumes"] if isinstance(v, dict)}
        assert binds[workdir / "models"] == "./models" and binds[workdir / "runs"] == "./runs", name
    demo, _ = resolve(stack["prepare"]["command"], {})
    assert (workdir / demo.prepare).is_relative_to(workdir / "models")
    assert (workdir / demo.models_dir).is_relative_to(workdir / "models")
    for name in (*FORESIGHT_SERVICES, "view"):
        assert PurePosixPath(stack[name]["environment"]["FORESIGHT_CONFIG"]) == demo.prepare / "foresight.toml", name
    executor, _ = resolve(stack["executor"]["command"], container_env(stack["executor"], prepared))
    assert (workdir / (executor.mcap or "runs/run.mcap")).is_relative_to(workdir / "runs")  # empty: runs/<time>.mcap


def test_the_secure_variant_gives_each_service_only_its_own_role_read_only() -> None:
    """Every Zenoh session on TLS with its role's certificate; the router `foresight router --security` (its access
    control from the same generator). Each file is mounted with create_host_path false: a missing one fails `up`
    naming it, where the short syntax made a root-owned directory there and `security init` then failed."""
    ok = schema_check(SECURE)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    secure = _load(SECURE)["services"]
    assert sorted(secure) == sorted(name for name in _load(COMPOSE)["services"] if name != "prepare")
    zenoh_options = {o.env for o in config_options("zenoh", ZenohConfig)}
    for name, svc in secure.items():
        role = "observer" if name == "view" else name  # the live view reads, as displays do
        for m in svc["volumes"]:
            assert m["type"] == "bind" and m["read_only"] is True and m["bind"] == {"create_host_path": False}, name
            assert PurePosixPath(m["target"]).name == Path(m["source"]).name, name
        files = sorted(PurePosixPath(m["target"]) for m in svc["volumes"])
        assert files == sorted(PurePosixPath(SECURITY_DIR, f) for f in ("ca.crt", f"{role}.crt", f"{role}.key")), name
        if name != "router":
            assert svc["environment"]["FORESIGHT_ZENOH_SECURITY_DIR"] == SECURITY_DIR
            assert set(svc["environment"]) <= zenoh_options, name
    merged = services(VARIANTS["compose.yaml + compose.secure.yaml"])
    _, router = resolve(merged["router"]["command"], container_env(merged["router"], Path("unused")))
    assert router.security_dir == SECURITY_DIR and router.mode == "router"
    for name, svc in merged.items():  # nothing of the host's but models/, runs/ and the role's own files
        role = "observer" if name == "view" else name
        own = [] if name == "prepare" else [f"./security/{f}" for f in ("ca.crt", f"{role}.crt", f"{role}.key")]
        assert sorted(v["source"] for v in svc["volumes"] if isinstance(v, dict)) == ["./models", "./runs", *own], name
