"""Scale-out of the Monte Carlo engine: devices, processes, streaming (bit-identity and exactness)."""

import json
import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import gearte
from gearte.cli.config import load_study
from gearte.studies.streaming import StreamingStatistics

ROOT = Path(__file__).resolve().parents[1]
PLANETARY = "examples/planetary_wang2013_random.toml"


@pytest.fixture(scope="module")
def study():
    s = load_study(PLANETARY)
    return gearte.TEStudy(s.drive, s.errors, metric=gearte.Peak())


def _env(**extra):
    env = dict(os.environ)
    env.update(extra)
    return env


def test_four_devices_give_the_values_of_one(study, tmp_path):
    # A step runs one block per device with the program one device runs: the values cannot depend on the
    # device count (here 4 forced host devices in a fresh interpreter, against this process's one).
    one = gearte.monte_carlo(study, key=3, n_samples=700, block_size=64, chunk_size=64)
    assert one.devices == 1
    script = textwrap.dedent(
        f"""
        import os
        import jax, numpy as np
        jax.config.update("jax_enable_x64", True)
        import gearte
        from gearte.cli.config import load_study
        from gearte.core.cache import enable_compilation_cache
        enable_compilation_cache(os.environ["GEARTE_CACHE_DIR"], programs=False)  # the suite's JAX cache (conftest)
        s = load_study({PLANETARY!r})
        st = gearte.TEStudy(s.drive, s.errors, metric=gearte.Peak())
        out = {{}}
        for chunk in (64, 1000):
            r = gearte.monte_carlo(st, key=3, n_samples=700, block_size=64, chunk_size=chunk)
            assert r.devices == 4, r.devices
            out[f"c{{chunk}}"] = r.values
        np.savez({str(tmp_path / "four.npz")!r}, **out)
        """
    )
    env = _env(XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, check=True, timeout=300)
    four = np.load(tmp_path / "four.npz")
    for k in four.files:
        np.testing.assert_array_equal(four[k], one.values)


def test_streamed_chunks_are_the_held_values(study):
    held = gearte.monte_carlo(study, key=5, n_samples=1000, block_size=64).values
    seen: list = []
    r = gearte.monte_carlo(
        study, key=5, n_samples=1000, block_size=64, chunk_size=200, keep=False, on_chunk=lambda s, v: seen.append((s, v))
    )
    assert r.values is None
    starts = [s for s, _ in seen]
    assert starts == sorted(starts) and starts[0] == 0 and len(seen) > 1
    np.testing.assert_array_equal(np.concatenate([v for _, v in seen]), held)
    with pytest.raises(ValueError, match="on_chunk"):
        gearte.monte_carlo(study, key=5, n_samples=10, keep=False)


def test_streaming_statistics_of_a_study_match_the_exact_ones(study):
    held = gearte.monte_carlo(study, key=9, n_samples=5000, block_size=256).values
    acc = StreamingStatistics(block=1024)
    gearte.monte_carlo(study, key=9, n_samples=5000, block_size=256, chunk_size=700, keep=False, on_chunk=lambda s, v: acc.update(v))
    exact = gearte.statistics(held)
    got = acc.statistics()
    assert (got.n, got.min, got.max) == (exact.n, exact.min, exact.max)
    np.testing.assert_allclose([got.mean, got.std], [exact.mean, exact.std], rtol=1e-13)
    bounds = acc.quantile_errors()
    for p, v in exact.percentiles.items():
        assert abs(got.percentiles[p] - v) <= bounds[p], p
    i = acc.sample_near(exact.percentiles["50"])
    assert abs(held[i] - exact.percentiles["50"]) <= 2.0**-13 * abs(exact.percentiles["50"]) + 1e-3 * exact.std


def _cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "gearte", *args], cwd=ROOT, capture_output=True, text=True, timeout=300, **kw)


@pytest.fixture(scope="module")
def single_run(tmp_path_factory):
    # The single-process reference, run in this process (one device; the programs the other tests compiled):
    # the values do not depend on the device count, so the several-process run below, on two devices per process,
    # must give these to the bit.
    from gearte.cli.main import main

    out = tmp_path_factory.mktemp("single") / "run"
    assert main(["run", PLANETARY, "--samples", "3000", "--out", str(out), "--no-progress"]) == 0
    return out


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_processes_write_the_single_process_results(single_run, tmp_path):
    # jax.distributed on 127.0.0.1 (CPU collectives through gloo): each process computes its share of the
    # samples, process 0 writes the results once: the same values as one process.
    out = tmp_path / "multi"
    coord = f"127.0.0.1:{_free_port()}"
    cmd = [
        sys.executable,
        "-m",
        "gearte",
        "run",
        PLANETARY,
        "--samples",
        "3000",
        "--out",
        str(out),
        "--processes",
        "2",
        "--coordinator",
        coord,
    ]
    procs = [
        subprocess.Popen([*cmd, "--process-id", str(i)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for i in (0, 1)
    ]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    a, b = np.load(single_run / "samples.npz"), np.load(out / "samples.npz")
    np.testing.assert_array_equal(a["te_rad"], b["te_rad"])
    s = json.loads((out / "summary.json").read_text())
    assert s["processes"] == 2 and s["devices"] >= 2  # each process's devices (the CLI makes one per core)
    assert json.loads((single_run / "summary.json").read_text())["te"] == s["te"]


def test_each_process_keeps_its_programs_and_a_repeat_run_loads_them(study, tmp_path):
    # JAX's compilation cache serves only process 0 of a several-process run (its key covers each process's own
    # devices, and only process 0 writes it). gearte's program store keeps each process's Monte Carlo step under
    # a key of its own and loads it onto every process's devices: a second run compiles no step, and its values are
    # those of one process.
    one = gearte.monte_carlo(study, key=3, n_samples=700, block_size=64, chunk_size=64)
    store = tmp_path / "store"
    script = textwrap.dedent(
        f"""
        import sys
        import jax, numpy as np
        jax.config.update("jax_enable_x64", True)
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(coordinator_address=sys.argv[1], num_processes=2, process_id=int(sys.argv[2]))
        import gearte
        from gearte.cli.config import load_study
        from gearte.core.programs import enable_program_store
        kept = enable_program_store({str(store)!r})
        s = load_study({PLANETARY!r})
        st = gearte.TEStudy(s.drive, s.errors, metric=gearte.Peak())
        r = gearte.monte_carlo(st, key=3, n_samples=700, block_size=64, chunk_size=64)
        np.savez(sys.argv[3], values=r.values, devices=r.devices, saved=kept.saved, loaded=kept.loaded)
        """
    )
    env = _env(XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    runs = []
    for run in range(2):
        coord = f"127.0.0.1:{_free_port()}"
        outs = [tmp_path / f"run{run}_process{i}.npz" for i in (0, 1)]
        procs = [
            subprocess.Popen(
                [sys.executable, "-c", script, coord, str(i), str(outs[i])], cwd=ROOT, env=env, stderr=subprocess.PIPE, text=True
            )
            for i in (0, 1)
        ]
        errs = [p.communicate(timeout=300)[1] for p in procs]
        assert [p.returncode for p in procs] == [0, 0], errs
        runs.append([np.load(o) for o in outs])
    first, second = runs
    assert [int(r["saved"]) for r in first] == [1, 1] and [int(r["loaded"]) for r in first] == [0, 0]
    assert [int(r["saved"]) for r in second] == [0, 0] and [int(r["loaded"]) for r in second] == [1, 1]
    assert len(list(store.glob("*.program"))) == 2  # one step per process
    for r in first + second:
        assert int(r["devices"]) == 4
        np.testing.assert_array_equal(r["values"], one.values)


@pytest.mark.parametrize(
    "args, match",
    [
        (["--processes", "2"], "all three"),
        (["--processes", "2", "--process-id", "2", "--coordinator", "127.0.0.1:1"], "process-id"),
        (["--processes", "2", "--process-id", "0", "--coordinator", "nohostport"], "HOST:PORT"),
        (["--cluster", "--processes", "2"], "--cluster"),
    ],
)
def test_bad_process_options_are_refused(args, match, tmp_path):
    r = _cli("run", PLANETARY, "--samples", "10", "--out", str(tmp_path / "x"), *args)
    assert r.returncode == 2 and match in r.stderr and "Traceback" not in r.stderr


def test_cluster_without_a_scheduler_is_refused(tmp_path):
    # No scheduler's variables: JAX finds no cluster, and the command says what to do instead.
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "OMPI_", "PMI_", "MPI_"))}
    r = _cli("run", PLANETARY, "--samples", "10", "--out", str(tmp_path / "x"), "--cluster", env=env)
    assert r.returncode == 2 and r.stderr.startswith("gearte: error: --cluster: no cluster scheduler"), r.stderr


def test_a_streamed_run_reports_exact_moments_and_bounded_percentiles(single_run, tmp_path, monkeypatch):
    import gearte.cli.run as run_mod
    from gearte.cli.main import main

    monkeypatch.setattr(run_mod, "HOLD_BYTES", 1000)  # stream this small study
    out = tmp_path / "streamed"
    assert main(["run", PLANETARY, "--samples", "3000", "--out", str(out), "--keep-samples", "--no-progress"]) == 0
    held = json.loads((single_run / "summary.json").read_text())
    s = json.loads((out / "summary.json").read_text())
    assert "streamed" in s and "streamed" not in held
    assert not (out / "samples.npz").exists()
    for k in ("n", "min", "max"):
        assert s["te"][k] == held["te"][k]
    np.testing.assert_allclose([s["te"]["mean"], s["te"]["std"]], [held["te"]["mean"], held["te"]["std"]], rtol=1e-13)
    for p, v in held["te"]["percentiles"].items():
        assert abs(s["te"]["percentiles"][p] - v) <= s["streamed"]["percentile_error_bounds"][p]
    np.testing.assert_array_equal(np.load(out / "samples_te.npy"), np.load(single_run / "samples.npz")["te"])
    assert "Streamed study" in (out / "report.md").read_text()
    assert s["typical_sample"]["index"] == held["typical_sample"]["index"]
    # `gearte compare` reads the kept values; without them it says how to keep them.
    assert main(["compare", str(out), str(single_run), "--out", str(tmp_path / "cmp")]) == 0
    c = json.loads((tmp_path / "cmp" / "comparison.json").read_text())
    assert [r["n"] for r in c["runs"]] == [3000, 3000] and c["runs"][0]["mean"] == c["runs"][1]["mean"]
    (out / "samples_te.npy").unlink()
    assert main(["compare", str(out), str(single_run), "--out", str(tmp_path / "cmp2")]) == 2


@pytest.mark.parametrize("streamed", [False, True])
def test_a_process_that_does_not_write_takes_part_but_computes_no_trace_and_draws_nothing(streamed, tmp_path, monkeypatch):
    # The processes of a several-process run other than process 0 take part in every computation that may span the
    # processes (the Monte Carlo, the drive's study outputs) and skip what process 0 alone writes: no TE trace of the
    # typical unit (its programs would be compiled there on every run: JAX's cache serves process 0 alone), no plot.
    import gearte.cli.run as run_mod

    calls = []

    def refuse(what):
        def fn(*args, **kwargs):
            raise AssertionError(f"a process that does not write called {what}")

        return fn

    s = load_study(PLANETARY, samples=3000)
    drive_cls = type(s.drive)
    monkeypatch.setattr(run_mod, "_writes", lambda: False)
    monkeypatch.setattr(drive_cls, "trace", refuse("the drive's trace"))
    monkeypatch.setattr(run_mod, "_plots", refuse("the plots"))
    monkeypatch.setattr(run_mod, "_draw", refuse("a figure"))
    if streamed:  # a plain study (its drive without study outputs of its own), whose results would not be held
        monkeypatch.setattr(run_mod, "HOLD_BYTES", 1000)
    else:
        monkeypatch.setattr(drive_cls, "study_outputs", lambda self, context: calls.append(len(context.values_rad)))
    mc = run_mod.monte_carlo
    monkeypatch.setattr(run_mod, "monte_carlo", lambda *a, **k: calls.append("monte carlo") or mc(*a, **k))
    assert run_mod.run_study(s, tmp_path / "out", progress=False) == {}
    # A held study's values go to the drive's study outputs (which may run Monte Carlos on every process); a streamed
    # study has none.
    assert calls == (["monte carlo"] if streamed else ["monte carlo", 3000])
