"""CLI conventions, checked on the real `hil` entry point in a subprocess."""

from __future__ import annotations

import json

import pytest

from hil.cli import COMMANDS, build_parser


def test_top_level_help_lists_commands_and_exit_codes(hil):
    r = hil("--help")
    assert r.returncode == 0
    for name in COMMANDS:
        assert name in r.stdout
    assert "Exit codes" in r.stdout


def test_every_command_has_help_with_common_options(hil):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(sub.choices) == set(COMMANDS), "every listed command must exist"
    for name in COMMANDS:
        if name == "bench":
            continue  # its targets carry the options; checked below
        r = hil(name, "--help")
        if name == "vcan":  # runs another command, whose options those are
            assert r.returncode == 0 and "-- COMMAND" in r.stdout and "--config" not in r.stdout
            continue
        assert r.returncode == 0, r.stderr
        for opt in ("--config", "--set", "--json"):
            assert opt in r.stdout, f"hil {name} --help lacks {opt}"


def test_bench_targets_have_help(hil):
    from hil.commands.bench import TARGETS

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    bench = sub.choices["bench"]
    targets = next(a for a in bench._actions if a.dest == "target")
    for name in targets.choices:
        assert name.replace("-", "_") in TARGETS      # the user types can-flood; the module is can_flood
        r = hil("bench", name, "--help")
        assert r.returncode == 0 and "--json" in r.stdout


def test_unknown_command_and_option_are_one_line_exit_2(hil):
    r = hil("no-such-command")
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1
    r = hil("sim", "--no-such-option")
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("overrides", [["vessel.m=-3"], ["vessel.bogus=1"], ["vessel.m=fast"]])
def test_config_errors_are_one_line_exit_2(hil_main, overrides):
    args = ["sim", "--duration", "0.1", "--json"]
    for o in overrides:
        args += ["--set", o]
    r = hil_main(*args)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hil sim: error: "), r.stderr
    assert "vessel." in lines[0]
    assert r.stdout == ""


def test_missing_config_file_is_one_line(hil_main, tmp_path):
    r = hil_main("sim", "--config", str(tmp_path / "missing.toml"), "--duration", "0.1")
    assert r.returncode == 2
    assert r.stderr.strip().endswith("missing.toml: no such file")


def test_json_summary_is_one_object_on_stdout(hil):
    import socket

    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    try:
        port = sink.getsockname()[1]
        r = hil("sim", "--duration", "0.2", "--speedup", "4", "--json",
                "--commands-on", "127.0.0.1:0", "--state-to", f"127.0.0.1:{port}", timeout=60)
    finally:
        sink.close()
    assert r.returncode == 0, r.stderr
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 1, r.stdout
    summary = json.loads(lines[0])
    assert summary["steps"] == 20


def test_building_the_parser_imports_no_heavy_library():
    """`hil --help` stays fast: commands import numpy, numba, scipy, filterpy, pymavlink only when run."""
    import subprocess
    import sys

    heavy = ("numpy", "numba", "scipy", "filterpy", "pymavlink")
    code = ("import sys, hil.cli; hil.cli.build_parser(); "
            f"print(','.join(sorted(m for m in {heavy!r} if m in sys.modules)))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "", f"building the parser imported: {r.stdout.strip()}"


def test_one_algorithm_registry():
    """The planner's ALGORITHM_NAMES is the only list of algorithm names; the rest use it."""
    import typing

    import planner
    from hil import experiment
    from hil.commands import plan
    from planner.params import ALGORITHM_NAMES, PlannerParams

    assert planner.ALGORITHMS is ALGORITHM_NAMES
    assert experiment.ALGORITHMS is ALGORITHM_NAMES and plan.ALGORITHMS is ALGORITHM_NAMES
    assert set(experiment.LABELS) == set(ALGORITHM_NAMES)
    assert typing.get_args(typing.get_type_hints(PlannerParams)["algorithm"]) == ALGORITHM_NAMES
    for name in ALGORITHM_NAMES:
        assert planner.make_planner(name, PlannerParams(algorithm=name), seed=1) is not None
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for command in ("run", "autopilot", "plan"):
        algo = next(a for a in sub.choices[command]._actions if a.dest == "algorithm")
        assert tuple(algo.choices) == ALGORITHM_NAMES


def _one_line_exit_2(r, command: str) -> str:
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith(f"hil {command}: error: "), r.stderr
    return last


@pytest.mark.parametrize("argv", [
    ["run", "--duration", "1"],
    ["montecarlo", "--runs", "1", "--algorithms", "rrt-star", "--no-plots"],
    ["montecarlo", "--routes", "--runs", "1"],
])
def test_an_output_folder_that_is_a_file_is_one_line(hil, tmp_path, argv):
    """--out naming an existing file (or a folder under one) is a user mistake: one line, exit 2,
    before anything runs, and the file is left as it was."""
    blocker = tmp_path / "results.txt"
    blocker.write_text("keep me")
    for out in (blocker, blocker / "sub"):
        r = hil(*argv, "--out", str(out), timeout=120)
        assert "--out" in _one_line_exit_2(r, argv[0])
    assert blocker.read_text() == "keep me"


def _wall(tmp_path):
    import numpy as np
    occ = np.zeros((40, 40), dtype=bool)
    occ[0:28, 18:22] = True
    np.save(tmp_path / "wall.npy", occ)
    return ["plan", "--map", str(tmp_path / "wall.npy"), "--resolution", "0.5", "--start", "3,3",
            "--goal", "17,3", "--deadline", "0.05"]


def test_plan_plot_to_a_folder_or_an_unknown_format_is_one_line(hil, tmp_path):
    """The plot goes to the file the user named or the command stops before planning: no 'plot written to
    DIR' while matplotlib wrote DIR.png, no traceback after the search for a .txt name or a path under a file."""
    folder = tmp_path / "plots"
    folder.mkdir()
    (tmp_path / "afile").write_text("x")
    for plot in (folder, tmp_path / "plan.txt", tmp_path / "afile" / "plan.png", tmp_path / "plan"):
        r = hil(*_wall(tmp_path), "--plot", str(plot))
        assert "--plot" in _one_line_exit_2(r, "plan")
    assert list(folder.iterdir()) == [] and not (tmp_path / "plots.png").exists()
    assert not (tmp_path / "plan.png").exists()
    r = hil(*_wall(tmp_path), "--plot", str(tmp_path / "new" / "plan.png"))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "new" / "plan.png").stat().st_size > 0


@pytest.mark.parametrize("argv, dest, value", [
    (["montecarlo", "--traffic", "--miss", "-6,-2"], "miss", (-6.0, -2.0)),
    (["plan", "--start", "-3.5,2"], "start", (-3.5, 2.0)),
])
def test_negative_pairs_are_values_not_options(argv, dest, value):
    """`--miss -6,-2` (the help's own sign convention: negative = to port) is a value, as `--miss=-6,-2` is."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:
        raise AssertionError(f"{argv} did not parse") from exc
    assert tuple(getattr(args, dest)) == value


def test_an_unknown_option_is_named_with_its_command(hil):
    """`hil autopilot --duration 1` (an option of another command) says 'hil autopilot: error: ...' and points
    to `hil autopilot --help`, not 'hil: error:' and the top-level help."""
    r = hil("autopilot", "--duration", "1")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert r.stderr.startswith("hil autopilot: error: unrecognized arguments: --duration 1"), r.stderr
    assert "hil autopilot --help" in r.stderr
