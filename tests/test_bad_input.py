"""Every bad input answered cleanly: from the command line (exit status 2, one message naming the file,
table, key or option, no traceback, nothing written or deleted) and from Python (a ValueError or
ConfigError with the same message). Interrupts are in test_interrupt.py, fuzzed study files in
test_fuzz_study_files.py.
"""

import importlib
import json
import math
import os
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import gearte
from gearte import cli
from gearte.cli import run as run_mod
from gearte.cli.compare import RunFolderError, compare_runs
from gearte.cli.config import ConfigError, load_study
from gearte.cli.io import OutputError
from gearte.cli.run import estimate_cost, run_study

main_mod = importlib.import_module("gearte.cli.main")  # the module (gearte.cli.main is also the function's name)
ROOT = Path(__file__).resolve().parents[1]
RANDOM = ROOT / "examples" / "planetary_wang2013_random.toml"
CYCLOID = ROOT / "examples" / "cycloid_yao2001_modified.toml"


def snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every path under `folder` (hidden ones included) with its bytes (None for folders)."""
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


def refused(capsys, tmp_path, *args, message: str, computing: bool = False, monkeypatch=None) -> str:
    """`gearte ARGS` exits 2 with one plain message containing `message`, and changes nothing under tmp_path.
    With a monkeypatch, computing anything fails the test (the refusal came before any work)."""
    if monkeypatch is not None and not computing:

        def no_work(*a, **k):
            raise AssertionError("computed before refusing")

        monkeypatch.setattr(run_mod, "_run", no_work)
        monkeypatch.setattr(main_mod, "estimate_cost", no_work)
    before = snapshot(tmp_path)
    capsys.readouterr()
    assert cli.main([str(a) for a in args]) == 2
    cap = capsys.readouterr()
    assert message in cap.err, cap.err
    assert cap.err.startswith("gearte: error") and cap.err.count("\n") == 1 and "Traceback" not in cap.err, cap.err
    assert snapshot(tmp_path) == before
    return cap.err


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """Two finished planetary runs (64 samples), copied by the tests that alter them."""
    base = tmp_path_factory.mktemp("runs")
    a, b = base / "a", base / "b"
    assert cli.main(["run", str(RANDOM), "--out", str(a), "--samples", "64", "--seed", "1"]) == 0
    assert cli.main(["run", str(ROOT / "examples" / "planetary_wang2013_half.toml"), "--out", str(b), "--samples", "64"]) == 0
    return a, b


def copy_run(src: Path, dst: Path) -> Path:
    dst.mkdir(parents=True)
    for p in src.iterdir():
        (dst / p.name).write_bytes(p.read_bytes())
    return dst


# ---------------------------------------------------------------- --out


def test_out_dot_refuses_the_users_folder(capsys, tmp_path, monkeypatch):
    (tmp_path / "mine.txt").write_text("the user's own file")
    monkeypatch.chdir(tmp_path)
    refused(capsys, tmp_path, "run", RANDOM, "--out", ".", message="--out .: is the current folder", monkeypatch=monkeypatch)
    with pytest.raises(OutputError, match="current folder"):
        run_study(load_study(RANDOM), ".")


def test_out_refuses_a_folder_with_other_files(capsys, tmp_path, monkeypatch):
    user = tmp_path / "papers"
    user.mkdir()
    (user / "notes.md").write_text("notes")
    refused(capsys, tmp_path, "run", RANDOM, "--out", user, message="files gearte did not write", monkeypatch=monkeypatch)
    with pytest.raises(OutputError, match="files gearte did not write"):
        run_study(load_study(RANDOM), user)


def test_out_replaces_its_own_result_but_not_one_the_user_added_to(capsys, tmp_path, finished, monkeypatch):
    res = copy_run(finished[0], tmp_path / "res")
    assert cli.main(["run", str(RANDOM), "--out", str(res), "--samples", "32"]) == 0  # its own result: replaced
    assert json.loads((res / "summary.json").read_text())["samples"] == 32
    (res / "my_notes.md").write_text("mine")
    refused(capsys, tmp_path, "run", RANDOM, "--out", res, message="files gearte did not write", monkeypatch=monkeypatch)


def test_out_an_existing_file(capsys, tmp_path, monkeypatch):
    f = tmp_path / "f"
    f.write_text("x")
    refused(capsys, tmp_path, "run", RANDOM, "--out", f, message=f"--out {f}: is an existing file", monkeypatch=monkeypatch)


def test_out_below_a_file(capsys, tmp_path, monkeypatch):
    f = tmp_path / "f"
    f.write_text("x")
    refused(
        capsys, tmp_path, "run", RANDOM, "--out", f / "sub", message="is a file, so no folder can be made below it", monkeypatch=monkeypatch
    )


def test_out_where_nothing_can_be_written(capsys, tmp_path, monkeypatch):
    # /proc accepts no new folders, even for root.
    refused(
        capsys,
        tmp_path,
        "run",
        RANDOM,
        "--out",
        "/proc/gearte-results",
        message="--out /proc/gearte-results: cannot",
        monkeypatch=monkeypatch,
    )


def test_out_a_symbolic_link_or_empty(capsys, tmp_path, monkeypatch):
    target = tmp_path / "target"
    target.mkdir()
    (tmp_path / "link").symlink_to(target)
    refused(capsys, tmp_path, "run", RANDOM, "--out", tmp_path / "link", message="symbolic link", monkeypatch=monkeypatch)
    refused(capsys, tmp_path, "run", RANDOM, "--out", "", message="--out: empty", monkeypatch=monkeypatch)


def test_out_the_folder_holding_the_study_file(capsys, tmp_path, monkeypatch):
    cfg = tmp_path / "study" / "s.toml"
    cfg.parent.mkdir()
    cfg.write_text(RANDOM.read_text())
    refused(capsys, tmp_path, "run", cfg, "--out", cfg.parent, message="input", monkeypatch=monkeypatch)


def test_a_failed_run_leaves_no_parent_folders(capsys, tmp_path, monkeypatch):
    def boom(*a, **k):
        raise ValueError("simulated failure while computing")

    monkeypatch.setattr(run_mod, "_run", boom)
    refused(capsys, tmp_path, "run", RANDOM, "--out", tmp_path / "new" / "deeper" / "res", message="simulated failure", computing=True)


# ---------------------------------------------------------------- study files


def test_binary_study_file_named(capsys, tmp_path):
    cfg = tmp_path / "s.toml"
    cfg.write_bytes(bytes(range(256)))
    refused(capsys, tmp_path, "check", cfg, message=f"{cfg}: not a UTF-8 text file")
    refused(capsys, tmp_path, "run", cfg, "--out", tmp_path / "o", message=f"{cfg}: not a UTF-8 text file")
    with pytest.raises(ConfigError, match="not a UTF-8"):
        load_study(cfg)


def test_a_pipe_a_device_or_a_huge_file_as_the_study_file(capsys, tmp_path, monkeypatch):
    """Only a regular file is read: a pipe would block `check` for ever, /dev/zero would never end."""
    fifo = tmp_path / "s.toml"
    os.mkfifo(fifo)
    for path in (fifo, "/dev/zero"):  # in a command of its own, so that a regression fails by the time-out, not hangs
        r = subprocess.run([sys.executable, "-m", "gearte", "check", str(path)], cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and f"{path}: not a regular file" in r.stderr and "Traceback" not in r.stderr, r.stderr
    big = tmp_path / "big.toml"
    with big.open("wb") as f:
        f.truncate(17 * 2**20)  # sparse: 17 MiB of nothing
    refused(capsys, tmp_path, "run", big, "--out", tmp_path / "o", message="at most 16 MiB", monkeypatch=monkeypatch)


@pytest.mark.parametrize(
    "old, new, message",
    [
        (
            "[errors.carrier_assembly]",
            "[errors.carrier_asembly]",
            "unknown error source `carrier_asembly` (did you mean `carrier_assembly`?)",
        ),
        ("[errors.carrier_assembly]", "[erors.carrier_assembly]", "unknown table `[erors]` (did you mean `[errors]`?)"),
        ("samples = 50000", "samples = 4294967296", "[study] samples: at most 2³² − 1"),
        (
            "tolerance_um = 16",
            "tolerance_um = 1e20",
            "tolerance_um: 1e+20 µm is more than 100,000 µm (100 mm): lengths ending in _um are micrometres",
        ),
        ("tolerance_um = 16", "tolerance_deg = 16", "tolerance_deg: this source is a length; give `tolerance_um`"),
        # an optional key (read only where present) is among the allowed ones, and the nearest
        ("seed = 1001", "seed = 1001\nchunk_sise = 5", "unknown key `chunk_sise` (did you mean `chunk_size`?); allowed here: chunk_size,"),
        # coprime tooth counts whose hyper-period (358,800 input revolutions) the exact extrema could not sample
        (
            "z_sun = 12\nz_planet = 36\nz_ring = 84",
            "z_sun = 301\nz_planet = 299\nz_ring = 899",
            "[drive]: extrema: the signal's 3 orders up to 270,599",
        ),
    ],
    ids=[
        "misspelt source",
        "misspelt table",
        "samples beyond one key",
        "micrometres beyond 100 mm",
        "an angle for a length",
        "optional key misspelt",
        "hyper-period too long",
    ],
)
def test_study_file_mistakes_named_by_check_and_run(old, new, message, capsys, tmp_path, monkeypatch):
    text = RANDOM.read_text()
    assert old in text
    cfg = tmp_path / "s.toml"
    cfg.write_text(text.replace(old, new))
    refused(capsys, tmp_path, "check", cfg, message=message)
    refused(capsys, tmp_path, "run", cfg, "--out", tmp_path / "o", message=message, monkeypatch=monkeypatch)
    with pytest.raises(ConfigError, match=r"s\.toml: "):
        load_study(cfg)


@pytest.mark.parametrize(
    "example, old, new, message",
    [
        ("cycloid_yao2001_unmodified", "positions_per_pitch = 2 ", "positions_per_pitch = 2000000 ", "positions_per_pitch: must be ≤ 4096"),
        # the grid's revolutions past z_a = 25 repeat pin pairings already on it (as the analysis' revolutions do)
        (
            "cycloid_yao2001_unmodified",
            "revolutions = 1\n\n[drive.reference]",
            "revolutions = 26\n\n[drive.reference]",
            "give at most 25, got 26",
        ),
        ("harmonic_liu", "starts = 32", "starts = 1000000", "starts: must be ≤ 4096"),
        ("helical_wind_turbine", "carrier_turns = 1 ", "carrier_turns = 1000 ", "carrier_turns: at most 100"),
        ("helical_wind_turbine", "carrier_turns = 1 ", "carrier_turns = 1\nn_slices = 80000 ", "n_slices: must be ≤ 256"),
    ],
)
def test_counts_that_size_every_sample_are_bounded_when_the_file_is_read(example, old, new, message, tmp_path):
    """A slip of a few digits in a count that sizes every sample's grid or solve is refused naming the key, before
    anything is computed (each had been accepted, and the run or its timing would have taken hours or the memory)."""
    src = ROOT / "examples" / f"{example}.toml"
    text = src.read_text()
    assert old in text
    cfg = tmp_path / "s.toml"
    cfg.write_text(text.replace(old, new, 1).replace('"dynamics/', f'"{src.parent}/dynamics/'))
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_study(cfg)


def test_a_te_far_past_small_errors_is_warned_of(capsys, tmp_path):
    """A module a thousand times too small (a unit slip) gives a TE of radians: the run finishes, and says so in its
    output, its report and its summary; the example itself gives no warning."""
    cfg = tmp_path / "s.toml"
    text = RANDOM.read_text()
    assert "module_mm = 1.0" in text
    cfg.write_text(text.replace("module_mm = 1.0", "module_mm = 0.001"))
    assert cli.main(["run", str(cfg), "--out", str(tmp_path / "o"), "--samples", "16"]) == 0
    err = capsys.readouterr().err
    assert "gearte: warning: the peak reaches" in err and "far past the small errors" in err
    assert "**Warning:** the peak reaches" in (tmp_path / "o" / "report.md").read_text()
    assert len(json.loads((tmp_path / "o" / "summary.json").read_text())["warnings"]) == 1
    assert cli.main(["run", str(RANDOM), "--out", str(tmp_path / "ok"), "--samples", "16"]) == 0
    assert "warning" not in capsys.readouterr().err
    assert "warnings" not in json.loads((tmp_path / "ok" / "summary.json").read_text())


@pytest.mark.parametrize(
    "example, old, message",
    [
        ("planetary_wang2013_budget.toml", "samples = 4096 ", "[budget] samples: must be ≤ 4294967295"),
        ("planetary_wang2013_budget.toml", "check_samples = 50000 ", "[budget] check_samples: must be ≤ 4294967295"),
        ("planetary_wang2013_allocate.toml", "starts = 16 ", "[allocation] starts: must be ≤ 4294967295"),
        ("planetary_wang2013_allocate.toml", "check_samples = 50000 ", "[allocation] check_samples: must be ≤ 4294967295"),
        ("cycloid_yao2001_modified.toml", "pathwise_samples = 64", "[sensitivity] pathwise_samples: must be ≤ 4294967295"),
    ],
)
def test_a_study_kinds_sample_counts_beyond_one_key_named_by_check_and_run(example, old, message, capsys, tmp_path, monkeypatch):
    """Sample counts of the study kinds have the bound of the study's own (sample indices are 32-bit): `check` names
    them, and `run` refuses before computing (2⁴⁰ samples would otherwise run out of memory)."""
    text = (ROOT / "examples" / example).read_text()
    assert old in text
    cfg = tmp_path / "s.toml"
    key = old.split("=")[0].strip()
    cfg.write_text(text.replace(old, f"{key} = {2**40} "))
    refused(capsys, tmp_path, "check", cfg, message=message)
    refused(capsys, tmp_path, "run", cfg, "--out", tmp_path / "o", message=message, monkeypatch=monkeypatch)


def test_gearte_cpu_devices_in_ascii_digits_only():
    # Read before JAX is imported: each value in a command of its own.
    for value in ("0", "\u0663", "\u00b2"):
        env = {**os.environ, "GEARTE_CPU_DEVICES": value}
        r = subprocess.run(
            [sys.executable, "-m", "gearte", "check", str(RANDOM)], cwd=ROOT, capture_output=True, text=True, env=env, timeout=120
        )
        assert r.returncode == 2 and r.stderr.startswith("gearte: error: GEARTE_CPU_DEVICES: a whole number"), (value, r.stderr)


@pytest.mark.parametrize(
    "text",
    [
        "RESOURCE_EXHAUSTED: Out of memory allocating 26388279066624 bytes.",
        "INTERNAL: Failed to allocate buffer: Out of memory allocating 1814592322696 bytes.",  # the CPU runtime's form
    ],
    ids=["resource-exhausted", "internal"],
)
def test_out_of_memory_is_reported_plainly(text, capsys, tmp_path, monkeypatch):
    class JaxRuntimeError(RuntimeError):  # the name XLA's errors carry
        pass

    def exhausted(*a, **k):
        raise JaxRuntimeError(text)

    monkeypatch.setattr(run_mod, "_run", exhausted)
    err = refused(capsys, tmp_path, "run", RANDOM, "--out", tmp_path / "o", message="out of memory", computing=True)
    assert "reduce its sample counts" in err


@pytest.mark.parametrize(
    "args, message",
    [
        (["--samples", "0"], "gearte run: error: argument --samples: must be ≥ 1, got 0 (see gearte run --help)"),
        (["--samples", "\u0663"], "gearte run: error: argument --samples: expected a whole number, got '\u0663'"),
        (["--seed", "1_0"], "gearte run: error: argument --seed: expected a whole number, got '1_0'"),
    ],
    ids=["zero", "arabic-indic digit", "underscore"],
)
def test_an_option_argparse_refuses_is_one_line(args, message, capsys, tmp_path):
    with pytest.raises(SystemExit) as e:
        cli.main(["run", str(RANDOM), "--out", str(tmp_path / "o"), *args])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.startswith(message) and err.count("\n") == 1, err
    assert not any(tmp_path.iterdir())


def test_a_full_disk_names_the_results_folder_and_keeps_the_earlier_result(capsys, tmp_path, finished, monkeypatch):
    import errno

    res = copy_run(finished[0], tmp_path / "res")

    def full(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(run_mod, "_run", full)
    refused(capsys, tmp_path, "run", RANDOM, "--out", res, message=f"--out {res}: No space left on device while writing", computing=True)


def test_several_processes_check_the_study_file_and_the_folder_before_joining(capsys, tmp_path, monkeypatch):
    """Joining a several-process run waits for the other processes: a missing study file or a bad results folder is
    named before it, not after a time-out."""

    def no_join(*a, **k):
        raise AssertionError("joined the processes before checking the inputs")

    monkeypatch.setattr(main_mod, "_distributed", no_join)
    several = ["--processes", "2", "--process-id", "0", "--coordinator", "127.0.0.1:1"]
    missing = tmp_path / "missing.toml"
    refused(capsys, tmp_path, "run", missing, "--out", tmp_path / "o", *several, message=str(missing))
    f = tmp_path / "f"
    f.write_text("x")
    refused(capsys, tmp_path, "run", RANDOM, "--out", f, *several, message="is an existing file")


def test_out_a_mount_point(capsys, tmp_path, monkeypatch):
    target = tmp_path / "volume"
    target.mkdir()
    real = os.path.ismount
    monkeypatch.setattr(os.path, "ismount", lambda p: Path(p) == target or real(p))
    refused(capsys, tmp_path, "run", RANDOM, "--out", target, message="is a mount point", monkeypatch=monkeypatch)


def test_a_result_that_cannot_be_replaced_is_kept_and_nothing_is_left(capsys, tmp_path, finished, monkeypatch):
    """Replacing an earlier result renames it aside first; where that fails (a busy folder) the run is refused, naming
    the folder, and the earlier result stays as it was with no folder of gearte's beside it."""
    import errno

    from gearte.cli import io as io_mod

    res = copy_run(finished[0], tmp_path / "res")
    real = os.rename

    def busy(src, dst):
        if Path(src) == res:
            raise OSError(errno.EBUSY, os.strerror(errno.EBUSY), str(src))
        return real(src, dst)

    monkeypatch.setattr(io_mod.os, "rename", busy)
    refused(capsys, tmp_path, "run", RANDOM, "--out", res, "--samples", "16", message=f"--out {res}: cannot be replaced", computing=True)


def test_option_beyond_one_key_named_as_the_option(capsys, tmp_path, monkeypatch):
    for command in (["check", RANDOM], ["run", RANDOM, "--out", tmp_path / "o"]):
        err = refused(capsys, tmp_path, *command, "--samples", 2**32, message="--samples: must be in [1, 2³² − 1]", monkeypatch=monkeypatch)
        assert err.startswith("gearte: error: --samples") and "config" not in err  # the option, not the file
    with pytest.raises(ConfigError, match="--samples"):
        load_study(RANDOM, samples=2**32)


def test_cycloid_unknown_key_in_drive(capsys, tmp_path):
    text = CYCLOID.read_text()
    cfg = tmp_path / "c.toml"
    cfg.write_text(text.replace("z_lobes = 25", "z_lobes = 25\nz_lobs = 25", 1))
    refused(capsys, tmp_path, "check", cfg, message="[drive]: unknown key `z_lobs` (did you mean `z_lobes`?)")


def test_a_run_of_days_is_estimated_and_needs_yes(capsys, tmp_path):
    err = refused(capsys, tmp_path, "run", RANDOM, "--out", tmp_path / "o", "--samples", 2**32 - 1, message="add --yes to run it anyway")
    # A plain study that large is streamed (nothing held per sample): only its time needs --yes.
    assert "--samples 4,294,967,295: about" in err and "samples/s on this machine, streamed" in err


def test_estimate_and_yes(capsys, tmp_path, monkeypatch):
    study = load_study(RANDOM, samples=1000)
    # Per sample a planetary run keeps te, te_rad and index: 3 × 8 bytes; no drive outputs.
    assert estimate_cost(study).bytes == 24 * 1000 and estimate_cost(study).seconds is None
    c = estimate_cost(study, measure_above=10)
    assert c.seconds is not None and c.rate is not None and c.seconds == pytest.approx(1000 / c.rate)
    monkeypatch.setattr(run_mod, "MEASURE_ABOVE", 10)
    monkeypatch.setattr(main_mod, "CONFIRM_SECONDS", 0.0)
    refused(capsys, tmp_path, "run", RANDOM, "--out", tmp_path / "o", "--samples", 200, message="--samples 200: about")
    assert cli.main(["run", str(RANDOM), "--out", str(tmp_path / "o"), "--samples", "200", "--yes"]) == 0
    assert "--samples 200: about" in capsys.readouterr().err


def test_a_slow_drive_is_timed_from_fewer_samples(capsys, tmp_path, monkeypatch):
    """An RV study of a few thousand units runs for an hour: it is timed before it starts, from 100 times the
    samples the timing takes (two blocks), not from the million samples of a closed-form drive."""
    rv = ROOT / "examples" / "rv_robot_joint_tolerances.toml"
    study = load_study(rv)
    threshold = run_mod.timing_threshold(study)
    assert threshold == run_mod.MEASURE_FACTOR * run_mod.measured_samples(study) < study.samples
    assert threshold + 1 == 801 and run_mod.timing_threshold(load_study(RANDOM)) + 1 == 409_601  # the README's figures
    assert run_mod.timing_threshold(load_study(RANDOM)) == min(run_mod.MEASURE_ABOVE, 100 * run_mod.measured_samples(load_study(RANDOM)))
    asked = []

    def hour(study, *, measure_above):
        asked.append((study.samples, measure_above))
        return run_mod.Cost(study.samples, 0, 3600.0, study.samples / 3600.0)

    def ran(*a, **k):
        raise AssertionError("ran")

    monkeypatch.setattr(run_mod, "_run", ran)
    monkeypatch.setattr(main_mod, "estimate_cost", hour)
    refused(capsys, tmp_path, "run", rv, "--out", tmp_path / "o", "--samples", threshold + 1, message="about 60 min", computing=True)
    assert asked == [(threshold + 1, threshold)]
    # The study's [sensitivity] computes a gradient per sample and metric besides: 256 × 3 more samples, counted.
    extra = 256 * 3
    assert run_mod.kind_evaluations(study) == {"sensitivity": extra}
    refused(
        capsys, tmp_path, "run", rv, "--out", tmp_path / "o", "--samples", threshold - extra + 1, message="about 60 min", computing=True
    )
    assert asked[-1] == (threshold - extra + 1, threshold)
    # At the threshold (the study's samples and its kinds' together) nothing is timed: the run starts at once (here
    # stopped where it would compute).
    with pytest.raises(AssertionError, match="ran"):
        cli.main(["run", str(rv), "--out", str(tmp_path / "o"), "--samples", str(threshold - extra), "--no-progress"])
    assert len(asked) == 2


def test_a_study_kinds_samples_are_estimated_with_the_studys_own(capsys, tmp_path, monkeypatch):
    """A designed experiment of 10 runs + the optimum twice, 4,000 samples each, computes 48,000 samples besides the
    study's 200: a run is timed and estimated on all of them, and the message says how many are the kind's."""
    doe = ROOT / "examples" / "planetary_wang2013_doe.toml"
    study = load_study(doe, samples=200)
    assert run_mod.kind_evaluations(study) == {"doe": 12 * 4000} and run_mod.evaluations(study) == 48_200
    # An allocation's worst case is exact (no surrogate samples); its checks take each rule's expected and robust TE
    # (the found and the given rule) and a Monte Carlo of the other assemblies.
    alloc = ROOT / "examples" / "planetary_wang2013_allocate.toml"
    assert run_mod.kind_evaluations(load_study(alloc)) == {"allocation": 2 * (2 * 50_000 + 50_000)}
    robust = tmp_path / "robust.toml"
    robust.write_text(alloc.read_text().replace('objective = "worst_case"', 'objective = "robust"'))
    assert run_mod.kind_evaluations(load_study(robust)) == {"allocation": 16 * 512 + 2 * (2 * 50_000 + 50_000)}
    c = run_mod.estimate_cost(study, measure_above=10_000)
    assert c.rate is not None and c.seconds == pytest.approx(48_200 / c.rate)
    assert run_mod.estimate_cost(study, measure_above=48_200).seconds is None  # not beyond: not timed

    def ran(*a, **k):
        raise AssertionError("ran")

    monkeypatch.setattr(run_mod, "_run", ran)
    monkeypatch.setattr(run_mod, "MEASURE_ABOVE", 10_000)
    monkeypatch.setattr(main_mod, "CONFIRM_SECONDS", 0.0)
    refused(
        capsys,
        tmp_path,
        "run",
        doe,
        "--out",
        tmp_path / "o",
        "--samples",
        200,
        message="(200 samples of the study's own and at least 48,000 of [doe]), and 4.7 KiB of per-sample results held in memory and written to samples.npz; add --yes to run it anyway, or give fewer samples in [doe] (they count most)",
    )


# ---------------------------------------------------------------- compare


def test_compare_out_one_of_the_inputs(capsys, tmp_path, finished, monkeypatch):
    a = copy_run(finished[0], tmp_path / "a")
    b = copy_run(finished[1], tmp_path / "b")
    refused(capsys, tmp_path, "compare", a, b, "--out", a, message=f"--out {a}: is, holds or lies inside the input")
    refused(capsys, tmp_path, "compare", a, b, "--out", a / "cmp", message="lies inside the input")
    with pytest.raises(OutputError):
        compare_runs([a, b], b)


def test_compare_out_another_run_is_refused_but_a_comparison_is_replaced(capsys, tmp_path, finished):
    a = copy_run(finished[0], tmp_path / "a")
    b = copy_run(finished[1], tmp_path / "b")
    other = copy_run(finished[0], tmp_path / "other")
    refused(capsys, tmp_path, "compare", a, b, "--out", other, message=f"--out {other}: holds a gearte run")
    assert cli.main(["compare", str(a), str(b), "--out", str(tmp_path / "cmp")]) == 0
    assert cli.main(["compare", str(b), str(a), "--out", str(tmp_path / "cmp")]) == 0  # its own comparison: replaced
    assert (tmp_path / "cmp" / "comparison.json").is_file()


def _broken_runs(tmp_path: Path, a: Path) -> dict[str, tuple[Path, str]]:
    runs = {}
    d = copy_run(a, tmp_path / "bad_json")
    (d / "summary.json").write_text("{")
    runs["corrupt summary.json"] = (d, f"{d / 'summary.json'}: not valid JSON")
    d = copy_run(a, tmp_path / "bad_npz")
    (d / "samples.npz").write_bytes(b"garbage")
    runs["corrupt samples.npz"] = (d, f"{d / 'samples.npz'}: cannot be read")
    d = copy_run(a, tmp_path / "pickled")
    np.savez(d / "samples.npz", te=np.array([{"a": 1}] * 64, dtype=object))
    runs["pickled samples.npz"] = (d, f"{d / 'samples.npz'}: cannot be read")
    d = copy_run(a, tmp_path / "short")
    np.savez(d / "samples.npz", te=np.ones(3))
    runs["samples.npz of another length"] = (d, "must hold 64 finite numbers")
    d = copy_run(a, tmp_path / "missing_field")
    s = json.loads((d / "summary.json").read_text())
    del s["te"]["mean"]
    (d / "summary.json").write_text(json.dumps(s))
    runs["summary missing a field"] = (d, f"{d / 'summary.json'}: missing `te.mean`")
    f = tmp_path / "a_file"
    f.write_text("x")
    runs["a file as a run"] = (f, f"{f}: a file, not a results folder")
    runs["no such run"] = (tmp_path / "nothing", "no such folder")
    d = tmp_path / "empty"
    d.mkdir()
    runs["a folder that is not a run"] = (d, "not a finished gearte run (no summary.json)")
    return runs


BROKEN = [
    "corrupt summary.json",
    "corrupt samples.npz",
    "pickled samples.npz",
    "samples.npz of another length",
    "summary missing a field",
    "a file as a run",
    "no such run",
    "a folder that is not a run",
]


@pytest.mark.parametrize("case", BROKEN)
def test_compare_a_broken_run(case, capsys, tmp_path, finished, monkeypatch):
    a = copy_run(finished[0], tmp_path / "a")
    bad, message = _broken_runs(tmp_path, a)[case]

    def no_pickles(*a, **k):
        raise AssertionError("a pickle was loaded")

    monkeypatch.setattr(pickle, "load", no_pickles)
    monkeypatch.setattr(pickle, "loads", no_pickles)
    err = refused(capsys, tmp_path, "compare", a, bad, "--out", tmp_path / "cmp", message=message)
    assert "allow_pickle" not in err
    with pytest.raises(RunFolderError):
        compare_runs([a, bad], tmp_path / "cmp")


def test_compare_a_comparison_as_a_run(capsys, tmp_path, finished):
    a, b = (copy_run(r, tmp_path / r.name) for r in finished)
    assert cli.main(["compare", str(a), str(b), "--out", str(tmp_path / "cmp")]) == 0
    refused(capsys, tmp_path, "compare", a, tmp_path / "cmp", "--out", tmp_path / "cmp2", message="a comparison, not a run")
    # A comparison replaces its own earlier comparison.
    assert cli.main(["compare", str(b), str(a), "--out", str(tmp_path / "cmp")]) == 0


def test_compare_runs_of_different_drives_on_what_they_share(capsys, tmp_path, finished):
    a = copy_run(finished[0], tmp_path / "planetary")
    h = copy_run(finished[1], tmp_path / "harmonic_arcmin")
    # The second run as another drive's, reported in arcmin: compared in the first run's arcsec.
    s = json.loads((h / "summary.json").read_text())
    s["drive"] = {"type": "harmonic"}
    for k in ("min", "max", "mean", "std"):
        s["te"][k] /= 60.0
    s["te"]["percentiles"] = {p: v / 60.0 for p, v in s["te"]["percentiles"].items()}
    s["te"]["unit"] = "arcmin"
    (h / "summary.json").write_text(json.dumps(s))
    with np.load(h / "samples.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["te"] = arrays["te"] / 60.0
    np.savez(h / "samples.npz", **arrays)
    res = compare_runs([a, h], tmp_path / "cmp")
    assert res["unit"] == "arcsec" and res["drives"] == ["harmonic", "planetary_2kh"]
    half = json.loads((finished[1] / "summary.json").read_text())["te"]["mean"]
    assert res["runs"][1]["mean"] == pytest.approx(half, rel=1e-12)
    assert "different drives" in (tmp_path / "cmp" / "report.md").read_text()
    # Different metrics share nothing to compare: refused with the reason.
    s["te"]["metric"] = "peak_to_peak"
    (h / "summary.json").write_text(json.dumps(s))
    refused(capsys, tmp_path, "compare", a, h, "--out", tmp_path / "cmp2", message="the runs measure different metrics: peak")


# ---------------------------------------------------------------- Python API and options


@pytest.mark.parametrize(
    "magnitude, phase, message",
    [(-5, 0, "must be ≥ 0"), (math.nan, 0, "must be finite"), (5, math.inf, "Eccentricity.phase"), ([1.0, -2.0], 0, "must be ≥ 0")],
    ids=["negative", "nan", "infinite phase", "negative in a list"],
)
def test_eccentricity_refuses_what_fixed_refuses(magnitude, phase, message):
    with pytest.raises(ValueError, match=message):
        gearte.Eccentricity(magnitude, phase)


def test_version():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.run(
        [sys.executable, "-c", "import sys, gearte_command; sys.exit(gearte_command.main())", "--version"],
        capture_output=True,
        text=True,
        env=env,
    )
    assert p.returncode == 0 and p.stdout.strip() == f"gearte {gearte.__version__}"


def test_a_byte_order_mark_before_the_toml_is_dropped(tmp_path, capsys):
    """Some editors start a UTF-8 file with a byte-order mark, which TOML does not allow: it is dropped."""
    cfg = tmp_path / "bom.toml"
    cfg.write_bytes(b"\xef\xbb\xbf" + RANDOM.read_bytes())
    assert cli.main(["check", str(cfg)]) == 0
    assert "OK" in capsys.readouterr().out


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("pin_circle_radius_um = 14 ", "pin_circle_radius_um = 1e300 ", "pin_circle_radius_um: 1e+300 is larger than 100,000 um"),
        ("eccentricity_um = 20 ", "eccentricity_um = 2e5 ", "eccentricity_um: 200000 is larger than 100,000 um"),
    ],
    ids=["huge", "a unit mistake"],
)
def test_cycloid_reference_values_beyond_their_units_range(old, new, message, capsys, tmp_path):
    """[drive.reference] reads its values itself (a number, a list or a pattern table per error source): they have
    the same bounds as the rest of the file, 100 mm in µm."""
    text = (ROOT / "examples" / "cycloid_yao2001_modified.toml").read_text(encoding="utf-8")
    assert old in text
    cfg = tmp_path / "ref.toml"
    cfg.write_text(text.replace(old, new, 1), encoding="utf-8")
    refused(capsys, tmp_path, "check", cfg, message=message)
