"""Misspelt sections and variables are errors naming the closest valid name (issue 24)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import pytest

from shared.config import ConfigError, ZenohConfig, add_config_arguments, opt, resolve_config
from shared.config_names import SECTIONS, check_environment, check_file_sections, section_class


@dataclasses.dataclass
class Svc:
    rate_hz: float = opt(30.0, help="rate")
    log_level: str = opt("INFO", help="level")


def test_every_section_names_its_config_class() -> None:
    for section in SECTIONS:
        cls = section_class(section)
        assert dataclasses.is_dataclass(cls), section


def test_unknown_file_section_names_the_closest() -> None:
    with pytest.raises(ConfigError, match=r"unknown section \[zenho\]; did you mean zenoh\?"):
        check_file_sections({"zenho": {}})
    with pytest.raises(ConfigError, match=r"unknown section \[replayr\]; did you mean replayer\?"):
        check_file_sections({"replayer": {}, "replayr": {}})
    with pytest.raises(ConfigError, match=r"unknown section \[xyz\] \(sections: zenoh, "):
        check_file_sections({"xyz": {}})
    check_file_sections({name: {} for name in SECTIONS})


def test_misspelt_variable_names_the_closest_option() -> None:
    checked = {"replayer": section_class("replayer"), "zenoh": ZenohConfig}
    with pytest.raises(ConfigError, match=r"FORESIGHT_REPLAYER_RATEHZ is no option of \[replayer\]; did you mean "
                                          r"FORESIGHT_REPLAYER_RATE_HZ\?"):
        check_environment({"FORESIGHT_REPLAYER_RATEHZ": "3"}, checked)
    with pytest.raises(ConfigError, match=r"FORESIGHT_ZENOH_MOD is no option of \[zenoh\]; did you mean "
                                          r"FORESIGHT_ZENOH_MODE\?"):
        check_environment({"FORESIGHT_ZENOH_MOD": "peer"}, checked)
    # a misspelt section: the closest option of any section
    with pytest.raises(ConfigError, match=r"FORESIGHT_REPLAYR_RATE_HZ is no Foresight option; did you mean "
                                          r"FORESIGHT_REPLAYER_RATE_HZ\?"):
        check_environment({"FORESIGHT_REPLAYR_RATE_HZ": "3"}, checked)
    # only the names after FORESIGHT_ compare: FOO was 'close' to the Docker build's UID for their common prefix
    with pytest.raises(ConfigError) as exc:
        check_environment({"FORESIGHT_FOO": "1"}, checked)
    assert "did you mean" not in str(exc.value) and "is no Foresight option" in str(exc.value)
    # lower case: the environment's names are case-sensitive, so it was ignored without a word
    with pytest.raises(ConfigError, match=r"foresight_replayer_rate_hz is read as nothing: .* upper case "
                                          r"\(FORESIGHT_REPLAYER_RATE_HZ\)"):
        check_environment({"foresight_replayer_rate_hz": "3"}, checked)


def test_valid_and_foreign_variables_pass() -> None:
    checked = {"replayer": section_class("replayer")}
    check_environment({"FORESIGHT_REPLAYER_RATE_HZ": "3", "FORESIGHT_CONFIG": "x.toml",
                       "FORESIGHT_BLAS_THREADS": "2", "FORESIGHT_PARENT_PID": "1",
                       "FORESIGHT_TEST_FUZZ_COUNT": "3",  # the test suite's own
                       "FORESIGHT_PLANNER_NOPE": "1",  # another section's: its own command checks it
                       "PATH": "/bin"}, checked)
    with pytest.raises(ConfigError, match="FORESIGHT_PLANNER_NOPE is no option of"):
        check_environment({"FORESIGHT_PLANNER_NOPE": "1"}, {"planner": section_class("planner")})


def test_resolve_config_checks_file_and_environment(tmp_path: Path) -> None:
    p = argparse.ArgumentParser()
    add_config_arguments(p, "replayer", Svc)
    f = tmp_path / "c.toml"
    f.write_text("[replayer]\nrate_hz = 3\n[zenho]\nmode = 'peer'\n")
    with pytest.raises(ConfigError, match=r"unknown section \[zenho\]; did you mean zenoh"):
        resolve_config("replayer", Svc, p.parse_args(["--config", str(f)]), env={})
    f.write_text("[replayer]\nratehz = 3\n")
    with pytest.raises(ConfigError, match=r"unknown option\(s\) ratehz; did you mean rate_hz\?"):
        resolve_config("replayer", Svc, p.parse_args(["--config", str(f)]), env={})
    with pytest.raises(ConfigError, match="FORESIGHT_REPLAYER_RATEHZ"):
        resolve_config("replayer", Svc, p.parse_args([]), env={"FORESIGHT_REPLAYER_RATEHZ": "3"})
    cfg, _ = resolve_config("replayer", Svc, p.parse_args([]), env={"FORESIGHT_REPLAYER_RATE_HZ": "3"})
    assert cfg.rate_hz == 3.0


@pytest.mark.parametrize("variable, meant", [("FORESIGHT_CONFG", "FORESIGHT_CONFIG"),
                                             ("FORESIGHT_BLAS_THREAD", "FORESIGHT_BLAS_THREADS"),
                                             ("FORESIGHT_ZENHO_CONNECT", "FORESIGHT_ZENOH_CONNECT"),
                                             ("FORESIGHT_PLANER_GOALS", "FORESIGHT_PLANNER_GOALS")])
def test_a_misspelt_section_or_variable_is_named_from_the_section_it_most_likely_meant(variable, meant) -> None:
    with pytest.raises(ConfigError, match=rf"{variable} is no Foresight option; did you mean {meant}\?"):
        check_environment({variable: "1"}, {"replayer": section_class("replayer")})


def test_naming_a_misspelt_section_imports_only_the_section_it_meant() -> None:
    """FORESIGHT_REPLAYR_RATE_HZ took 7.8 s to be named (every section's config imported, torch with the planner's)."""
    import subprocess
    import sys

    code = ("import sys\nfrom shared.config import ConfigError\nfrom shared.config_names import check_environment, "
            "section_class\ntry:\n    check_environment({'FORESIGHT_REPLAYR_RATE_HZ': '3'}, "
            "{'replayer': section_class('replayer')})\nexcept ConfigError as exc:\n    print(exc)\n"
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[2]).stdout.splitlines()
    assert "did you mean FORESIGHT_REPLAYER_RATE_HZ?" in out[0] and out[-1] == "False", out
