"""Start-up: importing gearte and asking the command for help import neither JAX nor matplotlib.

Each check runs in a fresh interpreter (a subprocess), since this one has JAX loaded already.
"""

import ast
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import gearte

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("jax", "jaxlib", "equinox", "matplotlib", "scipy", "optimistix", "numpy")


def fresh(code: str) -> dict:
    """Run `code` in a new interpreter; it prints one JSON line, returned."""
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_ENABLE_X64", "MPLBACKEND")}
    env["PYTHONPATH"] = str(ROOT)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout.strip().splitlines()[-1])


LOADED = f"import json, sys; print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"


def test_import_gearte_loads_nothing_heavy():
    assert fresh("import gearte, gearte.cli; " + LOADED) == []


def test_a_name_loads_its_module_on_first_use():
    # A drive needs JAX; a study file's header needs nothing heavy.
    assert "jax" in fresh("import gearte; gearte.Planetary2KH; " + LOADED)
    assert fresh("import gearte.cli.config as c; c.check_file('examples/planetary_wang2013_random.toml'); " + LOADED) == []


def test_help_of_every_command_loads_nothing_heavy():
    code = (
        "import contextlib, io, json, sys\n"
        "from gearte.cli.main import _parser\n"
        "p = _parser()\n"
        "for cmd in ([], ['run'], ['check'], ['compare'], ['grade'], ['identify'], ['assemble']):\n"
        "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "        p.parse_args([*cmd, '--help'])\n" + LOADED
    )
    assert fresh(code) == []


def test_every_public_name_resolves_and_is_declared_for_type_checkers():
    for name in gearte.__all__:
        assert getattr(gearte, name) is not None, name
    assert set(gearte.__all__) <= set(dir(gearte))
    # The names the type checkers see (the `if TYPE_CHECKING:` imports) are exactly the public ones.
    tree = ast.parse((ROOT / "gearte" / "__init__.py").read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If) and getattr(n.test, "id", None) == "TYPE_CHECKING")
    declared = {a.asname or a.name for n in block.body if isinstance(n, (ast.Import, ast.ImportFrom)) for a in n.names}
    assert declared == set(gearte.__all__) - {"__version__"}
    with pytest.raises(AttributeError, match="no_such_name"):
        gearte.no_such_name  # noqa: B018


def test_the_registry_imports_a_drive_only_when_its_class_is_asked_for():
    """A study of one drive imports that drive's modules only (the cycloid-pin and RV modules take a second to
    import); every registered name is its class's `type_name`."""
    code = (
        "import json, sys; from gearte.drives.registry import DRIVES; names = sorted(DRIVES); "
        "before = sorted(m for m in sys.modules if m.startswith('gearte.drives.')); DRIVES['planetary_2kh']; "
        "after = sorted(m for m in sys.modules if m.startswith('gearte.drives.')); print(json.dumps([names, before, after]))"
    )
    names, before, after = fresh(code)
    assert names == sorted(["planetary_2kh", "explicit", "harmonic", "cycloid_pin", "rv_khv", "helical_planetary"])
    assert before == ["gearte.drives.registry"]
    assert "gearte.drives.planetary_2kh" in after and not any("cycloid" in m or "rv_khv" in m or "helical" in m for m in after)
    from gearte.drives import DRIVES

    for name in DRIVES:
        assert DRIVES[name].type_name == name


def test_gearte_drives_exports_every_drive_and_the_helical_model_on_first_use():
    import gearte.drives as drives

    for name, cls in drives.DRIVES.items():  # every registered drive by its class name
        assert getattr(drives, cls.__name__) is cls, name
    # The helical names load with their modules (diffrax) on first use, and are the top-level ones.
    assert "diffrax" not in fresh("import gearte.drives; " + LOADED.replace(repr(HEAVY), repr(("diffrax",))))
    # Every name of the package loads on first use (drives._LAZY); the helical and RV ones are also top-level names.
    assert set(drives._LAZY) <= set(dir(drives))
    for name, module in drives._LAZY.items():
        assert getattr(drives, name) is getattr(importlib.import_module(module, "gearte.drives"), name), name
    helical = {n for n, m in drives._LAZY.items() if m.startswith(".helical")}
    for name in helical | {"RVKHV", "RVResponse"}:
        assert getattr(drives, name) is getattr(gearte, name), name
    with pytest.raises(AttributeError, match="no_such_name"):
        drives.no_such_name  # noqa: B018


def test_check_of_a_planetary_study_imports_no_solver():
    """`gearte check` of a planetary study, with or without an `[allocation]` or `[budget]` table, builds the whole
    study (JAX) but imports neither optimistix (a quarter of a second) nor matplotlib: the study kinds import their
    optimisers when they run, not when their table is read. (One interpreter checks the three files: a module
    imported by any of them is still loaded at the end.)"""
    examples = ["planetary_wang2013_random", "planetary_wang2013_allocate", "planetary_wang2013_budget"]
    code = (
        "import contextlib, io, json, sys\nfrom gearte.cli.main import main\nout = io.StringIO()\n"
        f"with contextlib.redirect_stdout(out):\n    status = [main(['check', f'examples/{{e}}.toml']) for e in {examples!r}]\n"
        "print(json.dumps([status, out.getvalue(), sorted(m for m in ('jax', 'optimistix', 'lineax', 'matplotlib') if m in sys.modules)]))"
    )
    status, out, loaded = fresh(code)
    assert status == [0, 0, 0] and out.count(": OK (") == 3, (status, out)
    assert "[allocation]" in out and "[budget]" in out, out  # the kinds' tables were read
    assert loaded == ["jax"], loaded


def test_kind_tables_of_the_first_checks_match_the_study_kinds():
    from gearte.cli.config import KIND_TABLES
    from gearte.cli.kinds import STUDY_KINDS

    assert KIND_TABLES == tuple(k.table for k in STUDY_KINDS)


@pytest.mark.parametrize(
    "text, message",
    [
        ("[studdy]\nname = 'x'\n", "unknown table `[studdy]` (did you mean `[study]`?)"),
        ("[study]\nname = 'a b'\nseed = 1\n[drive]\ntype = 'planetary_2kh'\n", "[study] name: use letters"),
        ("[study]\nname = 'a'\nseed = 1\n[drive]\ntype = 3\n", "[drive] type: expected a string"),
        ("[study]\nname = 'a'\n", "missing required key `seed`"),
        ("[study\n", "not valid TOML"),
    ],
)
def test_check_names_a_broken_file_without_importing_jax(tmp_path, text, message):
    study = tmp_path / "s.toml"
    study.write_text(text)
    code = (
        "import contextlib, io, json, sys\nfrom gearte.cli.main import main\nerr = io.StringIO()\n"
        f"with contextlib.redirect_stderr(err):\n    status = main(['check', {str(study)!r}])\n"
        "print(json.dumps([status, err.getvalue(), sorted(m for m in ('jax', 'equinox', 'matplotlib') if m in sys.modules)]))"
    )
    status, err, loaded = fresh(code)
    assert status == 2 and message in err and loaded == [], (status, err, loaded)


@pytest.mark.parametrize(
    "study, status, stream, answer", [("good", 0, "stdout", ": OK ("), ("bad", 2, "stderr", "z_sun: expected a whole number")]
)
def test_check_prints_its_answer_and_exits_without_tearing_jax_down(tmp_path, study, status, stream, answer):
    """`gearte check` ends at once once its answer is printed (the interpreter's teardown of JAX takes about 0.2 s of a
    second): the answer reaches a pipe whole, with the exit status, and no exit handler runs."""
    path = ROOT / "examples" / "planetary_wang2013_random.toml"
    if study == "bad":
        text = path.read_text(encoding="utf-8")
        assert "z_sun = 12\n" in text
        path = tmp_path / "bad.toml"
        path.write_text(text.replace("z_sun = 12\n", 'z_sun = "x"\n'), encoding="utf-8")
    code = (
        "import atexit, sys\n"
        "atexit.register(lambda: print('exit handlers ran', file=sys.stderr))\n"
        f"sys.argv = ['gearte', 'check', {str(path)!r}]\n"
        "from gearte_command import main\n"
        "sys.exit(main())\n"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert p.returncode == status, p.stderr
    assert answer in getattr(p, stream)
    assert "exit handlers ran" not in p.stderr
