"""A virtual CAN bus (vcan0) for tests and soaks: natively when the kernel has one, else in User-Mode Linux.

Many kernels (this project's CI machines among them) lack SocketCAN: ``ip link add dev vcan0 type
vcan`` fails with "Unknown device type" and AF_CAN sockets with EAFNOSUPPORT. Debian's
``user-mode-linux`` package boots a Linux 6.1 kernel as an ordinary process, with the can,
can-raw and vcan modules. :func:`run_in_uml` boots it with the host's root file system mounted
read-write through hostfs (so this project's venv and files are visible at the same paths), loads
the modules with ``finit_module`` (no kmod needed), creates vcan0 with the host's ``ip``, runs a
batch of jobs one after the other, writes their output to host files and powers off. Every wait
is bounded; on a timeout the UML process group is killed and the console is kept for the error.

:func:`detect` chooses, in order: native vcan (an existing vcan0, or one created with ``ip link``
when root), User-Mode Linux, or neither with the exact reason.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from hil.cpu_load import HOST_LOAD_ENV, HostLoadFeed

UML_CANDIDATES = ("/usr/bin/linux.uml", "/usr/bin/linux")
UML_MODULES = Path("/usr/lib/uml/modules")
CAN_MODULES = ("net/can/can.ko", "net/can/can-raw.ko", "drivers/net/can/dev/can-dev.ko", "drivers/net/can/vcan.ko")
ENV_KEYS = ("PATH", "HOME", "LANG", "LC_ALL", "PYTHONPATH", "NUMBA_CACHE_DIR", "NUMBA_OPT", "TMPDIR")


@dataclass
class Job:
    """One command to run on the vcan bus: argv, working directory, extra environment, time limit (s)."""

    name: str
    argv: list[str]
    cwd: str = "."
    env: dict[str, str] = field(default_factory=dict)
    timeout: float = 300.0


@dataclass
class JobResult:
    name: str
    returncode: int | None       # None: killed at its time limit
    stdout: str
    stderr: str
    seconds: float

    def json(self) -> object:
        """The last stdout line as JSON (the hil commands' --json summary)."""
        lines = self.stdout.strip().splitlines()
        return json.loads(lines[-1]) if lines else None


class VcanUnavailable(RuntimeError):
    """Neither native vcan nor User-Mode Linux: the message says exactly why."""


def _can_socket_ok(channel: str) -> str | None:
    try:
        import can

        bus = can.Bus(interface="socketcan", channel=channel)
        bus.shutdown()
        return None
    except Exception as exc:
        return f"{type(exc).__name__}: {exc}"


def native_vcan(channel: str = "vcan0") -> str | None:
    """None when ``channel`` is usable with socketcan here (created if root and absent), else why not."""
    if Path(f"/sys/class/net/{channel}").exists():
        return _can_socket_ok(channel)
    ip = shutil.which("ip") or "/usr/sbin/ip"
    if os.geteuid() != 0:
        return f"no {channel} and not root, so it cannot be created"
    if not Path(ip).exists():
        return "no `ip` command (iproute2) to create vcan0"
    r = subprocess.run([ip, "link", "add", "dev", channel, "type", "vcan"], capture_output=True, text=True, timeout=10)
    if r.returncode != 0:
        return f"`ip link add dev {channel} type vcan` failed: {r.stderr.strip()}"
    subprocess.run([ip, "link", "set", "up", channel], capture_output=True, text=True, timeout=10)
    return _can_socket_ok(channel)


def uml_binary() -> str | None:
    for c in UML_CANDIDATES:
        if Path(c).is_file() and os.access(c, os.X_OK):
            return c
    return None


def uml_modules() -> Path | None:
    """The kernel/ folder of the UML modules that hold can, can-raw and vcan."""
    if not UML_MODULES.is_dir():
        return None
    for ver in sorted(UML_MODULES.iterdir(), reverse=True):
        k = ver / "kernel"
        if all((k / m).is_file() for m in CAN_MODULES):
            return k
    return None


def uml_unavailable() -> str | None:
    """None when User-Mode Linux can give us vcan0 here, else why not."""
    if uml_binary() is None:
        return "User-Mode Linux is not installed (apt-get install user-mode-linux)"
    if uml_modules() is None:
        return f"no UML modules with {', '.join(Path(m).name for m in CAN_MODULES)} under {UML_MODULES}"
    if os.geteuid() != 0:
        return "User-Mode Linux with a read-write hostfs root needs root"
    if not (shutil.which("ip") or Path("/usr/sbin/ip").exists()):
        return "no `ip` command (iproute2) to create vcan0 inside User-Mode Linux"
    return None


def detect(channel: str = "vcan0") -> tuple[str, str]:
    """("native", reason-for-log) or ("uml", why-native-failed); VcanUnavailable with both reasons."""
    native = native_vcan(channel)
    if native is None:
        return "native", f"native {channel}"
    uml = uml_unavailable()
    if uml is None:
        return "uml", f"native vcan unavailable ({native}); using User-Mode Linux"
    raise VcanUnavailable(f"no virtual CAN: native vcan unavailable ({native}); {uml}")


# The guest's init (PID 1), run by this interpreter through hostfs. Kept self-contained: it may
# only use the standard library before the jobs run.
_INIT = r'''#!{python}
import ctypes, json, os, subprocess, sys, time
t0 = time.monotonic()
WORK = {work!r}
libc = ctypes.CDLL(None, use_errno=True)
report = {{"modules": {{}}, "jobs": []}}
def save():
    with open(os.path.join(WORK, "guest.json.tmp"), "w") as fh:
        json.dump(report, fh)
    os.replace(os.path.join(WORK, "guest.json.tmp"), os.path.join(WORK, "guest.json"))
try:
    for src, dst, fs in (("proc", "/proc", "proc"), ("sysfs", "/sys", "sysfs"), ("devtmpfs", "/dev", "devtmpfs"),
                         ("tmpfs", "/dev/shm", "tmpfs"), ("tmpfs", "/run", "tmpfs")):
        if dst == "/dev" and os.path.exists("/dev/null") and os.path.ismount("/dev"):
            continue  # the kernel mounted devtmpfs itself
        os.makedirs(dst, exist_ok=True)
        if libc.mount(src.encode(), dst.encode(), fs.encode(), 0, None) != 0:
            report.setdefault("mount_errors", {{}})[dst] = ctypes.get_errno()
    # The host's socket buffer limits (the guest's defaults are ~200 KB: a busy UDP tap would drop).
    for key, value in {sysctls!r}.items():
        try:
            with open("/proc/sys/net/core/" + key, "w") as fh:
                fh.write(value)
        except OSError as exc:
            report.setdefault("sysctl_errors", {{}})[key] = str(exc)
    for m in {modules!r}:
        fd = os.open(os.path.join({kernel!r}, m), os.O_RDONLY)
        rc = libc.syscall(313, fd, b"", 0)  # finit_module (x86_64); no kmod in the guest
        report["modules"][m] = 0 if rc == 0 else ctypes.get_errno()
        os.close(fd)
    for args in (["link", "set", "up", "lo"], ["link", "add", "dev", "vcan0", "type", "vcan"],
                 ["link", "set", "up", "vcan0"]):
        r = subprocess.run([{ip!r}] + args, capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError("ip " + " ".join(args) + ": " + r.stderr.strip())
    report["boot_s"] = time.monotonic() - t0
    save()
    jobs = json.load(open(os.path.join(WORK, "jobs.json")))
    for i, job in enumerate(jobs):
        out = open(os.path.join(WORK, f"job{{i}}.out"), "wb")
        err = open(os.path.join(WORK, f"job{{i}}.err"), "wb")
        s = time.monotonic()
        p = subprocess.Popen(job["argv"], cwd=job["cwd"], env=job["env"], stdout=out, stderr=err,
                             stdin=subprocess.DEVNULL, start_new_session=True)
        try:
            rc = p.wait(timeout=job["timeout"])
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, 9)
            p.wait()
            rc = None
        out.close(); err.close()
        report["jobs"].append({{"name": job["name"], "returncode": rc, "seconds": time.monotonic() - s}})
        save()
except BaseException as exc:
    import traceback
    report["error"] = traceback.format_exc()
finally:
    report["total_s"] = time.monotonic() - t0
    save()
    libc.sync()
    libc.reboot(0x4321FEDC)  # LINUX_REBOOT_CMD_POWER_OFF: the UML process exits
'''


@dataclass
class UmlRun:
    results: list[JobResult]
    boot_s: float | None            # guest: kernel up to vcan0 ready (s, guest clock)
    wall_s: float                   # host: UML started to exited
    console: str


def run_in_uml(jobs: list[Job], mem: str = "1536M", boot_timeout: float = 60.0,
               workdir: str | Path | None = None, follow: IO[str] | None = None) -> UmlRun:
    """Boot User-Mode Linux once, run ``jobs`` on its vcan0 one after the other, power off.

    ``follow``: copy the jobs' stderr there as it is written (progress of long jobs).
    RuntimeError (with the console's tail) if the guest does not come up or does not finish in
    time; each job is killed at its own time limit (returncode None).
    """
    why = uml_unavailable()
    binary = uml_binary()
    if why or binary is None:
        raise VcanUnavailable(why or "User-Mode Linux is not installed")
    work = Path(workdir or tempfile.mkdtemp(prefix="hil-uml-"))
    work.mkdir(parents=True, exist_ok=True)
    env_base = {k: os.environ[k] for k in ENV_KEYS if k in os.environ}
    env_base.setdefault("PATH", "/usr/local/bin:/usr/bin:/bin:/usr/sbin:/sbin")
    env_base.setdefault("HOME", "/root")
    env_base["PYTHONUNBUFFERED"] = "1"
    # The host's load, which the guest's /proc cannot show (hil/cpu_load.py: a soak in the guest judges by it).
    host_load = work.resolve() / "host_load.json"
    env_base[HOST_LOAD_ENV] = str(host_load)
    (work / "jobs.json").write_text(json.dumps([
        {"name": j.name, "argv": j.argv, "cwd": str(Path(j.cwd).resolve()), "env": {**env_base, **j.env},
         "timeout": j.timeout} for j in jobs]))
    init = work / "init.py"
    sysctls = {}
    for key in ("rmem_max", "wmem_max", "rmem_default", "wmem_default"):
        try:
            sysctls[key] = Path(f"/proc/sys/net/core/{key}").read_text().strip()
        except OSError:
            pass
    init.write_text(_INIT.format(python=sys.executable, sysctls=sysctls, work=str(work.resolve()),
                                 modules=list(CAN_MODULES),
                                 kernel=str(uml_modules()), ip=shutil.which("ip") or "/usr/sbin/ip"))
    init.chmod(0o755)
    (work / "guest.json").unlink(missing_ok=True)
    console_path = work / "console.txt"
    limit = boot_timeout + sum(j.timeout + 10.0 for j in jobs)
    cmd = [binary, f"mem={mem}", "rootfstype=hostfs", "rw", f"init={init.resolve()}",
           "con=null", "con0=fd:0,fd:1", "quiet"]
    t0 = time.monotonic()
    with open(console_path, "wb") as console, open(os.devnull, "rb") as devnull:
        # UML runs in its own temporary directory (its memory file lives in TMPDIR).
        proc = subprocess.Popen(cmd, stdin=devnull, stdout=console, stderr=subprocess.STDOUT,
                                start_new_session=True, cwd=work)
        feed = HostLoadFeed(host_load, proc.pid).start()
        try:
            if follow is None:
                proc.wait(timeout=limit)
            else:
                _wait_following(proc, limit, [work / f"job{i}.err" for i in range(len(jobs))], follow)
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            raise RuntimeError(f"User-Mode Linux did not finish within {limit:.0f} s; console:\n"
                               + _tail(console_path)) from None
        finally:
            feed.stop()
            if proc.poll() is None:
                _kill_group(proc)
    wall = time.monotonic() - t0
    guest_path = work / "guest.json"
    if not guest_path.exists():
        raise RuntimeError(f"User-Mode Linux exited ({proc.returncode}) before its init reported; console:\n"
                           + _tail(console_path))
    guest = json.loads(guest_path.read_text())
    if "error" in guest:
        raise RuntimeError(f"User-Mode Linux init failed: {guest['error'].strip().splitlines()[-1]}; "
                           f"modules {guest.get('modules')}; console:\n" + _tail(console_path))
    results = []
    for i, (job, done) in enumerate(zip(jobs, guest["jobs"], strict=False)):
        results.append(JobResult(job.name, done["returncode"],
                                 (work / f"job{i}.out").read_text(errors="replace"),
                                 (work / f"job{i}.err").read_text(errors="replace"), done["seconds"]))
    if len(results) < len(jobs):
        raise RuntimeError(f"User-Mode Linux ran {len(results)} of {len(jobs)} jobs; console:\n" + _tail(console_path))
    return UmlRun(results, guest.get("boot_s"), wall, console_path.read_text(errors="replace"))


def _wait_following(proc: subprocess.Popen, limit: float, paths: list[Path], out: IO[str]) -> None:
    """Wait up to ``limit`` s for ``proc``, copying what is appended to ``paths`` to ``out``
    (the guest writes them through hostfs); TimeoutExpired at the limit."""
    end = time.monotonic() + limit
    offsets = [0] * len(paths)

    def copy() -> None:
        for i, path in enumerate(paths):
            try:
                with open(path, "rb") as fh:
                    fh.seek(offsets[i])
                    chunk = fh.read()
            except OSError:
                continue
            if chunk:
                offsets[i] += len(chunk)
                out.write(chunk.decode(errors="replace"))
                out.flush()

    while True:
        try:
            proc.wait(timeout=max(0.0, min(0.5, end - time.monotonic())))
            copy()
            return
        except subprocess.TimeoutExpired:
            copy()
            if time.monotonic() >= end:
                raise


def run_native(jobs: list[Job]) -> list[JobResult]:
    """The same batch on this machine's own vcan (no UML)."""
    out = []
    env_base = dict(os.environ, PYTHONUNBUFFERED="1")
    for j in jobs:
        s = time.monotonic()
        p = subprocess.Popen(j.argv, cwd=j.cwd, env={**env_base, **j.env}, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, start_new_session=True)
        try:
            o, e = p.communicate(timeout=j.timeout)
            rc = p.returncode
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            o, e = p.communicate()
            rc = None
        out.append(JobResult(j.name, rc, o.decode(errors="replace"), e.decode(errors="replace"), time.monotonic() - s))
    return out


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        pass


def _tail(path: Path, n: int = 40) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no console)"
