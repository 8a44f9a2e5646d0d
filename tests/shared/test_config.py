"""Config precedence (defaults < TOML < env < flag) and one-line errors for bad values."""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

import pytest

from shared.config import (
    ConfigError,
    ZenohConfig,
    add_config_arguments,
    config_options,
    nested,
    opt,
    parse_value,
    resolve_config,
)


@dataclasses.dataclass
class DemoCfg:
    rate_hz: float = opt(30.0, help="rate")
    mode: str = opt("realtime", choices=("realtime", "lockstep"), help="mode")
    classes: list[int] = opt(default_factory=list, help="classes")
    loop: bool = opt(False, help="loop")
    library: Path | None = opt(None, help="library")

    def validate(self) -> None:
        if self.rate_hz <= 0:
            raise ConfigError(f"demo.rate_hz: must be > 0, got {self.rate_hz}")


def parse(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_config_arguments(p, "demo", DemoCfg)
    return p.parse_args(argv)


def write(tmp_path: Path, text: str) -> Path:
    f = tmp_path / "c.toml"
    f.write_text(text)
    return f


def test_defaults():
    cfg, z = resolve_config("demo", DemoCfg, parse([]), env={})
    assert cfg == DemoCfg()
    assert z == ZenohConfig(role="observer") and z.multicast_scouting is False  # demo is no role: the observer's
    _, zp = resolve_config("planner", DemoCfg, parse([]), env={})
    assert zp.role == "planner"  # a service presents its own certificate (with security)


def test_precedence_file_env_flag(tmp_path):
    f = write(tmp_path, '[demo]\nrate_hz = 10\nclasses = [1, 2]\n[zenoh]\nconnect = ["tcp/127.0.0.1:9000"]\n')
    cfg, z = resolve_config("demo", DemoCfg, parse(["--config", str(f)]), env={})
    assert cfg.rate_hz == 10 and cfg.classes == [1, 2] and z.connect == ["tcp/127.0.0.1:9000"]
    env = {"FORESIGHT_DEMO_RATE_HZ": "20", "FORESIGHT_ZENOH_CONNECT": "tcp/127.0.0.1:9001,tcp/127.0.0.1:9002"}
    cfg, z = resolve_config("demo", DemoCfg, parse(["--config", str(f)]), env=env)
    assert cfg.rate_hz == 20 and cfg.classes == [1, 2]
    assert z.connect == ["tcp/127.0.0.1:9001", "tcp/127.0.0.1:9002"]
    cfg, z = resolve_config("demo", DemoCfg, parse(["--config", str(f), "--rate-hz", "40", "--connect",
                                                    "tcp/127.0.0.1:9003"]), env=env)
    assert cfg.rate_hz == 40 and z.connect == ["tcp/127.0.0.1:9003"]


def test_config_file_from_env(tmp_path):
    f = write(tmp_path, "[demo]\nloop = true\n")
    cfg, _ = resolve_config("demo", DemoCfg, parse([]), env={"FORESIGHT_CONFIG": str(f)})
    assert cfg.loop is True
    cfg, _ = resolve_config("demo", DemoCfg, parse(["--no-loop"]), env={"FORESIGHT_CONFIG": str(f)})
    assert cfg.loop is False
    with pytest.raises(ConfigError, match=r"not found \(the file \$FORESIGHT_CONFIG names\)"):  # a forgotten export
        resolve_config("demo", DemoCfg, parse([]), env={"FORESIGHT_CONFIG": str(f) + ".missing"})


def test_a_refused_value_names_where_it_was_set(tmp_path):
    """`rate_hz = -5` in a file was refused without naming the file (a wrong type named it)."""
    f = write(tmp_path, "[demo]\nrate_hz = -5\n")
    with pytest.raises(ConfigError, match=rf"^demo.rate_hz: must be > 0, got -5.0 \(set by config file '{f}'\)$"):
        resolve_config("demo", DemoCfg, parse(["--config", str(f)]), env={})
    with pytest.raises(ConfigError, match=r"got -2.0 \(set by FORESIGHT_DEMO_RATE_HZ\)$"):
        resolve_config("demo", DemoCfg, parse([]), env={"FORESIGHT_DEMO_RATE_HZ": "-2"})
    with pytest.raises(ConfigError, match=r"got -1.0 \(set by --rate-hz\)$"):
        resolve_config("demo", DemoCfg, parse(["--config", str(f), "--rate-hz", "-1"]), env={})


def test_section_field_shadowing_a_zenoh_flag():
    @dataclasses.dataclass
    class WithMode:
        mode: str = opt("a", choices=("a", "b"), help="own mode")

    p = argparse.ArgumentParser()
    add_config_arguments(p, "x", WithMode)
    cfg, z = resolve_config("x", WithMode, p.parse_args(["--mode", "b", "--zenoh-mode", "client"]), env={})
    assert cfg.mode == "b" and z.mode == "client"
    with pytest.raises(ConfigError, match="--zenoh-mode: 'x' is not one of"):
        resolve_config("x", WithMode, p.parse_args(["--zenoh-mode", "x"]), env={})


@pytest.mark.parametrize(("argv", "env", "pattern"), [
    (["--rate-hz", "fast"], {}, r"^--rate-hz: expected float, got 'fast'$"),
    (["--rate-hz", "nan"], {}, r"^--rate-hz: expected float"),
    (["--rate-hz", "-1"], {}, r"^demo\.rate_hz: must be > 0"),
    (["--mode", "warp"], {}, r"^--mode: 'warp' is not one of realtime, lockstep$"),
    (["--classes", "1,x"], {}, r"^--classes: expected int, got 'x'$"),
    ([], {"FORESIGHT_DEMO_LOOP": "maybe"}, r"^FORESIGHT_DEMO_LOOP: expected bool"),
    ([], {"FORESIGHT_ZENOH_MODE": "hub"}, r"^FORESIGHT_ZENOH_MODE: 'hub' is not one of"),
    (["--connect", "localhost"], {}, r"zenoh\.connect: endpoint 'localhost' is not of the form"),
    (["--prefix", "a/*"], {}, r"zenoh\.prefix"),
    (["--prefix", "a//b"], {}, r"^zenoh\.prefix: 'a//b' must be a Zenoh key"),
    (["--prefix", "cell#1"], {}, r"^zenoh\.prefix: 'cell#1' must be a Zenoh key.*\(it has #\)"),
    (["--prefix", "robot?x"], {}, r"\(it has \?\)"),
    (["--prefix", "lab$1"], {}, r"\(it has \$\)"),
    # an empty connect (a blank $ROUTER) ran a service nothing could reach, without a word
    ([], {"FORESIGHT_ZENOH_CONNECT": ""}, r"zenoh\.connect: empty, and this peer listens on no fixed port .*"
                                          r"nothing can reach it.*\(set by FORESIGHT_ZENOH_CONNECT\)"),
    # a client listens on nothing: "this client listens on no fixed port" named the wrong cause
    (["--zenoh-mode", "client", "--connect", ""], {},
     r"^zenoh\.connect: empty, and a client reaches only the endpoints it connects to \(scouting off\): it would "
     r"reach nothing"),
])
def test_bad_values(argv, env, pattern):
    with pytest.raises(ConfigError, match=pattern):
        resolve_config("demo", DemoCfg, parse(argv), env=env)


def test_bad_files(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        resolve_config("demo", DemoCfg, parse(["--config", str(tmp_path / "none.toml")]), env={})
    with pytest.raises(ConfigError, match="c.toml"):
        resolve_config("demo", DemoCfg, parse(["--config", str(write(tmp_path, "[demo\n"))]), env={})
    with pytest.raises(ConfigError, match=r"\[demo\]: unknown option\(s\) speed"):
        resolve_config("demo", DemoCfg, parse(["--config", str(write(tmp_path, "[demo]\nspeed = 1\n"))]), env={})
    with pytest.raises(ConfigError, match="demo.rate_hz: expected float"):
        resolve_config("demo", DemoCfg, parse(["--config", str(write(tmp_path, '[demo]\nrate_hz = "x"\n'))]),
                       env={})
    with pytest.raises(ConfigError, match="top-level key 'rate_hz'"):
        resolve_config("demo", DemoCfg, parse(["--config", str(write(tmp_path, "rate_hz = 3\n"))]), env={})
    # a number or a boolean written as a string in TOML was read as one; as text only env and flags are
    for line, kind in (('rate_hz = "3"', "float"), ('loop = "true"', "bool"), ('classes = ["1"]', "int")):
        with pytest.raises(ConfigError, match=rf"expected {kind}, got the string .* without quotes"):
            resolve_config("demo", DemoCfg, parse(["--config", str(write(tmp_path, f"[demo]\n{line}\n"))]), env={})
    assert resolve_config("demo", DemoCfg, parse([]), env={"FORESIGHT_DEMO_RATE_HZ": "3"})[0].rate_hz == 3.0


def test_parse_value_types():
    assert parse_value("x", bool, "on") is True
    assert parse_value("x", int, 3.0) == 3
    with pytest.raises(ConfigError):
        parse_value("x", int, 3.5)
    with pytest.raises(ConfigError):
        parse_value("x", float, True)
    assert parse_value("x", Path | None, "~/a") == Path("~/a").expanduser()
    assert parse_value("x", list[str], "a, b,") == ["a", "b"]


@pytest.mark.parametrize(("tp", "text", "value"), [(int, "5", 5), (int, "5.0", 5), (int, " -3 ", -3),
                                                   (float, "1e3", 1000.0), (float, ".5", 0.5), (float, "-2.25", -2.25)])
def test_numbers_as_text_read_as_a_file_would_hold_them(tp, text, value):
    assert parse_value("x", tp, text) == value and type(parse_value("x", tp, text)) is tp


@pytest.mark.parametrize(("tp", "text"), [(int, "1_000"), (int, "\u0663"), (int, "0x10"), (int, "5.5"), (int, ""),
                                          (float, "1_0.5"), (float, "\u0663"), (float, "inf"), (float, "nan"),
                                          (float, "1e999")])
def test_numbers_python_would_read_but_no_file_holds_are_refused(tp, text):
    """int() and float() take underscores and any script's digits: FORESIGHT_X=1_000 was 1000."""
    with pytest.raises(ConfigError, match=f"x: expected {tp.__name__}, got"):
        parse_value("x", tp, text)


# ----------------------------------------------------------------------------------------------
# nested component configs


@dataclasses.dataclass
class Inner:
    """A component.

    Attributes:
        steps: How many steps.
        device: Set by the parent.
    """

    steps: int = 5
    gain: float = 1.0  # the component's gain
    device: str = "cpu"

    def validate(self) -> None:
        if self.steps < 1:
            raise ValueError(f"inner.steps must be >= 1, got {self.steps}")


@dataclasses.dataclass
class Core:
    device: str = opt("cpu", help="device")
    inner: Inner = nested(Inner, help="the inner component", hide=("device",))

    def validate(self) -> None:
        self.inner.validate()


@dataclasses.dataclass
class Service:
    period_s: float = opt(0.5, help="period")
    core: Core = nested(Core, inline=True)


def test_nested_options_have_one_name_each() -> None:
    opts = {o.name: o for o in config_options("svc", Service)}
    assert list(opts) == ["svc.period_s", "svc.device", "svc.inner.steps", "svc.inner.gain"]  # device hidden
    steps = opts["svc.inner.steps"]
    assert (steps.attrs, steps.env, steps.flag) == (("core", "inner", "steps"), "FORESIGHT_SVC_INNER_STEPS",
                                                    "--inner.steps")
    assert opts["svc.device"].attrs == ("core", "device") and opts["svc.device"].flag == "--device"
    assert steps.help == "How many steps" and opts["svc.inner.gain"].help == "the component's gain"


def test_nested_precedence_file_env_flag(tmp_path) -> None:
    p = argparse.ArgumentParser()
    add_config_arguments(p, "svc", Service)
    f = write(tmp_path, "[svc]\ndevice = 'cuda'\nperiod_s = 2\n[svc.inner]\nsteps = 7\ngain = 3\n")
    cfg, _ = resolve_config("svc", Service, p.parse_args(["--config", str(f)]), env={})
    assert cfg == Service(period_s=2.0, core=Core(device="cuda", inner=Inner(steps=7, gain=3.0)))
    env = {"FORESIGHT_SVC_INNER_STEPS": "8", "FORESIGHT_SVC_DEVICE": "cpu"}
    cfg, _ = resolve_config("svc", Service, p.parse_args(["--config", str(f), "--inner.gain", "4"]), env=env)
    assert (cfg.core.device, cfg.core.inner.steps, cfg.core.inner.gain, cfg.period_s) == ("cpu", 8, 4.0, 2.0)


# [svc.inner] device is hidden (set by the parent); [svc] core is inline, no table of its own
@pytest.mark.parametrize(("text", "argv", "env", "pattern"), [
    ("[svc.inner]\nsteps = 0\n", [], {}, r"^svc: inner\.steps must be >= 1, got 0$"),
    ("[svc.inner]\nspeed = 1\n", [], {}, r"^config file '.*c\.toml': \[svc\.inner\]: unknown option\(s\) speed$"),
    ("[svc.inner]\ndevice = 'cuda'\n", [], {},
     r"^config file '.*c\.toml': \[svc\.inner\]: unknown option\(s\) device$"),
    ("[svc]\ninner = 3\n", [], {}, r"^config file '.*c\.toml': \[svc\.inner\]: must be a table"),
    ("[svc]\ncore = {}\n", [], {}, r"^config file '.*c\.toml': \[svc\.core\]: unknown table \(\[svc\] has "
     r"\[svc\.inner\]\)$"),
    ("[svc.innr]\nsteps = 2\n", [], {},  # it said "[svc]: unknown option(s) innr; did you mean inner?"
     r"^config file '.*c\.toml': \[svc\.innr\]: unknown table; did you mean \[svc\.inner\]\?$"),
    ("[svc.inner]\nsteps = 'many'\n", [], {}, r"^config file '.*c\.toml': svc\.inner\.steps: expected int"),
    ("", ["--inner.steps", "x"], {}, r"^--inner\.steps: expected int, got 'x'$"),
    ("", [], {"FORESIGHT_SVC_INNER_GAIN": "fast"}, r"^FORESIGHT_SVC_INNER_GAIN: expected float"),
])
def test_nested_bad_values_are_named(tmp_path, text, argv, env, pattern) -> None:
    p = argparse.ArgumentParser()
    add_config_arguments(p, "svc", Service)
    with pytest.raises(ConfigError, match=pattern):
        resolve_config("svc", Service, p.parse_args(["--config", str(write(tmp_path, text)), *argv]), env=env)


def test_help_groups_nested_tables(capsys) -> None:
    p = argparse.ArgumentParser()
    add_config_arguments(p, "svc", Service)
    with pytest.raises(SystemExit):
        p.parse_args(["--help"])
    out = capsys.readouterr().out
    assert "[svc] options (env FORESIGHT_SVC_<NAME>)" in out
    assert "[svc.inner] options (env FORESIGHT_SVC_INNER_<NAME>, flags --inner.<name>)" in out
    assert "the inner component" in out and "--inner.steps STEPS" in out and "--device" in out


def test_clashing_names_are_a_config_bug() -> None:
    @dataclasses.dataclass
    class Clash:
        inner_steps: int = opt(1, help="clashes with inner.steps in the environment")
        inner: Inner = nested(Inner)

    with pytest.raises(ValueError, match="share env FORESIGHT_X_INNER_STEPS"):
        config_options("x", Clash)


SERVICE_CONFIGS = {
    "replayer": "services.replayer.core:ReplayerConfig",
    "predictor": "services.predictor.core:PredictorConfig",
    "planner": "services.planner.config:PlannerServiceConfig",
    "executor": "services.executor.core:ExecutorConfig",
}


@pytest.mark.parametrize("service", sorted(SERVICE_CONFIGS))
def test_service_help_shows_every_option_of_its_config_tree(service, capsys) -> None:
    """One flag per field of the section's tree (nested configs as --<table>.<name>), each with a help text."""
    import importlib

    from shared.config import config_options

    module, cls_name = SERVICE_CONFIGS[service].split(":")
    options = config_options(service, getattr(importlib.import_module(module), cls_name))
    main = importlib.import_module(f"services.{service}.__main__").main
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for o in options:
        assert o.help, f"{o.name} has no help text"
        assert re.search(rf"^\s+{re.escape(o.flag)}\b", out, re.M), f"{o.flag} ({o.name}) missing from --help"
    tables = {o.table for o in options}
    for table in tables:
        assert f"[{'.'.join(table)}] options (env FORESIGHT_{'_'.join(table).upper()}_<NAME>" in out
    if service == "planner":
        assert {("planner",), ("planner", "stomp"), ("planner", "cost")} == tables
        assert "--stomp.iterations" in out and "--cost.w-human" in out
    assert ":meth:" not in out and "``" not in out  # docstring markup is made plain


def test_a_prefix_zenoh_takes_is_taken():
    _, z = resolve_config("demo", DemoCfg, parse(["--prefix", "cell-1/robot_2"]), env={})
    assert z.prefix == "cell-1/robot_2"


def test_a_config_file_that_is_not_utf8_is_named(tmp_path):
    bad = tmp_path / "latin1.toml"
    bad.write_bytes("[demo]\nmode = 'caf\xe9'\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"^config file '.*latin1\.toml': .*utf-8"):
        resolve_config("demo", DemoCfg, parse(["--config", str(bad)]), env={})


def test_an_empty_connect_is_fine_where_others_can_reach_this_session():
    for argv in (["--connect", "", "--listen", "tcp/127.0.0.1:7450"], ["--connect", "", "--zenoh-mode", "router"]):
        assert resolve_config("demo", DemoCfg, parse(argv), env={})[1].connect == []


def test_a_path_whose_home_cannot_be_found_and_a_directory_as_config_are_one_line(tmp_path):
    """'~nosuchuser/m.npz' was a RuntimeError traceback from every path option; a directory 'not found'."""
    with pytest.raises(ConfigError, match=r"FORESIGHT_DEMO_LIBRARY: cannot expand '~' in '~nosuchuser-x/lib' "
                                          r"\(no such user"):
        resolve_config("demo", DemoCfg, parse([]), env={"FORESIGHT_DEMO_LIBRARY": "~nosuchuser-x/lib"})
    with pytest.raises(ConfigError, match="is a directory, not a TOML file"):
        resolve_config("demo", DemoCfg, parse(["--config", str(tmp_path)]), env={})


def test_an_empty_path_from_the_environment_is_unset_and_a_number_is_no_path(tmp_path):
    assert resolve_config("demo", DemoCfg, parse([]), env={"FORESIGHT_DEMO_LIBRARY": ""})[0].library is None
    # unset: the file's path stands (the empty variable gave the default, the synthetic library, over the file's)
    conf = write(tmp_path, "[demo]\nlibrary = 'mine.npz'\n")
    for empty in ("", "  "):
        got = resolve_config("demo", DemoCfg, parse(["--config", str(conf)]), env={"FORESIGHT_DEMO_LIBRARY": empty})
        assert got[0].library == Path("mine.npz")
    with pytest.raises(ConfigError, match=r"demo\.library: expected Path, got 5"):
        resolve_config("demo", DemoCfg, parse(["--config", str(write(tmp_path, "[demo]\nlibrary = 5\n"))]), env={})


def test_an_empty_path_flag_is_refused_not_taken_as_unset(tmp_path):
    """``--library ""`` silently cleared the file's path, where ``FORESIGHT_DEMO_LIBRARY=`` leaves it."""
    conf = write(tmp_path, "[demo]\nlibrary = 'mine.npz'\n")
    for empty in ("", "  "):
        with pytest.raises(ConfigError, match=r"^--library: empty; give a path \(leave the flag out to keep"):
            resolve_config("demo", DemoCfg, parse(["--config", str(conf), "--library", empty]), env={})


@pytest.mark.parametrize(("option", "endpoint"), [
    ("connect", "tcp/127.0.0.1:abc"), ("connect", "tcp/127.0.0.1:99999"), ("connect", "tls/router"),
    ("connect", "tcp/127.0.0.1:0"), ("connect", "tcp/:7447"), ("listen", "udp/127.0.0.1:-1")])
def test_an_endpoint_without_a_host_and_port_is_refused_by_the_config(option: str, endpoint: str) -> None:
    """``--connect tcp/127.0.0.1:abc`` was taken: the session retried for ever and the replayer played to no one."""
    with pytest.raises(ConfigError, match=rf"zenoh\.{option}: endpoint '{re.escape(endpoint)}' is not of the form "
                       r"proto/HOST:PORT \(a port [01]-65535\): .* \(set by FORESIGHT_ZENOH_"):
        resolve_config("demo", DemoCfg, parse([]), env={f"FORESIGHT_ZENOH_{option.upper()}": endpoint})


def test_endpoints_of_a_host_and_port_or_a_path_are_taken() -> None:
    env = {"FORESIGHT_ZENOH_CONNECT": "tcp/[::1]:7447,tls/router:7447,unixsock-stream//tmp/z.sock",
           "FORESIGHT_ZENOH_LISTEN": "tcp/127.0.0.1:0"}
    zen = resolve_config("demo", DemoCfg, parse([]), env=env)[1]
    assert zen.connect == ["tcp/[::1]:7447", "tls/router:7447", "unixsock-stream//tmp/z.sock"]
    assert zen.listen == ["tcp/127.0.0.1:0"]
