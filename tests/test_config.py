"""Strict configuration loading: every kind of bad input is one line naming file, key and problem."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from common.params import param
from hil import config, settings
from hil.config import DEFAULT_CONFIG
from hil.errors import ConfigError


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "c.toml"
    p.write_text(text)
    return p


def _default_text() -> str:
    return DEFAULT_CONFIG.read_text()


def test_default_config_loads_into_frozen_dataclasses():
    cfg = settings.load()
    assert cfg.vessel.m == 55.0
    assert cfg.sim.dt == 0.01
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.vessel.m = 1.0  # type: ignore[misc]


def test_default_config_round_trips_through_to_table(tmp_path):
    import tomllib

    cfg = settings.load()
    table = config.to_table(cfg)
    again = config.from_table(settings.HilConfig, table, "round-trip")
    assert again == cfg
    # and the original file parses to the same table where keys are shared
    raw = tomllib.loads(_default_text())
    assert raw["vessel"] == table["vessel"]


@pytest.mark.parametrize(
    "old, new, expected",
    [
        ("m = 55.0 ", "m = -55.0 ", "vessel.m: must be > 0 kg (got -55.0)"),
        ("T_max = 119.68", "T_max = 0.0", "vessel.T_max: must be > 0 N (got 0.0)"),
        ("T_min = -66.71", "T_min = 5.0", "vessel.T_min: must be <= 0 N (got 5.0)"),
        ("dt = 0.01 ", "dt = 0.0 ", "sim.dt: must be > 0 s (got 0.0)"),
        ("dt = 0.01 ", 'dt = "fast" ', "sim.dt: expected a number, got 'fast'"),
        ("enabled = true\namplitude", "enabled = 1\namplitude", "waves.enabled: expected true or false, got 1"),
        ("seed = 1\n", "seed = 1.5\n", "sim.seed: expected an integer, got 1.5"),
        ('state_to = ["127.0.0.1:14560"]', 'state_to = "127.0.0.1:14560"', "link.state_to: expected an array, got str"),
    ],
)
def test_bad_values_name_file_key_and_problem(tmp_path, old, new, expected):
    text = _default_text()
    assert old in text, old
    p = _write(tmp_path, text.replace(old, new, 1))
    with pytest.raises(ConfigError) as exc:
        settings.load(p)
    msg = str(exc.value)
    assert msg == f"{p}: {expected}"
    assert "\n" not in msg


def test_unknown_key_is_rejected(tmp_path):
    p = _write(tmp_path, _default_text().replace("[vessel]\n", "[vessel]\nmass_typo = 3.0\n", 1))
    with pytest.raises(ConfigError, match=r"vessel\.mass_typo: unknown key"):
        settings.load(p)


def test_unknown_section_is_rejected(tmp_path):
    p = _write(tmp_path, _default_text() + "\n[nonsense]\nx = 1\n")
    with pytest.raises(ConfigError, match=r": nonsense: unknown key"):
        settings.load(p)


def test_a_key_left_out_of_a_file_keeps_its_default(tmp_path):
    # --config files are laid over configs/default.toml (issue 16): a file without a key keeps the
    # default (this replaced the earlier "missing key" rejection of incomplete files).
    text = _default_text()
    p = _write(tmp_path, text.replace("d_r = 100.0", "", 1))
    assert settings.load(p).vessel.d_r == 100.0


def test_a_missing_key_is_still_rejected_where_a_schema_has_no_default():
    with pytest.raises(ConfigError, match=r"t\.toml: s\.hi: missing key"):
        config.from_table(_Cross, {"lo": 0, "pair": [1, 2]}, "t.toml", "s")


def test_missing_file_and_bad_toml_are_one_line(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        settings.load(tmp_path / "nope.toml")
    p = _write(tmp_path, "[vessel\nm = 1")
    with pytest.raises(ConfigError, match="not valid TOML") as exc:
        settings.load(p)
    assert "\n" not in str(exc.value)


def test_overrides_apply_and_are_validated():
    cfg = settings.load(None, ["current.enabled=false", "vessel.m=60", "link.commands_on=127.0.0.1:15000"])
    assert cfg.current.enabled is False
    assert cfg.vessel.m == 60.0
    assert cfg.link.commands_on == "127.0.0.1:15000"  # a bare word that is not TOML is a string
    with pytest.raises(ConfigError, match=r"--set vessel\.nope=1: unknown key vessel\.nope"):
        settings.load(None, ["vessel.nope=1"])
    with pytest.raises(ConfigError, match=r"--set nosection\.x=1: unknown key nosection"):
        settings.load(None, ["nosection.x=1"])
    with pytest.raises(ConfigError, match=r"expected section\.key=value"):
        settings.load(None, ["vessel.m"])
    with pytest.raises(ConfigError, match=r"vessel\.m: must be > 0"):
        settings.load(None, ["vessel.m=-1"])


@dataclasses.dataclass(frozen=True)
class _Cross:
    lo: float = param("lower", "m")
    hi: float = param("upper", "m")
    pair: tuple[float, float] = param("a pair", ge=0)

    def __post_init__(self) -> None:
        if self.hi <= self.lo:
            raise ValueError(f"hi: must be above lo ({self.lo}), got {self.hi}")


def test_cross_field_rules_and_tuples():
    ok = config.from_table(_Cross, {"lo": 0, "hi": 1, "pair": [1, 2]}, "t.toml", "s")
    assert ok.pair == (1.0, 2.0) and isinstance(ok.lo, float)
    with pytest.raises(ConfigError, match=r"^t\.toml: s\.hi: must be above lo"):
        config.from_table(_Cross, {"lo": 1, "hi": 0, "pair": [1, 2]}, "t.toml", "s")
    with pytest.raises(ConfigError, match=r"s\.pair: expected an array of 2 items, got 3"):
        config.from_table(_Cross, {"lo": 0, "hi": 1, "pair": [1, 2, 3]}, "t.toml", "s")
    with pytest.raises(ConfigError, match=r"s\.pair: must be >= 0 \(got -1.0\)"):
        config.from_table(_Cross, {"lo": 0, "hi": 1, "pair": [-1, 2]}, "t.toml", "s")
    with pytest.raises(ConfigError, match=r"s\.lo: expected a number, got True"):
        config.from_table(_Cross, {"lo": True, "hi": 1, "pair": [1, 2]}, "t.toml", "s")
