"""Small things a newcomer met (issue 32, point 5): help texts that say what the code does, "did you
mean" for a misspelt flag, --demo keeping its summary in --out, summaries as readable as the run's files."""

from __future__ import annotations

import json
import os
import stat

from hil.scenario_names import available


def test_soak_help_names_its_real_default(hil_main):
    r = hil_main("soak", "--help")
    assert r.returncode == 0
    assert "(default: can, for a soak)" in " ".join(r.stdout.split())


def test_plan_help_lists_only_the_scenarios_plan_takes(hil_main):
    r = hil_main("plan", "--help")
    text = " ".join(r.stdout.split())
    assert available("random") and set(available("random")) <= set(available())
    for name in available("random"):
        assert f" {name}," not in text and f" {name})" not in text, name
    assert "harbour" in text and "labyrinth" in text


def test_a_misspelt_flag_gets_a_suggestion(hil_main):
    r = hil_main("run", "--scenaro", "harbour")
    assert r.returncode == 2
    assert "did you mean '--scenario'?" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = hil_main("plan", "--qqqqq")
    assert r.returncode == 2 and "did you mean" not in r.stderr


def test_the_demo_keeps_its_summary_in_out(hil, tmp_path):
    out = tmp_path / "demo"
    r = hil("run", "--demo", "--duration", "1", "--out", str(out), "--json", timeout=120)
    assert r.returncode == 0, r.stderr
    saved = json.loads((out / "summary.json").read_text())
    assert saved["seed"] == json.loads(r.stdout)["seed"] and saved["sim_time_s"] >= 1.0
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE((out / "summary.json").stat().st_mode) == 0o666 & ~umask


def test_a_failed_start_leaves_no_empty_files(tmp_path):
    from hil.files import tidy_failed_start

    out = tmp_path / "run"
    out.mkdir()
    (out / "run.tlog").write_bytes(b"")
    (out / "autopilot.log").write_text("autopilot: error: no such thing\n")
    tidy_failed_start(out, fresh=True)
    assert sorted(p.name for p in out.iterdir()) == ["autopilot.log"]     # the log that says why stays
    (out / "autopilot.log").unlink()
    (out / "run.tlog").write_bytes(b"")
    tidy_failed_start(out, fresh=True)
    assert not out.exists()
    kept = tmp_path / "kept"
    kept.mkdir()
    tidy_failed_start(kept, fresh=False)                                  # a folder the user gave stays
    assert kept.is_dir()


def test_no_system_id_warning_when_the_ground_station_link_is_off(tmp_path):
    """A second run with ``--gcs none`` streams to no ground station: no "another run streams as
    system N" warning (issue 32 point 5); with its link on, the same clash warns."""
    import fcntl
    import tempfile
    from pathlib import Path
    from types import SimpleNamespace

    from hil.hilrun import HilRun, gcs_endpoints_in_effect

    assert gcs_endpoints_in_effect(["udpout:127.0.0.1:14550"], ["--gcs", "none"]) == []
    assert gcs_endpoints_in_effect(["udpout:127.0.0.1:14550"], ["--wait-for-arm"]) == ["udpout:127.0.0.1:14550"]
    assert gcs_endpoints_in_effect([], ["--gcs", "udpin:0.0.0.0:14551", "--gcs", "none"]) == ["udpin:0.0.0.0:14551"]
    sysid = 237  # a private id: the lock of a real run (system id 1) is not touched
    holder = open(Path(tempfile.gettempdir()) / f"usv-hil-sysid-{sysid}.lock", "a")
    fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)  # "another run" streaming as system 237
    try:
        for args, warned in ((["--gcs", "none"], False), ([], True)):
            said: list[str] = []
            run = SimpleNamespace(
                cfg=SimpleNamespace(gcs=SimpleNamespace(endpoints=["udpout:127.0.0.1:14550"]),
                                    autopilot=SimpleNamespace(system_id=sysid)),
                opts=SimpleNamespace(extra_autopilot_args=args, on_progress=said.append),
                warnings=[], _sysid_lock=None)
            HilRun.claim_system_id(run)  # type: ignore[arg-type]
            assert bool(run.warnings) == warned and bool(said) == warned, (args, said)
            assert run._sysid_lock is None
    finally:
        holder.close()
