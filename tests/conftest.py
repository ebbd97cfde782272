import gc
import os
import sys
from pathlib import Path
from typing import NamedTuple

import jax
import pytest

# As optimistix's tests do: float64 and strict dtype promotion, so silent int/float or
# float32/float64 mixing in the library fails loudly here. (Importing gearte changes no
# global state; a user turns 64-bit mode on the same way.)
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
# JAX's persistent compilation cache, the one the `gearte` command uses (gearte.core.cache: ~/.cache/gearte/jax
# unless GEARTE_CACHE_DIR says otherwise; GEARTE_TEST_JAX_CACHE sets another for the suite alone). A second run
# of the suite, from any clone, and a `gearte run` after it, reuse compiled code instead of compiling it again;
# notebooks run in the test process, and the commands the tests start inherit GEARTE_CACHE_DIR.
from gearte.core.cache import default_cache_dir, enable_compilation_cache  # noqa: E402

_CACHE = os.environ.get("GEARTE_TEST_JAX_CACHE") or str(default_cache_dir())
os.environ["GEARTE_CACHE_DIR"] = _CACHE
# gearte's program store (gearte.core.programs) off, here and in the commands the tests start: its key covers
# gearte's source, so after every change of the source it would compile every Monte Carlo program of the suite
# again from scratch, where JAX's cache still has most of them. tests/test_programs.py tests the store itself.
os.environ["GEARTE_PROGRAM_STORE"] = "0"
enable_compilation_cache(_CACHE)

sys.path.insert(0, os.path.dirname(__file__))
os.environ.setdefault("MPLBACKEND", "Agg")


# ---------------------------------------------------------------- scheduling on the workers
# `make test` runs the suite on two workers (``-n 2 --dist loadgroup --no-loadscope-reorder``) with the
# scheduler below: each group runs whole on one worker, so its tests (and its notebook, run in the test
# process) share the functions compiled for them and the session fixtures; groups start in decreasing
# order of their cost (longest first, so that the two workers finish together). A test file not listed
# is its own group. (The scheduler names the groups itself: xdist's ``xdist_group`` marks no longer
# reach its scheduler under pytest ≥ 9.2.)
GROUPS = {
    "test_cycloid": "cycloid",
    "test_cycloid_grinding": "cycloid",
    "test_cycloid_floating": "cycloid",
    "test_cycloid_modification": "cycloid",
    "test_harmonic": "harmonic",
    "test_harmonic_tooth_mesh": "harmonic",
    "test_allocation": "planetary_optimise",
    "test_budget": "planetary_optimise",
    "test_budget_limits": "planetary_optimise",
    "test_sensitivity": "planetary_optimise",
    "test_identify": "identification",
    "test_identify_grid": "identification",
    "test_assemble": "identification",
    "test_identify_cli": "identification",
    "test_identify_records_checks": "identification",
    "test_montecarlo": "planetary",
    "test_planetary": "planetary",
    "test_scaleout": "planetary",
    "test_doe": "doe",
    "test_doe_cli": "doe",
    "test_helical": "helical",
    "test_helical_modification": "helical",
    "test_helical_drive": "helical",
    "test_rv": "rv",
    "test_rv_outputs": "rv",
}
#: Notebook → the group of the tests of its subject (unlisted notebooks: group "notebooks").
NOTEBOOK_GROUPS = {
    "cycloid_clearance.ipynb": "cycloid",
    "harmonic_drive.ipynb": "harmonic",
    "tolerance_allocation.ipynb": "planetary_optimise",
    "identify_and_assemble.ipynb": "identification",
    "planetary_wang2013.ipynb": "planetary",
    "helical_modification.ipynb": "helical",
    "rv_reducer.ipynb": "rv",
}
#: Cost of each group (s, one worker, warm compilation cache; measured with --durations=0, rounded): only their order matters.
COST_S = {
    "planetary_optimise": 102,
    "rv": 71,
    "cycloid": 58,
    "planetary": 58,
    "helical": 55,
    "harmonic": 39,
    "test_contract": 36,
    "identification": 34,
    "test_programs": 19,
    "test_metrics": 19,
    "test_fuzz_study_files": 15,
    "test_cli": 15,
    "test_interrupt": 14,
    "doe": 11,
    "test_bad_input": 8,
    "test_costs": 7,
    "test_boundary_checks": 6,
    "test_startup": 6,
}


#: Drive (test_contract's parameter) → the group of its own tests, so that the contract's short run of the drive's
#: example and the drive's tests that read the same run (harmonic, cycloid) share it (`example_run`).
CONTRACT_GROUPS = {
    "cycloid_pin": "cycloid",
    "harmonic": "harmonic",
    "helical_planetary": "helical",
    "planetary_2kh": "planetary",
    "rv_khv": "rv",
}


def group_of(nodeid: str) -> tuple[str, bool]:
    """The group of a test (by its node id), and whether it is a notebook's run."""
    path, _, name = nodeid.partition("::")
    stem = Path(path).stem
    if stem == "test_notebooks" and name.startswith("test_notebook_runs["):
        return NOTEBOOK_GROUPS.get(name[len("test_notebook_runs[") : -1], "notebooks"), True
    if stem == "test_contract" and name.endswith("]"):
        return CONTRACT_GROUPS.get(name[name.index("[") + 1 : -1], stem), False
    return GROUPS.get(stem, stem), False


#: The group whose tests the worker ran last (`pytest_runtest_setup`).
_LAST_GROUP: list[str] = []


def pytest_runtest_setup(item):
    """Between two groups on a worker, drop JAX's compiled programs: a group's tests share them, the next group
    does not. A worker that keeps every program of every group it runs maps their machine code in tens of
    thousands of memory regions (55,000 were counted late in a run); past the kernel's ``vm.max_map_count``
    (65,530 by default) XLA's compiler and its executable (de)serialisation crash the worker (segfault or abort).
    Programs needed again come back from the persistent compilation cache."""
    group, _ = group_of(item.nodeid)
    if _LAST_GROUP and _LAST_GROUP[0] != group:
        jax.clear_caches()
        gc.collect()
    _LAST_GROUP[:] = [group]


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    del config
    order = []
    for i, item in enumerate(items):
        group, notebook = group_of(item.nodeid)
        order.append(((-COST_S.get(group, 0), group, notebook, i), item))
    items[:] = [item for _, item in sorted(order, key=lambda k: k[0])]


def pytest_xdist_make_scheduler(config, log):
    from xdist.scheduler import LoadScopeScheduling

    class GroupScheduling(LoadScopeScheduling):
        """xdist's scope scheduling with `group_of` as the scope."""

        def _split_scope(self, nodeid: str) -> str:
            return group_of(nodeid)[0]

    return GroupScheduling(config, log)


#: Samples and seed of the contract's short run of each drive's example (tests/test_contract.py), which the drive's
#: tests of the same example read too (`example_run`).
CONTRACT_SAMPLES, CONTRACT_SEED = 40, 2


class ExampleRun(NamedTuple):
    """A shared ``gearte run``: its results folder and what it printed."""

    out: Path
    stdout: str


@pytest.fixture(scope="session")
def example_run(tmp_path_factory):
    """``example_run(path, *, samples, seed, drive_only=False)``: the results folder (and printed output) of
    ``gearte run`` on the study file `path`, run once per worker for each set of arguments and shared by the tests
    that read it (the contract's short run of a drive's example and the drive's own tests of that example;
    `CONTRACT_GROUPS` puts them on one worker). With `drive_only` the study kinds (budgets, optimisers,
    sensitivities) are left out: the drive's own outputs only (`gearte.cli.run.run_study`). Tests read the
    folder, never write into it."""
    import contextlib
    import dataclasses
    import io

    from gearte import cli
    from gearte.cli.config import load_study
    from gearte.cli.run import run_study

    done: dict[tuple, ExampleRun] = {}

    def run(path: Path, *, samples: int, seed: int, drive_only: bool = False) -> ExampleRun:
        key = (str(path), samples, seed, drive_only)
        if key not in done:
            out = tmp_path_factory.mktemp("example_run") / Path(path).stem
            printed = io.StringIO()
            with contextlib.redirect_stdout(printed):
                if drive_only:
                    run_study(dataclasses.replace(load_study(path, samples=samples, seed=seed), kinds={}), out)
                else:
                    args = ["run", str(path), "--out", str(out), "--samples", str(samples), "--seed", str(seed)]
                    assert cli.main(args) == 0
            done[key] = ExampleRun(out, printed.getvalue())
        return done[key]

    return run
