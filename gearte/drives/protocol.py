"""What every drive provides: the drive protocol.

As optimistix separates `AbstractMinimiser` from its solvers, gearte separates the drive
protocol from the drives and from the studies that use it:

- `AbstractDrive`: declares its error sources (`SourceSpec`: name, kind, shape, unit,
  default tolerance, phase symbol), turns a set of errors into its *response* over the
  input angle (`response`), and offers the metrics that can be taken of that response
  (`metrics`: peak, peak-to-peak, lost motion, loaded pairs…). It also declares how a study
  file describes it (`from_table`), and any outputs beyond the statistics (`study_outputs`).
- `AbstractSinusoidalDrive`: the response is a sum of sinusoids (`components`), so its
  extrema are exact over the whole hyper-period (planetary, harmonic, explicit).
- `AbstractGridDrive`: the response is computed on a grid of input angles, with a stated
  angular accuracy (geometric, equilibrium and dynamic models: cycloid-pin, RV, helical).

Studies (Monte Carlo, sensitivities, budgets, allocation) are written once against this
protocol, in `gearte.studies` and `gearte.optimise`, and never look inside a drive.
"""

from __future__ import annotations

import abc
import dataclasses
import weakref
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar, Literal, Self

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from ..core.extrema import Extrema, extrema
from ..core.grid import grid_size
from ..core.metrics import RMS, AbstractMetric, Peak, PeakToPeak
from ..core.programs import kept_jit
from ..core.signal import Components, TESignal, evaluate, to_signal
from ..core.validate import check_array_values, check_names

if TYPE_CHECKING:
    from ..core.schema import Table

SourceKind = Literal["eccentricity", "deviation"]


class Eccentricity(eqx.Module):
    """An error vector: `magnitude` µm at `phase` rad (arrays; one entry per instance for per-planet sources).

    Values given as Python numbers, lists or NumPy arrays are checked: a magnitude must be
    finite and ≥ 0, a phase finite. (JAX arrays, e.g. drawn inside a study, are taken as they are.)
    The two shapes must broadcast together (the same shape, or one a scalar: one phase for every instance), for
    any values (a shape is known even inside `jit`).
    """

    magnitude: Float[Array, "*n"]
    phase: Float[Array, "*n"]

    def __init__(self, magnitude: ArrayLike, phase: ArrayLike = 0.0):
        check_array_values("Eccentricity.magnitude", magnitude, nonnegative=True, unit="µm")
        check_array_values("Eccentricity.phase", phase, unit="rad")
        m_shape, p_shape = np.shape(magnitude), np.shape(phase)
        try:
            np.broadcast_shapes(m_shape, p_shape)
        except ValueError:
            raise ValueError(
                f"Eccentricity: magnitude of shape {m_shape} and phase of shape {p_shape} do not broadcast together; give one "
                "phase per magnitude (the same shape), or a single phase for all"
            ) from None
        self.magnitude = jnp.asarray(magnitude, dtype=float)
        self.phase = jnp.asarray(phase, dtype=float)


class SourceSpec(eqx.Module):
    """An error source a drive declares.

    - `name`: the source's name (study files use it as ``[errors.NAME]``).
    - `kind`: ``"eccentricity"`` (a magnitude, µm, at a phase, rad: an `Eccentricity`) or
      ``"deviation"`` (a signed value in `unit`: an array).
    - `shape`: ``()`` for a scalar, ``(n,)`` for one value per instance (planet, pin, tooth space).
    - `unit`: ``"µm"`` or ``"rad"``.
    - `tolerance`: the drive's default tolerance (in `unit`), or None.
    - `symbol`: the source's symbol in the source paper (reports and assembly rules).
    - `description`: one line for reports.
    """

    name: str = eqx.field(static=True)
    kind: SourceKind = eqx.field(static=True)
    shape: tuple[int, ...] = eqx.field(static=True)
    unit: str = eqx.field(static=True)
    tolerance: float | None = eqx.field(static=True)
    symbol: str = eqx.field(static=True)
    description: str = eqx.field(static=True)

    def __init__(
        self,
        name: str,
        kind: SourceKind = "eccentricity",
        *,
        shape: tuple[int, ...] = (1,),
        unit: str = "µm",
        tolerance: float | None = None,
        symbol: str | None = None,
        description: str = "",
    ):
        if kind not in ("eccentricity", "deviation"):
            raise ValueError(f"SourceSpec {name!r}: kind must be 'eccentricity' or 'deviation', got {kind!r}")
        if unit not in ("µm", "rad"):
            raise ValueError(f"SourceSpec {name!r}: unit must be 'µm' or 'rad', got {unit!r}")
        self.name, self.kind, self.shape, self.unit = name, kind, tuple(int(s) for s in shape), unit
        self.tolerance = None if tolerance is None else float(tolerance)
        self.symbol = name if symbol is None else symbol
        self.description = description

    @property
    def count(self) -> int:
        """Number of instances (1 for a scalar)."""
        return int(np.prod(self.shape)) if self.shape else 1


Errors = Mapping[str, Any]  # source name → Eccentricity (eccentricity sources) or array (deviation sources)


@dataclasses.dataclass(frozen=True)
class Figure:
    """A plot a study declares, drawn by the command line: the numerics never import matplotlib.

    `plot` names a function of `gearte.cli.plots`, or ``"module:function"`` for a drive's own plots
    module beside it (e.g. ``"gearte.drives.cycloid_pin_plots:rotation_error"``, imported only when
    drawing); it is called with ``**data, path=folder / filename``. `data` are its keyword arguments
    (NumPy arrays, numbers, strings); `filename` is the PNG written in the results folder.
    """

    filename: str
    plot: str
    data: dict
    caption: str = ""


@dataclasses.dataclass
class StudyOutputs:
    """What a drive adds to a `gearte run`: summary entries, report sections, figures, arrays saved
    beside the samples (`arrays`, in samples.npz) and further .npz files (`files`: file name → arrays)."""

    summary: dict = dataclasses.field(default_factory=dict)
    report: list[str] = dataclasses.field(default_factory=list)
    figures: list[Figure] = dataclasses.field(default_factory=list)
    arrays: dict = dataclasses.field(default_factory=dict)
    files: dict = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class Trace:
    """The TE of one unit over the input angle, for reports: `theta` (input, rad), `te` (rad), the span
    in input revolutions (`span_revs`, exact text), its extrema (rad, at input angles in rad), and
    spectral lines (frequency as a multiple of the input speed → amplitude, rad; may be empty)."""

    theta: np.ndarray
    te: np.ndarray
    span_revs: str
    max: float
    min: float
    theta_max: float
    theta_min: float
    lines: list[tuple[str, float]] = dataclasses.field(default_factory=list)

    @classmethod
    def of_grid(cls, theta: np.ndarray, te: np.ndarray, span_revs: str) -> Trace:
        """The trace of TE sampled on a grid of input angles, its extrema the grid's (no lines)."""
        i, k = int(np.argmax(te)), int(np.argmin(te))
        return cls(theta, te, span_revs, float(te[i]), float(te[k]), float(theta[i]), float(theta[k]))


class AbstractStudyContext(abc.ABC):
    """What a drive's `study_outputs` is given by the study runner (so drives never import the studies)."""

    unit: str
    seed: int
    samples: int
    chunk_size: int | None
    progress: bool | None
    values_rad: np.ndarray
    outputs: dict[str, np.ndarray]  # the drive's `sample_outputs` of every sample
    model: Any  # the ErrorModel of the study
    metric: AbstractMetric

    @abc.abstractmethod
    def monte_carlo(self, fn, *, desc: str) -> np.ndarray:
        """Run ``fn(key_i)`` over the study's samples with the study's keys; returns the values."""

    @abc.abstractmethod
    def sample_errors(self, index: int) -> dict:
        """The errors of sample `index` (regenerated from its key)."""


class AbstractDrive(eqx.Module):
    """A drive: error sources in, response over the input angle out, metrics of that response.

    Subclasses implement `error_sources`, `response`, `metrics` and `from_table`, and set the
    class variables `type_name` (the study file's ``[drive] type``) and `linear` (the response
    is linear in the error magnitudes at fixed phases, so metrics such as the peak are
    positively homogeneous of degree 1 in the tolerances).
    """

    type_name: ClassVar[str]
    linear: ClassVar[bool]

    @property
    @abc.abstractmethod
    def error_sources(self) -> dict[str, SourceSpec]:
        """The error sources, by name, in a fixed order (sample keys are folded in by position)."""

    @abc.abstractmethod
    def response(self, errors: Errors) -> Any:
        """The drive's response to these errors (a pytree the metrics read), over the input angle."""

    @property
    @abc.abstractmethod
    def metrics(self) -> dict[str, AbstractMetric]:
        """The metrics this drive offers, by study-file name; the first is the default."""

    @abc.abstractmethod
    def trace(self, errors: Errors) -> Trace:
        """The TE of the unit with these errors over the input angle (the drive's period), for reports and plots."""

    @classmethod
    @abc.abstractmethod
    def from_table(cls, table: Table) -> Self:
        """Build the drive from its study-file table ``[drive]`` (read every key; unknown keys are refused by the caller)."""

    def describe(self) -> list[tuple[str, str]]:
        """(parameter, value) rows for reports."""
        return []

    def accuracy(self) -> str:
        """How exactly the metrics are taken, for reports."""
        return ""

    def bytes_per_sample(self) -> int:
        """Rough peak working memory of one Monte Carlo sample (bytes), to size blocks."""
        return 2048

    def solved(self, response: Any) -> Array:
        """Whether every solve behind `response` succeeded (a boolean scalar). A closed-form drive always succeeds;
        a drive that solves (the RV reducer's equilibria) says where it did not, and a tolerance budget's exact checks
        then count that sample as missing a yield's spec (and leave it out of a mean ± kσ)."""
        del response
        return jnp.asarray(True)

    def sample_outputs(self, errors: Errors, response: Any) -> dict[str, Array]:
        """Per-sample arrays a `gearte run` keeps beside the metric, computed in the same Monte Carlo
        pass from the same response (given to `study_outputs` as ``context.outputs``); none by default."""
        del errors, response
        return {}

    def study_outputs(self, context: AbstractStudyContext) -> StudyOutputs:
        """Outputs of a `gearte run` beyond the metric's statistics (none by default)."""
        del context
        return StudyOutputs()

    def checked(self, errors: Errors) -> dict[str, Any]:
        """Check names, kinds and shapes (at trace time) and broadcast to the declared shapes."""
        specs = self.error_sources
        name = type(self).__name__
        check_names(errors, specs, what=f"{name}: errors must name exactly {list(specs)}")
        out = {}
        for n, spec in specs.items():
            e = errors[n]
            if spec.kind == "eccentricity":
                if not isinstance(e, Eccentricity):
                    raise ValueError(f"{name}: errors[{n!r}] must be an Eccentricity(magnitude_um, phase_rad)")
                out[n] = Eccentricity(
                    _broadcast(name, n, "magnitude", e.magnitude, spec.shape), _broadcast(name, n, "phase", e.phase, spec.shape)
                )
            else:
                if isinstance(e, Eccentricity):
                    raise ValueError(f"{name}: errors[{n!r}] is a signed deviation ({spec.unit}); give a number or an array")
                check_array_values(f"{name}: errors[{n!r}]", e, unit=spec.unit)
                out[n] = _broadcast(name, n, "value", jnp.asarray(e, dtype=float), spec.shape)
        return out

    def zero_errors(self) -> dict[str, Any]:
        """Every source at zero (eccentricities of magnitude 0 at phase 0)."""
        return {
            n: (Eccentricity(jnp.zeros(s.shape), jnp.zeros(s.shape)) if s.kind == "eccentricity" else jnp.zeros(s.shape))
            for n, s in self.error_sources.items()
        }


def _broadcast(drive: str, source: str, what: str, arr: Array, shape: tuple[int, ...]) -> Array:
    n = int(np.prod(shape)) if shape else 1
    if arr.shape == shape:
        return arr
    if arr.shape in ((), (1,)) or (shape and arr.shape == (n,)):
        return jnp.broadcast_to(arr.reshape(-1)[0] if arr.shape == (1,) and shape == () else arr.reshape(-1) if arr.ndim else arr, shape)
    raise ValueError(f"{drive}: errors[{source!r}].{what} must be a scalar or have shape {shape}, got {arr.shape}")


class AbstractSinusoidalDrive(AbstractDrive):
    """A drive whose TE is a sum of sinusoids of the input angle: `components`.

    Its response is the TE signal over the hyper-period (rad), and its extrema are exact over
    the whole hyper-period (certified grid search and Newton refinement, `gearte.extrema`).
    """

    linear: ClassVar[bool] = True

    @abc.abstractmethod
    def components(self, errors: Errors) -> Components:
        """Sinusoidal components of the output TE for these errors."""

    def signal(self, errors: Errors) -> TESignal:
        """The output TE (rad) for these errors, over its hyper-period."""
        return to_signal(self.components(errors))

    def response(self, errors: Errors) -> TESignal:
        return self.signal(errors)

    def extrema(self, signal: TESignal) -> Extrema:
        """Exact extrema of a TE signal of this drive (a drive may supply a faster exact search)."""
        return extrema(signal)

    @property
    def metrics(self) -> dict[str, AbstractMetric]:
        return {"peak": Peak(), "peak_to_peak": PeakToPeak(), "rms": RMS()}

    def accuracy(self) -> str:
        return (
            "exact over the whole hyper-period: a grid of 16 points per period of the fastest term, the best maxima "
            "refined by Newton's method on the exact trigonometric polynomial, every other stretch of the grid bounded "
            "below them by the polynomial's derivatives (within 1e-6 of the TE's span; a very flat top, or two humps "
            "closer than a grid step, is refined again from every grid point around it)"
        )

    def trace(self, errors: Errors) -> Trace:
        # Two compiled programs, not dozens of eager operations; a repeat run loads the first from the program store
        # (`gearte.core.programs`: `_signal_and_extrema` is a kept program) and the second from JAX's cache.
        signal, ext = _signal_and_extrema(self, errors)
        revs = float(signal.hyper_period_revs)
        top_order = max(signal.orders) if signal.orders else 1
        npts = int(min(200_000, max(4000, 40 * top_order)))
        theta = np.linspace(0.0, 2 * np.pi * revs, npts)
        amp = np.hypot(np.asarray(signal.cos_coef), np.asarray(signal.sin_coef))
        lines = [("0 (constant)", float(signal.offset))] + [(str(f), float(a)) for f, a in zip(signal.frequencies, amp)]
        return Trace(
            theta=theta,
            te=np.asarray(_evaluate_jit(signal, theta)),
            span_revs=str(signal.hyper_period_revs),
            max=float(ext.max),
            min=float(ext.min),
            theta_max=float(ext.theta_max),
            theta_min=float(ext.theta_min),
            lines=lines,
        )

    def bytes_per_sample(self) -> int:
        # Traced once per drive (about 7 ms for the planetary example, 7 % of its 50,000-sample Monte Carlo run).
        hit = _BYTES_PER_SAMPLE.get(id(self))
        if hit is not None and hit[0]() is self:
            return hit[1]
        sig = jax.eval_shape(lambda: self.signal(self.zero_errors()))
        m = grid_size(sig.orders, 16) if sig.orders else 1
        value = 8 * (12 * m + 64 * len(sig.orders) + 256)
        key = id(self)
        _BYTES_PER_SAMPLE[key] = (weakref.ref(self, lambda _: _BYTES_PER_SAMPLE.pop(key, None)), value)
        return value


#: `AbstractSinusoidalDrive.bytes_per_sample` of the drives alive, by id (with a weak reference to the drive: an
#: entry goes when its drive does, and a new drive at the same address is not taken for it).
_BYTES_PER_SAMPLE: dict[int, tuple[weakref.ref, int]] = {}


class AbstractGridDrive(AbstractDrive):
    """A drive whose response is computed on a grid of input angles (geometry, equilibrium, dynamics).

    Subclasses state the grid and its angular accuracy in `accuracy`, and refine where they can.
    """

    linear: ClassVar[bool] = False

    @abc.abstractmethod
    def input_angles(self) -> Float[Array, " p"]:
        """The input angles (rad) the response is computed at."""

    def te(self, response: Any) -> Float[Array, " p"]:
        """The TE (rad) at each angle of `input_angles`, read from this drive's `response` (identification fits it
        to measured records). A drive that states no single TE on its grid leaves this out."""
        del response
        raise NotImplementedError(f"{type(self).__name__} does not state its TE on its grid (AbstractGridDrive.te)")


def sample_key(key: PRNGKeyArray, index) -> PRNGKeyArray:
    """The key of sample `index` of a study keyed by `key` (``fold_in``)."""
    return jax.random.fold_in(key, index)


@kept_jit
def _signal_and_extrema(drive: AbstractSinusoidalDrive, errors: Errors) -> tuple[TESignal, Extrema]:
    signal = drive.signal(errors)
    return signal, drive.extrema(signal)


_evaluate_jit = eqx.filter_jit(evaluate)


@eqx.filter_jit
def zero_signal(drive: AbstractSinusoidalDrive) -> TESignal:
    """The drive's TE signal with every source at zero: its orders and fundamental, the layout of all its signals
    (jitted at module level: traced once per drive structure, not on every call)."""
    return drive.signal(drive.zero_errors())
