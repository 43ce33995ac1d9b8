"""Layered configuration (issue 16): partial --config files over the defaults, in order, then --set;
errors that name the file or --set that gave the value and the nearest key; finite numbers in range;
scenario files whose paths are relative to themselves. In-process through hil.cli.main."""

from __future__ import annotations

import shutil

import pytest

from hil import cli, config, scenario, settings
from hil.config import CONFIG_DIR
from hil.errors import ConfigError


def _run_config_error(argv, capsys) -> str:
    rc = cli.main(argv)
    assert rc == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    return err


def test_partial_files_lay_over_the_defaults_in_order_then_set(tmp_path):
    a = tmp_path / "a.toml"
    a.write_text("[vessel]\nm = 60.0\n[sim]\nseed = 7\n")
    b = tmp_path / "b.toml"
    b.write_text("[vessel]\nm = 61.0\n[sensors.gps]\nrate_hz = 2.0\n")
    cfg = settings.load([a, b], ["sim.seed=9"])
    default = settings.load()
    assert cfg.vessel.m == 61.0 and cfg.sim.seed == 9 and cfg.sensors.gps.rate_hz == 2.0
    assert cfg.vessel.d_u == default.vessel.d_u and cfg.sensors.imu == default.sensors.imu
    assert settings.load([b, a]).vessel.m == 60.0


def test_a_complete_copy_of_the_defaults_still_works(tmp_path):
    p = tmp_path / "full.toml"
    shutil.copy(config.DEFAULT_CONFIG, p)
    assert settings.load(p) == settings.load()


@pytest.mark.parametrize("text, expected", [
    ("[vessel]\nd_uu = 3.0\n", "vessel.d_uu: unknown key (did you mean 'd_u'?)"),
    ("[vessel]\nzzz = 3.0\n", "vessel.zzz: unknown key (expected one of: m, "),
    ("[vesel]\nm = 3.0\n", "vesel: unknown key (did you mean 'vessel'?)"),
    ("[sensors.gsp]\nrate_hz = 1.0\n", "sensors.gsp: unknown key (did you mean 'gps'?)"),
    ("[planner]\nsafety_raduis = 5\n", "planner.safety_raduis: unknown key (did you mean 'safety_radius'?)"),
    ("[vessel]\nm = -1.0\n", "vessel.m: must be > 0 kg (got -1.0)"),
    ("[vessel]\nm = inf\n", "vessel.m: must be a finite number (got inf)"),
    ("[sim]\nfield = 1\n", "sim.field: unknown key"),
    ("[current]\nspeed = nan\n", "current.speed"),
    ("[geodesy]\nalt0 = 1e300\n", "geodesy.alt0: 1e+300 m is out of range (|value| <= 1e+09)"),
])
def test_file_errors_name_the_file_key_and_nearest_key(tmp_path, capsys, text, expected):
    p = tmp_path / "mine.toml"
    p.write_text(text)
    err = _run_config_error(["plan", "--config", str(p), "--scenario", "labyrinth"], capsys)
    assert f"{p}: {expected}" in err, err


def test_a_bad_value_in_the_second_file_blames_the_second_file(tmp_path):
    a = tmp_path / "a.toml"
    a.write_text("[vessel]\nm = 60.0\n")
    b = tmp_path / "b.toml"
    b.write_text("[vessel]\nm = 0.0\n")
    with pytest.raises(ConfigError, match=rf"^{b}: vessel\.m: must be > 0"):
        settings.load([a, b])


@pytest.mark.parametrize("setting, expected", [
    ("vessel.m=-5", "--set vessel.m=-5: vessel.m: must be > 0 kg (got -5.0)"),
    ("vessel.m=nan", "--set vessel.m=nan: vessel.m: must be a finite number (got nan)"),
    ("sim.duration=inf", "--set sim.duration=inf: sim.duration: must be a finite number (got inf)"),
    ("vessel.d_uu=5", "--set vessel.d_uu=5: unknown key vessel.d_uu (did you mean 'd_u'?)"),
    ("planer.step=5", "--set planer.step=5: unknown key planer (did you mean 'planner'?)"),
])
def test_set_errors_blame_the_set_not_the_defaults(capsys, setting, expected):
    err = _run_config_error(["plan", "--set", setting, "--scenario", "labyrinth"], capsys)
    assert expected in err and "default.toml" not in err, err


def test_every_configured_number_is_finite_and_bounded():
    with pytest.raises(ConfigError, match="sim.seed"):
        settings.load(None, ["sim.seed=-1"])
    for key in ("waves.amplitude=1e12", "sim.initial.psi=1e300"):
        with pytest.raises(ConfigError, match="out of range|must be"):
            settings.load(None, [key])


def test_scenario_files_resolve_paths_next_to_themselves(tmp_path):
    (tmp_path / "charts").mkdir()
    shutil.copy(CONFIG_DIR / "maps" / "labyrinth.npy", tmp_path / "charts" / "lab.npy")
    p = tmp_path / "my-scenario.toml"
    p.write_text((CONFIG_DIR / "scenarios" / "labyrinth.toml").read_text()
                 .replace('map = "../maps/labyrinth.npy"', 'map = "charts/lab.npy"')
                 .replace('name = "labyrinth"', 'name = "my test/one"'))
    spec = scenario.load_spec(str(p))
    sc = scenario.instance(spec, None)
    assert sc.occ.shape[0] > 0
    assert scenario.folder_name(spec) == "my-test-one"
    p.write_text(p.read_text().replace('map = "charts/lab.npy"', 'map = "charts/none.npy"'))
    with pytest.raises(ConfigError, match=rf"{p}: map: no such file {tmp_path}/charts/none.npy"):
        scenario.instance(scenario.load_spec(str(p)), None)


def test_scenario_numbers_are_bounded(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text((CONFIG_DIR / "scenarios" / "harbour.toml").read_text()
                 .replace("start_heading = 0.8", "start_heading = 1e300")
                 .replace('map = "../maps/', f'map = "{CONFIG_DIR}/maps/'))
    err = _run_config_error(["plan", "--scenario", str(p)], capsys)
    assert "start_heading: must be <=" in err, err


@pytest.mark.parametrize("value", ["nan", "inf", "-1.0"])
def test_scenario_field_time_must_be_finite(tmp_path, value):
    p = tmp_path / "s.toml"
    p.write_text((CONFIG_DIR / "scenarios" / "labyrinth.toml").read_text()
                 .replace('map = "../maps/', f'map = "{CONFIG_DIR}/maps/')
                 .replace("field_time = 0.0", f"field_time = {value}"))
    with pytest.raises(ConfigError, match=r"current\.field_time: must be a finite number"):
        scenario.instance(scenario.load_spec(str(p)), None)
