"""Ctrl-C (SIGINT) and SIGTERM in any phase of `gearte run` leave the previous complete result or nothing.

The real command runs in a subprocess (through the `gearte` entry point, `gearte_command.main`) and
is signalled at several moments: while Python imports gearte and JAX, while JAX compiles, while it
samples. Whatever the phase, it exits with 128 + the signal and "interrupted", prints no traceback,
and the earlier results folder is byte-for-byte what it was, with no temporary folder beside it.
The writing phase and an interrupt that a library swallows are tested in-process.
"""

import gc
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gearte import cli
from gearte.cli import io, plots

ROOT = Path(__file__).resolve().parents[1]
RANDOM = ROOT / "examples" / "planetary_wang2013_random.toml"
ENTRY = "import sys, gearte_command; sys.exit(gearte_command.main())"


def run(*args):
    return cli.main([str(a) for a in args])


@pytest.fixture(scope="module")
def previous(tmp_path_factory):
    """A complete earlier result, copied into each test's folder."""
    d = tmp_path_factory.mktemp("previous") / "res"
    assert run("run", RANDOM, "--out", d, "--samples", 64, "--seed", 5) == 0
    return d


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


# (signal, seconds after start): during the imports, around compilation, while sampling. The first is
# sent as soon as the command's handlers are in place (before that only Python's own start-up runs,
# whose Ctrl-C behaviour is Python's): on a loaded machine 0.05 s can still be inside that start-up.
MOMENTS = [(signal.SIGINT, 0.05), (signal.SIGINT, 0.3), (signal.SIGINT, 1.0), (signal.SIGTERM, 2.0), (signal.SIGINT, 4.0)]


def wait_for_handlers(pid: int, timeout_s: float = 30.0) -> None:
    """Wait until process `pid` catches SIGTERM (Python itself never does): gearte_command's handlers are set."""
    status = Path(f"/proc/{pid}/status")
    if not status.exists():  # not Linux: rely on the delay alone
        return
    bit = 1 << (signal.SIGTERM - 1)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        caught = next((line.split()[1] for line in status.read_text().splitlines() if line.startswith("SigCgt:")), "0")
        if int(caught, 16) & bit:
            return
        time.sleep(0.002)
    raise AssertionError(f"the command did not install its signal handlers within {timeout_s} s")


@pytest.mark.parametrize("sig, delay", MOMENTS, ids=[f"{signal.Signals(s).name}-{d}s" for s, d in MOMENTS])
def test_signal_at_any_moment_keeps_the_previous_result(sig, delay, previous, tmp_path):
    out = tmp_path / "res"
    shutil.copytree(previous, out)
    before = snapshot(out)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    # 2,700,000 samples: below the sizes that ask for --yes or stream the study, and long enough (seconds, on a
    # machine where 900,000 samples once were and no longer are) not to finish before the last signal.
    p = subprocess.Popen(
        [sys.executable, "-c", ENTRY, "run", str(RANDOM), "--out", str(out), "--samples", "2700000", "--no-progress"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    wait_for_handlers(p.pid)
    time.sleep(delay)
    p.send_signal(sig)
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 128 + sig, (p.returncode, stdout, stderr)
    assert "interrupted" in stderr and "Traceback" not in stderr, stderr
    assert snapshot(out) == before
    assert sorted(x.name for x in tmp_path.iterdir()) == ["res"]  # no temporary folder left


def test_interrupt_while_writing_and_a_swallowed_interrupt(previous, tmp_path, monkeypatch, capsys):
    out = tmp_path / "res"
    shutil.copytree(previous, out)
    before = snapshot(out)
    real_trace = plots.trace

    def interrupted_while_writing(*a, **k):
        os.kill(os.getpid(), signal.SIGTERM)
        return real_trace(*a, **k)

    monkeypatch.setattr(plots, "trace", interrupted_while_writing)
    assert run("run", RANDOM, "--out", out, "--samples", 64) == 128 + signal.SIGTERM
    assert snapshot(out) == before

    def swallowed(*a, **k):
        # A library that catches KeyboardInterrupt and carries on: the run must still not replace the result.
        try:
            os.kill(os.getpid(), signal.SIGINT)
        except KeyboardInterrupt:
            pass
        return real_trace(*a, **k)

    monkeypatch.setattr(plots, "trace", swallowed)
    assert run("run", RANDOM, "--out", out, "--samples", 64) == 130
    assert snapshot(out) == before

    def in_a_gc_callback(*a, **k):
        # JAX runs Python in garbage-collector callbacks; an interrupt raised there cannot propagate
        # (Python reports it as "ignored"): it must still stop the run, quietly.
        def callback(phase, info):
            gc.callbacks.remove(callback)
            os.kill(os.getpid(), signal.SIGINT)

        gc.callbacks.append(callback)
        gc.collect()
        return real_trace(*a, **k)

    monkeypatch.setattr(plots, "trace", in_a_gc_callback)
    capsys.readouterr()
    assert run("run", RANDOM, "--out", out, "--samples", 64) == 130
    assert snapshot(out) == before
    err = capsys.readouterr().err
    assert "interrupted" in err and "Exception ignored" not in err and "Traceback" not in err, err
    fresh = tmp_path / "fresh" / "deeper"
    assert run("run", RANDOM, "--out", fresh, "--samples", 64) == 130
    assert sorted(x.name for x in tmp_path.iterdir()) == ["res"]  # nor the parent folders made for it
    assert io.interrupt_received() is None  # the command line leaves no state behind


def _dead_pid() -> int:
    """A process id that no process holds now (a child that has ended and been reaped)."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_a_killed_runs_working_folders_are_cleared_and_its_moved_result_put_back(previous, tmp_path, capsys):
    """SIGKILL cannot be caught: a run killed while writing leaves its new results beside the folder, and one killed
    between its two renames the previous result moved aside. The next run into the folder clears them (only those of
    processes that are gone, on this host) and, where the folder itself is missing, puts the previous result back."""
    host = io.socket.gethostname().replace("-", "_")
    dead, live = _dead_pid(), os.getpid()
    out = tmp_path / "res"
    moved = tmp_path / f".res.old-{dead}@{host}-abc123"
    moved.mkdir()
    shutil.copytree(previous, moved / "previous")
    partial = tmp_path / f".res.partial-{dead}@{host}-def456"
    partial.mkdir()
    (partial / "summary.json").write_text("{")
    running = tmp_path / f".res.partial-{live}@{host}-ghi789"  # a run still going: left alone
    running.mkdir()
    before = snapshot(previous)
    with io.atomic_output_dir(out) as tmp:
        assert snapshot(out) == before  # put back before the new run writes anything
        (tmp / "note.txt").write_text("new")
    assert not moved.exists() and not partial.exists() and running.is_dir()
    assert snapshot(out) == {"note.txt": b"new"}
