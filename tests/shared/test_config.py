"""Config precedence (defaults < TOML < env < flag) and one-line errors for bad values."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import pytest

from shared.config import ConfigError, ZenohConfig, add_config_arguments, opt, parse_value, resolve_config


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
    assert z == ZenohConfig() and z.multicast_scouting is False


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


def test_parse_value_types():
    assert parse_value("x", bool, "on") is True
    assert parse_value("x", int, 3.0) == 3
    with pytest.raises(ConfigError):
        parse_value("x", int, 3.5)
    with pytest.raises(ConfigError):
        parse_value("x", float, True)
    assert parse_value("x", Path | None, "~/a") == Path("~/a").expanduser()
    assert parse_value("x", list[str], "a, b,") == ["a", "b"]
