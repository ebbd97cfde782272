"""`gearte run` / `compare` / `check`, config validation, atomic results folders."""

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import gearte
from gearte import cli
from gearte.cli import plots
from gearte.cli.config import ConfigError, load_study, parse_angle

ROOT = Path(__file__).resolve().parents[1]
# Plain Monte Carlo studies; allocation and budget studies have their own tests (test_allocation, test_budget).
EXAMPLES = sorted(p for p in (ROOT / "examples").glob("planetary_*.toml") if not p.stem.endswith(("_allocate", "_budget", "_doe")))
RANDOM = ROOT / "examples" / "planetary_wang2013_random.toml"


def run(*args):
    return cli.main([str(a) for a in args])


def test_importing_gearte_changes_no_global_state():
    code = (
        "import jax, sys; before = jax.config.read('jax_enable_x64'); import gearte, gearte.cli; "
        "assert jax.config.read('jax_enable_x64') == before == False, 'x64 changed'; "
        "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot imported'; "
        "import matplotlib; assert matplotlib.get_backend() is not None; print('ok')"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_ENABLE_X64", "MPLBACKEND")}
    env["PYTHONPATH"] = str(ROOT)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert p.returncode == 0 and p.stdout.strip() == "ok", p.stderr


def _refusals_without_x64(setup: str, calls: str) -> str:
    """Run `setup` (64-bit mode on), turn 64-bit mode off, then each of the `calls` (a dict of name → callable, as
    code) in a fresh interpreter; prints "<name> refused" for each that refuses with the fix (its RuntimeError names
    jax_enable_x64), else what it computed or raised. Returns the output."""
    code = (
        "import jax; jax.config.update('jax_enable_x64', True)\n"
        + setup
        + "\njax.config.update('jax_enable_x64', False)\n"
        + f"calls = {calls}\n"
        + "for name, call in calls.items():\n"
        + "    try:\n        print(name, 'computed', call())\n    except RuntimeError as e:\n"
        + "        print(name, 'refused' if 'jax_enable_x64' in str(e) else e)"
    )
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    env["PYTHONPATH"] = str(ROOT)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT)
    assert p.returncode == 0, p.stdout + p.stderr
    return p.stdout


def test_library_entry_points_refuse_float32_clearly():
    """Without JAX's 64-bit mode every entry point refuses with the fix, none computes in float32: the Monte Carlo,
    a drive's signal (the README's first steps), and the exact peaks of a signal built before x64 was turned off."""
    out = _refusals_without_x64(
        "import gearte, jax.numpy as jnp; from gearte.drives import wang2013\n"
        "d = wang2013.table1_drive(); m = gearte.ErrorModel({n: gearte.ErrorSource(gearte.Fixed(t), gearte.UniformPhase()) "
        "for n, t in wang2013.TABLE1_TOLERANCES_UM.items()}, d.error_sources)\n"
        "errors = d.zero_errors(); sig = d.signal(errors)",
        "{'monte_carlo': lambda: gearte.monte_carlo(gearte.TEStudy(d, m), key=1, n_samples=8), "
        "'signal': lambda: d.signal(errors), 'peak': lambda: gearte.peak(sig), 'extrema': lambda: gearte.extrema(sig), "
        "'smooth_peak': lambda: gearte.smooth_peak(sig, width=1e-6), 'evaluate': lambda: gearte.evaluate(sig, 0.0)}",
    )
    names = ("monte_carlo", "signal", "peak", "extrema", "smooth_peak", "evaluate")
    assert out.split("\n")[:-1] == [f"{n} refused" for n in names], out


def test_the_rv_contact_systems_refuse_float32_clearly():
    """The RV reducer's contact systems (public in gearte.drives.rv_khv_contacts) refuse without 64-bit mode, as the
    cycloid-pin functions they are built on do."""
    out = _refusals_without_x64(
        "from gearte.cli.config import load_study; from gearte.drives import rv_khv_contacts as rc\n"
        "d = load_study('examples/rv_robot_joint.toml').drive; err = d.errors(None); e0 = rc.cycloid_errors(d, err, 0)",
        "{'pin_contacts': lambda: rc.pin_contacts(d.stage, e0, 0.1), "
        "'single_disc_system': lambda: rc.single_disc_system(d.stage, e0, 0.1), 'rv_system': lambda: rc.rv_system(d, err, 0.1, 1.0)}",
    )
    names = ("pin_contacts", "single_disc_system", "rv_system")
    assert out.split("\n")[:-1] == [f"{n} refused" for n in names], out


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_examples_run_and_write_every_output(path, tmp_path):
    out = tmp_path / "res"
    assert run("run", path, "--out", out, "--samples", 600, "--seed", 3) == 0
    assert sorted(p.name for p in out.iterdir()) == ["histogram.png", "report.md", "samples.npz", "summary.json", "trace.png"]
    s = json.loads((out / "summary.json").read_text())
    te = s["te"]
    assert te["unit"] == "arcsec" and te["metric"] == "peak" and te["n"] == 600
    assert set(te["percentiles"]) == {"1", "5", "50", "95", "99", "99.73"}
    assert te["min"] <= te["percentiles"]["1"] <= te["percentiles"]["50"] <= te["percentiles"]["99.73"] <= te["max"]
    assert s["seed"] == 3 and s["samples"] == 600
    with np.load(out / "samples.npz") as z:
        np.testing.assert_allclose(z["te"], z["te_rad"] * 180 * 3600 / math.pi, rtol=1e-14)
        np.testing.assert_allclose(np.mean(z["te"]), te["mean"], rtol=1e-12)
    report = (out / "report.md").read_text()
    for needed in ("seed 3", "600", "float64", "uniform on [0, 2π)", "hyper-period"):
        assert needed in report, needed
    # 600 × 0.27 % = 1.6 samples beyond P99.73 (and 6 beyond P99): the first is flagged as no estimate of the tail.
    assert "P99.73 from 600 samples: fewer than 3 samples lie beyond it" in report
    # The typical sample's values carry their unit (µm for every planetary source), once per row.
    assert re.search(r"\| ring_manufacturing \| [-0-9.e]+ µm \| [0-9.]+ \|", report), report
    if "eq9" not in path.stem:
        assert "single path" in report  # the coupling assumption is stated
    if "rayleigh" in path.stem:
        assert "Rayleigh, scale σ" in report and "truncated at" in report


def test_same_seed_same_numbers_and_override(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    run("run", RANDOM, "--out", a, "--samples", 300, "--seed", 9)
    run("run", RANDOM, "--out", b, "--samples", 300, "--seed", 9, "--chunk-size", 7)
    run("run", RANDOM, "--out", c, "--samples", 300, "--seed", 10)
    za, zb, zc = (np.load(d / "samples.npz")["te"] for d in (a, b, c))
    np.testing.assert_array_equal(za, zb)
    assert not np.array_equal(za, zc)


def test_compare(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    run("run", RANDOM, "--out", a, "--samples", 300)
    run("run", ROOT / "examples" / "planetary_wang2013_half.toml", "--out", b, "--samples", 300, "--seed", 1001)
    assert run("compare", a, b, "--out", tmp_path / "cmp") == 0
    cmp = json.loads((tmp_path / "cmp" / "comparison.json").read_text())
    assert [r["name"] for r in cmp["runs"]] == ["wang2013-random", "wang2013-half"]
    # Same seed, half magnitudes: exactly half the mean.
    np.testing.assert_allclose(cmp["runs"][1]["mean_vs_first"], 0.5, rtol=1e-12)
    assert (tmp_path / "cmp" / "overlay.png").exists() and (tmp_path / "cmp" / "report.md").exists()
    assert run("compare", a, tmp_path / "nothing", "--out", tmp_path / "cmp2") == 2
    assert not (tmp_path / "cmp2").exists()


def config_text(**replace):
    text = RANDOM.read_text() + replace.pop("__append__", "")
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


BAD = {
    "unknown key": ({"z_sun = 12": "z_sun = 12\nz_moon = 3"}, "[drive]: unknown key `z_moon`"),
    "typo with hint": ({"coupling = ": "couplin = "}, "did you mean `coupling`"),
    "missing field": ({"z_planet = 36\n": ""}, "missing required key `z_planet`"),
    "negative tolerance": ({"tolerance_um = 13": "tolerance_um = -13"}, "[errors.sun_manufacturing] tolerance_um: must be ≥ 0"),
    "impossible tooth counts": ({"z_ring = 84": "z_ring = 85"}, "z_ring = z_sun + 2·z_planet"),
    "not assemblable": ({"z_sun = 12": "z_sun = 14", "z_ring = 84": "z_ring = 86"}, "cannot be assembled"),
    "wrong type": ({"z_sun = 12": 'z_sun = "twelve"'}, "[drive] z_sun: expected a whole number"),
    "NaN": ({"module_mm = 1.0": "module_mm = nan"}, "[drive] module_mm: must be a finite number"),
    "unknown source": (
        {"__append__": '\n[errors.ring_assembly]\ntolerance_um = 1\nmagnitude = { law = "fixed" }\nphase = { rule = "uniform" }\n'},
        "unknown error source `ring_assembly`",
    ),
    "missing source": (
        {
            '[errors.carrier_assembly]   # (A_c, γ_c), Table 1\ntolerance_um = 15\nmagnitude = { law = "fixed" }\nphase = { rule = "uniform" }': ""
        },
        "missing error source(s) ['carrier_assembly']",
    ),
    "unknown table": ({"[errors.carrier_assembly]": "[unused]"}, "study file: unknown table `[unused]`"),
    "bad law": (
        {
            'magnitude = { law = "fixed" }\nphase = { rule = "uniform" }\n\n[errors.planet_manufacturing]': 'magnitude = { law = "rayleig" }\nphase = { rule = "uniform" }\n\n[errors.planet_manufacturing]'
        },
        "did you mean 'rayleigh'",
    ),
    "bad seed": ({"seed = 1001": "seed = -4"}, "[study] seed: must be ≥ 0"),
    "bad metric": ({'metric = "peak"': 'metric = "amplitude"'}, "[study] metric: must be one of"),
    "bad angle": ({'pressure_angle_rad = "pi/9"': 'pressure_angle_rad = "pie/9"'}, "cannot read 'pie/9'"),
    "both angle units": ({'pressure_angle_rad = "pi/9"': 'pressure_angle_rad = "pi/9"\npressure_angle_deg = 20'}, "not both"),
    "not toml": ({"[study]": "[study"}, "not valid TOML"),
    "rayleigh without scale": (
        {
            'magnitude = { law = "fixed" }\nphase = { rule = "uniform" }\n\n[errors.planet_manufacturing]': 'magnitude = { law = "rayleigh" }\nphase = { rule = "uniform" }\n\n[errors.planet_manufacturing]'
        },
        "needs `scale_um`",
    ),
    "relative to nothing": (
        {
            'magnitude = { law = "fixed" }\nphase = { rule = "uniform" }\n\n[errors.planet_manufacturing]': 'magnitude = { law = "fixed" }\nphase = { rule = "relative", to = "beta_q" }\n\n[errors.planet_manufacturing]'
        },
        "'beta_q' is not an error source",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_configs_exit_nonzero_naming_the_field_and_write_nothing(case, tmp_path, capsys):
    replace, message = dict(BAD[case][0]), BAD[case][1]
    cfg = tmp_path / "bad.toml"
    cfg.write_text(config_text(**replace))
    out = tmp_path / "out"
    assert run("run", cfg, "--out", out, "--samples", 10) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [cfg]
    assert run("check", cfg) == 2


def test_check_ok(capsys):
    assert run("check", RANDOM) == 0
    assert "OK" in capsys.readouterr().out


def test_failed_run_leaves_nothing_and_keeps_the_previous_result(tmp_path, monkeypatch):
    out = tmp_path / "res"
    assert run("run", RANDOM, "--out", out, "--samples", 200) == 0
    before = (out / "summary.json").read_text()

    def boom(*a, **k):
        raise KeyboardInterrupt("simulated Ctrl-C while writing plots")

    monkeypatch.setattr(plots, "trace", boom)
    assert run("run", RANDOM, "--out", out, "--samples", 300) == 130
    assert (out / "summary.json").read_text() == before  # untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]  # no partial folders left
    fresh = tmp_path / "fresh"
    assert run("run", RANDOM, "--out", fresh, "--samples", 300) == 130
    assert not fresh.exists()


def test_parse_angle():
    assert parse_angle("7pi/9") == pytest.approx(7 * math.pi / 9, rel=1e-15)
    assert parse_angle("-pi/9") == pytest.approx(-math.pi / 9, rel=1e-15)
    assert parse_angle("2*pi/3") == pytest.approx(2 * math.pi / 3, rel=1e-15)
    assert parse_angle("0.5") == 0.5
    assert parse_angle("π") == pytest.approx(math.pi)
    for bad in ("", "pi/0", "7pi/9x", "/9"):
        with pytest.raises(ConfigError):
            parse_angle(bad)


def test_load_study_builds_the_table3_rule():
    s = load_study(ROOT / "examples" / "planetary_wang2013_rayleigh_allocated.toml")
    src = s.errors.sources
    assert isinstance(src["sun_assembly"].phase, gearte.RelativePhase) and src["sun_assembly"].phase.to == "ring_manufacturing"
    assert float(src["sun_assembly"].phase.offset) == pytest.approx(7 * math.pi / 9)
    assert float(src["carrier_assembly"].phase.offset) == pytest.approx(8 * math.pi / 9)
    assert isinstance(src["planet_assembly"].phase, gearte.FixedPhase)
    r = src["sun_manufacturing"].magnitude
    assert float(r.scale) == 6.5 and float(r.truncate_at) == 13.0


def test_real_command_line_entry_point(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(config_text(**{"tolerance_um = 13": "tolerance_um = -13"}))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.run(
        [sys.executable, "-m", "gearte", "run", str(bad), "--out", str(tmp_path / "o")], capture_output=True, text=True, env=env
    )
    assert p.returncode == 2
    assert "tolerance_um" in p.stderr and "≥ 0" in p.stderr
    p = subprocess.run(
        [sys.executable, "-m", "gearte", "run", str(RANDOM), "--out", str(tmp_path / "o"), "--samples", "0"],
        capture_output=True,
        text=True,
        env=env,
    )
    assert p.returncode == 2 and "--samples" in p.stderr
    p = subprocess.run([sys.executable, "-m", "gearte", "--version"], capture_output=True, text=True, env=env)
    assert p.returncode == 0 and p.stdout.strip() == f"gearte {gearte.__version__}"


def test_compilation_cache_folder_and_switches(monkeypatch, tmp_path):
    import importlib

    from gearte.core.cache import cache_wanted, default_cache_dir

    monkeypatch.delenv("GEARTE_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "xdg" / "gearte" / "jax"
    monkeypatch.setenv("GEARTE_CACHE_DIR", str(tmp_path / "mine"))
    assert default_cache_dir() == tmp_path / "mine"
    for value, wanted in (("0", False), ("off", False), (" No ", False), ("false", False), ("1", True), ("yes", True)):
        monkeypatch.setenv("GEARTE_COMPILATION_CACHE", value)
        assert cache_wanted() is wanted, value
    # The command turns the cache on unless told not to (the run below is refused after that choice: --out holds the study).
    calls = []
    cli_main = importlib.import_module("gearte.cli.main")  # the module (gearte.cli.main is also the function's name)
    monkeypatch.setattr(cli_main, "enable_compilation_cache", lambda: calls.append(1))
    study = tmp_path / "s.toml"
    study.write_text(RANDOM.read_text())
    for env, flag, expected in (("1", [], 1), ("1", ["--no-compile-cache"], 0), ("0", [], 0)):
        calls.clear()
        monkeypatch.setenv("GEARTE_COMPILATION_CACHE", env)
        assert cli.main(["run", str(study), "--out", str(tmp_path), *flag]) == 2
        assert len(calls) == expected, (env, flag)


def test_report_numbers_that_round_to_zero_carry_no_minus_sign():
    """A clearance of −3e-6 mm shown to four decimals reads 0.0000, not −0.0000; a value that does not round to zero
    keeps its sign, whatever the format."""
    from gearte.core.units import number_text

    assert number_text(-3e-6, ".4f") == "0.0000"
    assert number_text(-0.0, ".2f") == "0.00"
    assert number_text(-0.0001, ".4f") == "-0.0001"
    assert number_text(-1e-20, ".4g") == "-1e-20"
    assert number_text(2.5e-5, ".4f") == "0.0000"
    assert number_text(None) == "—"


def test_the_clearance_plot_legend_names_the_budget_line(monkeypatch, tmp_path):
    """The budget is drawn in the tangential panel and the legend sits by the normal one: it lists the pins and the
    budget line."""
    from matplotlib.figure import Figure

    from gearte.drives.cycloid_pin_plots import clearance_vs_input

    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, path, **kw: saved.append(fig))
    x = np.linspace(0.0, 10.0, 5)
    clearance_vs_input(x, np.full((5, 3), 0.01), np.zeros((5, 3)), [1, 2], budget_mm=0.005, title="t", path=tmp_path / "c.png")
    (fig,) = saved
    texts = [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]
    assert texts == ["pin 1", "pin 2", "budget 0.005 mm"]
